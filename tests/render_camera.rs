//! Issue 24, the images a user sees: square pixels whatever the camera's `aspectRatio`
//! (and the default size taken from it, with a warning for another `--size`),
//! `--exposure`, `render --preview`, and the default choice of animation clips. Each
//! scene is built in code; frames are read back with the `exr` crate.

mod common;

use std::path::{Path, PathBuf};

use common::build::{diffuse, linear, mesh, perspective, placed, SceneBuilder};
use common::exr_read::{channel, read_exr};
use common::farm::{ok, s, stderr, subfield};
use common::render_scene::{quad, temp_dir};
use glam::{Quat, Vec3, Vec4};
use subfield::render::{self, RenderOptions};
use subfield::scene::{Animation, Node, Scene};
use subfield::scene::{ClipSelection, Property};

/// Half the side of the square, and its distance in front of the camera.
const HALF: f32 = 1.0;
const DIST: f32 = 5.0;
/// The camera's vertical field of view (radians).
const YFOV: f32 = 0.6;

/// A camera of aspect ratio `aspect` at the origin looking down -Z at a grey square of
/// side 2·HALF facing it at distance DIST (no lights: the default light shines on it).
fn square_scene(aspect: Option<f32>) -> Scene {
    let mut b = SceneBuilder::new();
    let grey = b.add_material(diffuse("grey", Vec4::new(0.6, 0.6, 0.6, 1.0), 1.0));
    let m = b.add_mesh(mesh(
        "square",
        vec![quad(
            Vec3::new(0.0, 0.0, -DIST),
            Vec3::X * HALF,
            Vec3::Y * HALF,
            grey,
        )],
    ));
    let cam = b.add_camera(perspective("wide", YFOV, aspect, 0.1, None));
    let sq = b.add_node(Node {
        name: Some("square".into()),
        mesh: Some(m),
        ..Default::default()
    });
    let c = b.add_node(Node {
        name: Some("camera".into()),
        camera: Some(cam),
        ..Default::default()
    });
    b.add_root(sq);
    b.add_root(c);
    b.finish()
}

/// The bounding box (width, height) in pixels of the covered pixels (alpha > 0.5).
fn covered_extent(path: &Path) -> (usize, usize, usize, usize) {
    let (w, h, chans) = read_exr(path);
    let a = channel(&chans, "A");
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
    for y in 0..h {
        for x in 0..w {
            if a[y * w + x] > 0.5 {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    assert!(x1 >= x0 && y1 >= y0, "{}: nothing covered", path.display());
    (w, h, x1 - x0 + 1, y1 - y0 + 1)
}

#[test]
fn an_off_aspect_camera_keeps_its_square_square() {
    let dir = temp_dir("camera-square");
    let scene = dir.join("wide.glb");
    subfield::import::write_gltf(&square_scene(Some(16.0 / 9.0)), &scene).unwrap();
    // Pixels tall the square is: yfov is vertical whatever the image's width.
    let expect = |h: usize| h as f32 * (HALF / DIST) / (YFOV / 2.0).tan();
    for (size, warned) in [("640x480", true), ("640x360", false), ("300x400", true)] {
        let out = dir.join(format!("{size}.exr"));
        let o = ok(&["render", s(&scene), "-o", s(&out), "--size", size]);
        let err = stderr(&o);
        let lines = err
            .lines()
            .filter(|l| l.starts_with("warning:") && l.contains("aspect ratio"))
            .count();
        assert_eq!(lines, usize::from(warned), "{size}: {err}");
        if warned {
            assert!(
                err.contains(&format!(
                    "--size {size} is not the aspect ratio 1.7778 of camera \"wide\""
                )) && err.contains("without --size: 640x360"),
                "{err}"
            );
        }
        let (w, h, sw, sh) = covered_extent(&out);
        assert_eq!(format!("{w}x{h}"), size);
        assert!(
            sw.abs_diff(sh) <= 1,
            "{size}: the square is drawn {sw}x{sh} pixels"
        );
        assert!(
            (sh as f32 - expect(h)).abs() <= 1.5,
            "{size}: {sh} pixels tall, expected {}",
            expect(h)
        );
    }
    // Without --size: 640 wide at the camera's 16:9, no warning.
    let out = dir.join("default.exr");
    let o = ok(&["render", s(&scene), "-o", s(&out)]);
    assert!(!stderr(&o).contains("warning:"), "{}", stderr(&o));
    assert!(stderr(&o).contains("640x360 at 1 spp"), "{}", stderr(&o));
    let (w, h, sw, sh) = covered_extent(&out);
    assert_eq!((w, h), (640, 360));
    assert!(sw.abs_diff(sh) <= 1, "{sw}x{sh}");
    // A camera without an aspect ratio: 640x480 and no warning at any size.
    let free = dir.join("free.glb");
    subfield::import::write_gltf(&square_scene(None), &free).unwrap();
    let out = dir.join("free.exr");
    let o = ok(&["render", s(&free), "-o", s(&out)]);
    assert!(!stderr(&o).contains("warning:"), "{}", stderr(&o));
    let (w, h, _, _) = covered_extent(&out);
    assert_eq!((w, h), (640, 480));
}

#[test]
fn exposure_scales_the_written_radiance_and_is_a_render_option() {
    let dir = temp_dir("camera-exposure");
    let scene = dir.join("sq.glb");
    subfield::import::write_gltf(&square_scene(None), &scene).unwrap();
    let base = dir.join("ev0.exr");
    let common = ["--size", "96x64", "--float", "--aov", "depth,albedo"];
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec!["render", s(&scene), "-o", s(out)];
        args.extend(common);
        args.extend(extra);
        ok(&args)
    };
    run(&base, &[]);
    let (_, _, c0) = read_exr(&base);
    for ev in ["1.5", "-2"] {
        let out = dir.join(format!("ev{ev}.exr"));
        run(&out, &["--exposure", ev]);
        let (_, _, c1) = read_exr(&out);
        let k = ev.parse::<f32>().unwrap().exp2();
        let mut lit = 0;
        for ch in ["R", "G", "B"] {
            for (i, (a, b)) in channel(&c0, ch).iter().zip(channel(&c1, ch)).enumerate() {
                assert!(
                    (a * k - b).abs() <= 1e-6 * b.abs(),
                    "EV {ev}, {ch} of pixel {i}: {a} × {k} != {b}"
                );
                lit += usize::from(*a > 0.0);
            }
        }
        assert!(lit > 100, "too few lit pixels to compare: {lit}");
        for ch in ["A", "Z", "albedo.R", "albedo.G", "albedo.B"] {
            assert_eq!(channel(&c0, ch), channel(&c1, ch), "EV {ev}: {ch} changed");
        }
    }
    // The options string carries the exposure: a resumed run with another exposure
    // re-renders the frame, with the same one skips it.
    let o = run(&base, &["--resume", "--exposure", "1"]);
    assert!(
        stderr(&o).contains("rendered 1 frame (0 skipped"),
        "{}",
        stderr(&o)
    );
    let o = run(&base, &["--resume", "--exposure", "1"]);
    assert!(
        stderr(&o).contains("rendered 0 frames (1 skipped"),
        "{}",
        stderr(&o)
    );
    let o = subfield(&["render", s(&scene), "-o", s(&base), "--exposure", "nan"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--exposure NaN"), "{}", stderr(&o));
}

#[test]
fn render_writes_a_preview_of_its_first_frame() {
    let dir = temp_dir("camera-preview");
    let scene = dir.join("sq.glb");
    subfield::import::write_gltf(&square_scene(None), &scene).unwrap();
    let png = dir.join("look/preview.png");
    let o = ok(&[
        "render",
        s(&scene),
        "-o",
        s(&dir.join("f.#.exr")),
        "--frames",
        "0..2",
        "--size",
        "80x60",
        "--preview",
        s(&png),
    ]);
    assert!(stderr(&o).contains(&format!("preview: {}", png.display())));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (80, 60));
    let first = img.get_pixel(0, 0);
    assert!(
        img.pixels().any(|p| p != first),
        "the preview is one colour"
    );
    // The same pixels as frame 0, tone-mapped (sRGB of the clamped radiance).
    let (w, _, c) = read_exr(&dir.join("f.0.exr"));
    for (i, p) in img.pixels().enumerate() {
        for (k, ch) in ["R", "G", "B"].iter().enumerate() {
            let v = channel(&c, ch)[i];
            let want = render::linear_to_srgb8(v);
            assert!(
                p.0[k].abs_diff(want) <= 1,
                "pixel {},{} {ch}: {} vs {want}",
                i % w,
                i / w,
                p.0[k]
            );
        }
    }
    let o = subfield(&[
        "render",
        s(&scene),
        "-o",
        s(&dir.join("g.exr")),
        "--preview",
        s(&dir.join("p.jpg")),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("must end in .png"), "{}", stderr(&o));
    assert!(!dir.join("g.exr").exists());
}

/// Two cubes (nodes 0 and 1) in front of a camera, and clips: each `(name, node, dx)`
/// moves `node` by `dx` along +X over one second.
fn clip_scene(clips: &[(&str, u32, f32)]) -> Scene {
    let mut b = SceneBuilder::new();
    let grey = b.add_material(diffuse("grey", Vec4::ONE, 1.0));
    let mut nodes = Vec::new();
    for (i, x) in [-1.5f32, 1.5].into_iter().enumerate() {
        let m = b.add_mesh(mesh(
            &format!("cube{i}"),
            vec![common::render_scene::cube(Vec3::splat(0.5), grey)],
        ));
        let n = b.add_node(Node {
            name: Some(format!("cube{i}")),
            mesh: Some(m),
            transform: placed(Vec3::new(x, 0.0, 0.0), Quat::IDENTITY),
            ..Default::default()
        });
        b.add_root(n);
        nodes.push(n);
    }
    let cam = b.add_camera(perspective("cam", 0.9, None, 0.1, None));
    let c = b.add_node(Node {
        camera: Some(cam),
        transform: placed(Vec3::new(0.0, 0.0, 8.0), Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(c);
    for &(name, node, dx) in clips {
        let x = if node == 0 { -1.5 } else { 1.5 };
        b.add_animation(Animation {
            name: Some(name.into()),
            channels: vec![linear(
                nodes[node as usize],
                Property::Translation,
                vec![0.0, 1.0],
                vec![x, 0.0, 0.0, x + dx, 0.0, 0.0],
            )],
        });
    }
    let mut scene = b.finish();
    scene.fps = Some(4.0);
    scene
}

fn rgba(path: &Path) -> Vec<Vec<f32>> {
    let (_, _, c) = read_exr(path);
    ["R", "G", "B", "A"]
        .iter()
        .map(|n| channel(&c, n).to_vec())
        .collect()
}

#[test]
fn clips_on_the_same_target_play_the_first_alone_with_one_warning() {
    let dir = temp_dir("camera-clips");
    let scene_path = dir.join("clash.glb");
    subfield::import::write_gltf(
        &clip_scene(&[("walk", 0, 1.0), ("run", 0, -1.0), ("wave", 1, 0.5)]),
        &scene_path,
    )
    .unwrap();
    let scene = subfield::import::load(&scene_path).unwrap();
    let (sel, warning) = scene.default_clips();
    assert_eq!(sel, ClipSelection::One(0));
    let warning = warning.unwrap();
    for part in [
        "clips 0 \"walk\" and 1 \"run\" both animate the translation of node 0 \"cube0\"",
        "playing the first clip, 0 \"walk\", alone",
        "not played: 1 \"run\", 2 \"wave\"",
        "--animation",
    ] {
        assert!(warning.contains(part), "{part:?} not in {warning}");
    }
    let opts = RenderOptions {
        output: dir.join("f.#.exr"),
        ..Default::default()
    };
    let plan = render::plan(&scene, &opts).unwrap();
    assert_eq!(plan.selection, ClipSelection::One(0));
    assert_eq!(plan.warnings, vec![warning.clone()]);
    // --animation chooses outright, without the warning.
    let chosen = RenderOptions {
        animation: Some("run".into()),
        ..opts.clone()
    };
    let plan = render::plan(&scene, &chosen).unwrap();
    assert_eq!(plan.selection, ClipSelection::One(1));
    assert!(plan.warnings.is_empty(), "{:?}", plan.warnings);

    // The command line prints it once, and frame 2 (t = 0.5 s) is clip 0's alone.
    let frame = |name: &str, extra: &[&str]| -> (PathBuf, String) {
        let out = dir.join(format!("{name}.exr"));
        let mut args = vec![
            "render",
            s(&scene_path),
            "-o",
            s(&out),
            "--frames",
            "2",
            "--size",
            "64x48",
        ];
        args.extend(extra);
        let o = ok(&args);
        (out, stderr(&o))
    };
    let (default, err) = frame("default", &[]);
    assert_eq!(
        err.matches("warning:").count(),
        1,
        "one warning expected: {err}"
    );
    assert!(err.contains(&format!("warning: {warning}")), "{err}");
    let (walk, err) = frame("walk", &["--animation", "0"]);
    assert!(!err.contains("warning:"), "{err}");
    let (run, _) = frame("run", &["--animation", "run"]);
    assert_eq!(rgba(&default), rgba(&walk));
    assert_ne!(rgba(&default), rgba(&run));
}

#[test]
fn clips_on_disjoint_targets_play_together() {
    let dir = temp_dir("camera-clips-disjoint");
    let scene_path = dir.join("apart.glb");
    subfield::import::write_gltf(
        &clip_scene(&[("left", 0, 1.0), ("right", 1, -1.0)]),
        &scene_path,
    )
    .unwrap();
    let scene = subfield::import::load(&scene_path).unwrap();
    assert_eq!(scene.default_clips(), (ClipSelection::All, None));
    let plan = render::plan(
        &scene,
        &RenderOptions {
            output: dir.join("f.#.exr"),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(plan.selection, ClipSelection::All);
    assert!(plan.warnings.is_empty(), "{:?}", plan.warnings);
    // Both cubes move: the pose at 1 s has each at its clip's end.
    let pose = scene.pose_at(plan.selection, 1.0);
    assert_eq!(pose.local[0].translation, Vec3::new(-0.5, 0.0, 0.0));
    assert_eq!(pose.local[1].translation, Vec3::new(0.5, 0.0, 0.0));
}
