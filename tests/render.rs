//! The renderer driven as a library: depth against brute force for every pixel, an
//! independent EXR reader (OpenEXR's Python bindings), shading checks on scenes built
//! in code, and every shared glTF sample rendering.

mod common;

use common::exr_read::{channel, read_exr};
use common::render_scene;

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::{Mat3, Vec3, Vec4};
use render_scene::{temp_dir, write_scene};
use subfield::import;
use subfield::render::{self, Aovs, FrameRange, PixelType, RenderOptions};
use subfield::scene::{ClipSelection, Scene, TriangleSoup};
use subfield::{BruteForce, Intersector, Ray};

fn quiet(_: render::RenderEvent<'_>) {}

/// All triangles of the scene at `t` (static then dynamic: the order does not matter
/// for distances).
fn all_triangles(scene: &Scene, t: f32) -> Vec<[Vec3; 3]> {
    let all = scene.split(ClipSelection::All);
    let mut tris = scene.static_triangles(&all).positions;
    let mut d = TriangleSoup::new();
    scene.dynamic_triangles_at(&all, t, &mut d);
    tris.extend(d.positions);
    tris
}

/// The primary ray of pixel (x, y) of a `size` image straight from DESIGN.md §4.
fn contract_ray(
    rot: Mat3,
    origin: Vec3,
    tan_half: f32,
    aspect: f32,
    size: (usize, usize),
    (x, y): (usize, usize),
) -> Ray {
    let (w, h) = size;
    let cx = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * aspect * tan_half;
    let cy = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * tan_half;
    Ray::new(origin, rot * Vec3::new(cx, cy, -1.0))
}

fn check_depth(
    z: &[f32],
    w: usize,
    h: usize,
    tris: &[[Vec3; 3]],
    ray: impl Fn(usize, usize) -> Ray,
) -> usize {
    let bf = BruteForce::new(tris);
    let mut hits = 0;
    for y in 0..h {
        for x in 0..w {
            let r = ray(x, y);
            let got = z[y * w + x];
            match bf.intersect(&r) {
                None => assert_eq!(got, f32::INFINITY, "pixel ({x}, {y}) should miss"),
                Some(hit) => {
                    hits += 1;
                    let want = hit.t * r.dir.length();
                    assert!(
                        (got - want).abs() <= 1e-5 * want.max(1.0),
                        "pixel ({x}, {y}): Z {got}, brute force {want}"
                    );
                }
            }
        }
    }
    hits
}

#[test]
fn depth_matches_brute_force_at_every_pixel() {
    let dir = temp_dir("depth");
    let scene_path = write_scene(&dir);
    let scene = import::load(&scene_path).unwrap();
    let (w, h) = (80usize, 60usize);
    let opts = RenderOptions {
        output: dir.join("out/f.###.exr"),
        frames: Some(FrameRange { start: 0, end: 25 }.into()),
        shard: Some(render::Shard {
            index: 0,
            count: 12,
        }), // frames 0, 12, 24
        width: w as u32,
        height: h as u32,
        aovs: Aovs {
            depth: true,
            normal: false,
            albedo: false,
            ..Default::default()
        },
        spp: 2,
        preview: Some(render::PreviewOptions {
            frame: Some(12),
            path: dir.join("prev/preview.png"),
        }),
        ..Default::default()
    };
    let summary = render::render_sequence(&scene, &opts, &mut quiet).unwrap();
    assert_eq!(summary.rendered, 3);
    // The preview is frame 12, tone-mapped: the same image as the EXR, in sRGB bytes.
    assert_eq!(summary.preview, Some(dir.join("prev/preview.png")));
    let png = image::open(dir.join("prev/preview.png")).unwrap().to_rgb8();
    assert_eq!(png.dimensions(), (w as u32, h as u32));
    let (_, _, c12) = read_exr(&dir.join("out/f.012.exr"));
    for (i, px) in png.pixels().enumerate() {
        // The EXR holds half floats; the PNG was made from the float frame.
        let r = render::linear_to_srgb8(channel(&c12, "R")[i]);
        assert!(px.0[0].abs_diff(r) <= 1, "pixel {i}: {} vs {r}", px.0[0]);
    }
    assert!(
        summary.plan.split.dynamic_triangles == 12 && summary.plan.split.static_triangles == 18
    );
    for frame in [0u32, 12, 24] {
        let (fw, fh, chans) = read_exr(&dir.join(format!("out/f.{frame:03}.exr")));
        assert_eq!((fw, fh), (w, h));
        let t = frame as f32 / 24.0;
        let cam = scene.camera_at(ClipSelection::All, t, None).unwrap();
        let rot = Mat3::from_quat(cam.rotation);
        let tan_half = (cam.yfov().unwrap() / 2.0).tan();
        let aspect = w as f32 / h as f32;
        let tris = all_triangles(&scene, t);
        let hits = check_depth(channel(&chans, "Z"), w, h, &tris, |x, y| {
            contract_ray(rot, cam.position, tan_half, aspect, (w, h), (x, y))
        });
        assert!(
            hits > w * h / 2 && hits < w * h,
            "frame {frame}: {hits} hits"
        );
    }

    // A camera given outright, and the named camera with its own aspect ratio.
    let look = render::LookAt {
        from: Vec3::new(-3.0, 1.0, 4.0),
        at: Vec3::new(0.5, 0.5, 0.0),
        up: Vec3::Y,
        yfov_deg: 50.0,
    };
    let opts2 = RenderOptions {
        output: dir.join("look.exr"),
        frames: Some(FrameRange { start: 7, end: 8 }.into()),
        look_at: Some(look),
        shard: None,
        // One sample: the AOVs come from the shaded primary rays themselves.
        spp: 1,
        ..opts.clone()
    };
    render::render_sequence(&scene, &opts2, &mut quiet).unwrap();
    let (_, _, chans) = read_exr(&dir.join("look.exr"));
    let fwd = (look.at - look.from).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let rot = Mat3::from_cols(right, right.cross(fwd), -fwd);
    check_depth(
        channel(&chans, "Z"),
        w,
        h,
        &all_triangles(&scene, 7.0 / 24.0),
        |x, y| {
            contract_ray(
                rot,
                look.from,
                (25f32).to_radians().tan(),
                w as f32 / h as f32,
                (w, h),
                (x, y),
            )
        },
    );

    let opts3 = RenderOptions {
        output: dir.join("side.exr"),
        camera: Some("side".into()),
        look_at: None,
        ..opts2
    };
    render::render_sequence(&scene, &opts3, &mut quiet).unwrap();
    let (_, _, chans) = read_exr(&dir.join("side.exr"));
    let cam = scene
        .camera_at(ClipSelection::All, 0.0, Some("side"))
        .unwrap();
    let hits = check_depth(
        channel(&chans, "Z"),
        w,
        h,
        &all_triangles(&scene, 7.0 / 24.0),
        |x, y| {
            // The side camera records aspect 1, but pixels are square (issue 24): the
            // horizontal extent follows the image, as the contract says.
            contract_ray(
                Mat3::from_quat(cam.rotation),
                cam.position,
                0.5f32.tan(),
                w as f32 / h as f32,
                (w, h),
                (x, y),
            )
        },
    );
    assert!(hits > 0);
}

const READER: &str = r#"
import sys, json, OpenEXR, numpy as np
f = OpenEXR.File(sys.argv[1], separate_channels=True)
h = f.header()
(x0, y0), (x1, y1) = h["dataWindow"]
out = {"width": int(x1 - x0 + 1), "height": int(y1 - y0 + 1), "compression": str(h["compression"]), "channels": {}}
blob = bytearray()
for name, ch in sorted(f.channels().items()):
    px = ch.pixels
    out["channels"][name] = {"type": str(px.dtype), "offset": len(blob) // 4, "shape": list(px.shape)}
    blob += px.astype(np.float32).tobytes()
open(sys.argv[2], "wb").write(bytes(blob))
print(json.dumps(out))
"#;

fn openexr_available() -> bool {
    Command::new("python3")
        .args(["-c", "import OpenEXR, numpy"])
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn openexr_reads_our_files_and_agrees() {
    assert!(
        openexr_available(),
        "OpenEXR's Python bindings are missing: run the install step of .ci/run \
         (python3 -m pip install OpenEXR), which CI always runs"
    );
    let dir = temp_dir("openexr");
    let scene = import::load(&write_scene(&dir)).unwrap();
    let aovs = Aovs {
        depth: true,
        normal: true,
        albedo: true,
        ..Default::default()
    };
    for (pixel, rgba_type) in [(PixelType::Half, "float16"), (PixelType::Float, "float32")] {
        let out = dir.join(format!("{rgba_type}.exr"));
        let opts = RenderOptions {
            output: out.clone(),
            frames: Some(FrameRange { start: 5, end: 6 }.into()),
            width: 48,
            height: 32,
            aovs,
            pixel_type: pixel,
            ..Default::default()
        };
        render::render_sequence(&scene, &opts, &mut quiet).unwrap();
        let blob = dir.join("blob.f32");
        let o = Command::new("python3")
            .args(["-c", READER])
            .arg(&out)
            .arg(&blob)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let meta: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(meta["width"], 48);
        assert_eq!(meta["height"], 32);
        let names: Vec<&str> = meta["channels"]
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .collect();
        assert_eq!(names, render::channel_names(aovs));
        let bytes = std::fs::read(&blob).unwrap();
        let floats: Vec<f32> = bytes
            .chunks(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        let (_, _, ours) = read_exr(&out);
        let mut lit = 0;
        for (name, values) in &ours {
            let m = &meta["channels"][name.as_str()];
            let want_type = if ["R", "G", "B", "A"].contains(&name.as_str()) {
                rgba_type
            } else {
                "float32"
            };
            assert_eq!(m["type"], want_type, "{name}");
            assert_eq!(m["shape"], serde_json::json!([32, 48]), "{name}");
            let off = m["offset"].as_u64().unwrap() as usize;
            let theirs = &floats[off..off + values.len()];
            for (i, (a, b)) in values.iter().zip(theirs).enumerate() {
                assert!(
                    a == b || (a.is_nan() && b.is_nan()),
                    "{name}[{i}]: exr crate {a}, OpenEXR {b}"
                );
            }
            if name == "R" {
                lit = values.iter().filter(|v| **v > 0.01).count();
            }
        }
        assert!(lit > 48 * 32 / 2, "most pixels are lit ({lit})");
        // Misses: Z = +inf, alpha 0, normal 0.
        let z = channel(&ours, "Z");
        let a = channel(&ours, "A");
        for i in 0..z.len() {
            assert_eq!(
                z[i].is_infinite(),
                a[i] == 0.0,
                "pixel {i}: Z {} alpha {}",
                z[i],
                a[i]
            );
        }
    }
}

/// One pixel's RGB from a float render of `scene` through a look-at camera.
fn render_pixels(
    scene: &Scene,
    dir: &Path,
    name: &str,
    look: render::LookAt,
    size: (u32, u32),
    tweak: impl Fn(&mut RenderOptions),
) -> (usize, Vec<(String, Vec<f32>)>) {
    let out = dir.join(format!("{name}.exr"));
    let mut opts = RenderOptions {
        output: out.clone(),
        frames: Some(FrameRange { start: 0, end: 1 }.into()),
        width: size.0,
        height: size.1,
        look_at: Some(look),
        pixel_type: PixelType::Float,
        aovs: Aovs {
            depth: true,
            normal: true,
            albedo: true,
            ..Default::default()
        },
        ..Default::default()
    };
    tweak(&mut opts);
    render::render_sequence(scene, &opts, &mut quiet).unwrap();
    let (w, _, chans) = read_exr(&out);
    (w, chans)
}

fn rgb(chans: &[(String, Vec<f32>)], i: usize) -> Vec3 {
    Vec3::new(
        channel(chans, "R")[i],
        channel(chans, "G")[i],
        channel(chans, "B")[i],
    )
}

#[test]
fn shading_follows_the_model() {
    use common::build::{diffuse, placed, SceneBuilder};
    use subfield::scene::{Falloff, LightDef, LightKind, Material, Mesh, Node};
    let dir = temp_dir("shading");
    // A floor lit by a directional light straight down (E = 2 lux), a blocker casting
    // a shadow, a mirror facing the camera with a red emitter behind the camera.
    let mut b = SceneBuilder::new();
    let unnamed = |m: Material| Material { name: None, ..m };
    let white = b.add_material(unnamed(diffuse("", Vec4::new(0.5, 0.5, 0.5, 1.0), 1.0)));
    let mirror = b.add_material(unnamed(Material {
        metallic: 1.0,
        ..diffuse("", Vec4::ONE, 0.0)
    }));
    let glass = b.add_material(unnamed(Material {
        transmission: 1.0,
        ior: 1.5,
        ..diffuse("", Vec4::ONE, 0.0)
    }));
    let mut slab = render_scene::cube(Vec3::new(1.0, 0.1, 1.0), glass);
    for p in &mut slab.positions {
        *p += Vec3::new(8.0, 0.5, 0.0);
    }
    let red = b.add_material(unnamed(Material {
        emissive: Vec3::new(1.0, 0.0, 0.0),
        ..diffuse("", Vec4::new(0.0, 0.0, 0.0, 1.0), 1.0)
    }));
    let mesh = b.add_mesh(Mesh {
        primitives: vec![
            render_scene::quad(Vec3::ZERO, Vec3::Z * 10.0, Vec3::X * 10.0, white),
            // Blocker: a horizontal square at y = 1 over x in [4, 6] (its shadow falls straight down).
            render_scene::quad(Vec3::new(5.0, 1.0, 0.0), Vec3::Z, Vec3::X, white),
            // Mirror at x = -5 facing +X.
            render_scene::quad(
                Vec3::new(-5.0, 1.0, 0.0),
                Vec3::Y * 1.0,
                Vec3::Z * 1.0,
                mirror,
            ),
            // Red emitter at x = -2 facing -X (towards the mirror), above the floor.
            render_scene::quad(Vec3::new(-2.0, 1.0, 0.0), Vec3::Z * 1.0, Vec3::Y * 1.0, red),
            // A glass slab over x in [7, 9], y in [0.4, 0.6].
            slab,
        ],
        ..Default::default()
    });
    let sun = b.add_light(LightDef {
        name: None,
        kind: LightKind::Directional,
        color: Vec3::ONE,
        intensity: 2.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let n = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    let l = b.add_node(Node {
        light: Some(sun),
        transform: placed(
            Vec3::ZERO,
            glam::Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
        ),
        ..Default::default()
    });
    b.add_root(n);
    b.add_root(l);
    let path = dir.join("s.glb");
    import::write_gltf(&b.finish(), &path).unwrap();
    let scene = import::load(&path).unwrap();
    let ambient = 0.05;
    let down = |x: f32| render::LookAt {
        from: Vec3::new(x, 3.0, 0.0),
        at: Vec3::new(x, 0.0, 0.0),
        up: Vec3::Z,
        yfov_deg: 10.0,
    };
    // Lit floor: 0.5/π · 2 · cos 0 + 0.5 · ambient (roughness 1: no highlight).
    let (_, c) = render_pixels(&scene, &dir, "lit", down(2.0), (3, 3), |_| {});
    let want = 0.5 / std::f32::consts::PI * 2.0 + 0.5 * ambient;
    let got = rgb(&c, 4);
    assert!(
        got.abs_diff_eq(Vec3::splat(want), 1e-4),
        "lit floor {got}, want {want}"
    );
    assert!((channel(&c, "Z")[4] - 3.0).abs() < 1e-4);
    assert!(Vec3::from_slice(&[
        channel(&c, "N.X")[4],
        channel(&c, "N.Y")[4],
        channel(&c, "N.Z")[4]
    ])
    .abs_diff_eq(Vec3::Y, 1e-5));
    assert!((channel(&c, "albedo.G")[4] - 0.5).abs() < 1e-6);
    // Under the blocker (looking up from below it, the floor is in shadow): ambient only.
    let (_, c) = render_pixels(
        &scene,
        &dir,
        "shadow",
        render::LookAt {
            from: Vec3::new(5.0, 0.5, 0.0),
            at: Vec3::new(5.0, 0.0, 0.0),
            up: Vec3::Z,
            yfov_deg: 10.0,
        },
        (3, 3),
        |_| {},
    );
    let got = rgb(&c, 4);
    assert!(
        got.abs_diff_eq(Vec3::splat(0.5 * ambient), 1e-5),
        "shadowed floor {got}"
    );
    // The mirror shows the red emitter (radiance 1 in red, reflectance F = 1 for a
    // white metal); with depth 0 it shows no reflection.
    let at_mirror = render::LookAt {
        from: Vec3::new(-3.0, 1.0, 0.0),
        at: Vec3::new(-5.0, 1.0, 0.0),
        up: Vec3::Y,
        yfov_deg: 10.0,
    };
    let (_, c) = render_pixels(&scene, &dir, "mirror", at_mirror, (3, 3), |_| {});
    let got = rgb(&c, 4);
    assert!(
        (got.x - 1.0).abs() < 1e-3 && got.y < 1e-3 && got.z < 1e-3,
        "mirror {got}"
    );
    let (_, c) = render_pixels(&scene, &dir, "mirror0", at_mirror, (3, 3), |o| {
        o.max_depth = 0
    });
    assert!(rgb(&c, 4).x < 1e-3, "no reflection at depth 0");
    // At 45° (off the sun's glint) through the glass slab onto the floor in its
    // shadow: the floor's ambient radiance times the Fresnel transmittance of the two
    // interfaces (the same angles in and out), plus light bounced inside the slab
    // (about 0.3 %); nothing at depth 0 (clear glass has no diffuse part).
    let tilted = render::LookAt {
        from: Vec3::new(11.0, 3.0, 0.0),
        at: Vec3::new(8.0, 0.0, 0.0),
        up: Vec3::Z,
        yfov_deg: 2.0,
    };
    let (ci, n) = (std::f32::consts::FRAC_1_SQRT_2, 1.5f32);
    let ct = (1.0 - (ci / n).powi(2)).sqrt();
    let rs = ((ci - n * ct) / (ci + n * ct)).powi(2);
    let rp = ((n * ci - ct) / (n * ci + ct)).powi(2);
    let t = 1.0 - 0.5 * (rs + rp);
    let want = t * t * 0.5 * ambient;
    let (_, c) = render_pixels(&scene, &dir, "glass", tilted, (3, 3), |_| {});
    let got = rgb(&c, 4);
    assert!(
        got.abs_diff_eq(Vec3::splat(want), want * 0.01),
        "through glass {got}, want {want}"
    );
    let (_, c) = render_pixels(&scene, &dir, "glass0", tilted, (3, 3), |o| o.max_depth = 0);
    assert!(rgb(&c, 4).max_element() < 1e-3, "{}", rgb(&c, 4));
}

#[test]
fn textures_glass_and_alpha() {
    use subfield::scene::{AlphaMode, TextureRef};
    let dir = temp_dir("texture");
    let mut scene = import::load(&write_scene(&dir)).unwrap();
    // A 2×2 checker (sRGB 255 / 0) on the floor, nearest filtering, repeated 1×.
    let checker = common::build::add_checker(&mut scene);
    let floor = scene
        .materials
        .iter()
        .position(|m| m.name.as_deref() == Some("floor"))
        .unwrap();
    scene.materials[floor].base_color_texture = Some(TextureRef {
        texture: checker,
        tex_coord: 0,
        transform: None,
    });
    scene.materials[floor].base_color = Vec4::ONE;
    // Looking straight down at the floor's centre: uv (0.5, 0.5) is where four texels
    // meet; the floor quad spans z in [-5, 5] (u) and x in [-5, 5] (v).
    let look = render::LookAt {
        from: Vec3::new(-2.5, 2.0, -2.5),
        at: Vec3::new(-2.5, 0.0, -2.5),
        up: Vec3::X,
        yfov_deg: 5.0,
    };
    let (_, c) = render_pixels(&scene, &dir, "checker_a", look, (3, 3), |_| {});
    let a = channel(&c, "albedo.R")[4];
    let look_b = render::LookAt {
        from: Vec3::new(-2.5, 2.0, 2.5),
        at: Vec3::new(-2.5, 0.0, 2.5),
        ..look
    };
    let (_, c) = render_pixels(&scene, &dir, "checker_b", look_b, (3, 3), |_| {});
    let b = channel(&c, "albedo.R")[4];
    assert_eq!((a.min(b), a.max(b)), (0.0, 1.0), "checker texels {a} {b}");

    // Alpha mask: a fully cut-out floor shows what is below it (nothing): alpha 0 where
    // only the floor was.
    let (_, before) = render_pixels(&scene, &dir, "mask0", look, (3, 3), |_| {});
    assert_eq!(channel(&before, "A")[4], 1.0);
    scene.materials[floor].alpha_mode = AlphaMode::Mask { cutoff: 0.5 };
    scene.materials[floor].base_color = Vec4::new(1.0, 1.0, 1.0, 0.2);
    let (_, after) = render_pixels(&scene, &dir, "mask1", look, (3, 3), |_| {});
    assert_eq!(channel(&after, "A")[4], 0.0);
    // Z stays the first hit along the ray (the cut-out floor), as the contract says.
    assert!((channel(&after, "Z")[4] - 2.0).abs() < 1e-4);
}

#[test]
fn every_shared_gltf_renders_two_frames() {
    let Some(dir) = common::shared_gltf() else {
        return;
    };
    let out = temp_dir("shared");
    let mut rendered = 0;
    for path in common::gltf_files(&dir) {
        let scene = match import::load(&path) {
            Ok(s) => s,
            // Import errors are the importer's tests' business (some samples are
            // deliberately broken); the renderer must render whatever imports.
            Err(e) => {
                eprintln!("not imported: {}: {e}", path.display());
                continue;
            }
        };
        let opts = RenderOptions {
            output: out.join(format!("r{rendered}.#.exr")),
            frames: Some(FrameRange { start: 0, end: 2 }.into()),
            width: 32,
            height: 24,
            aovs: Aovs {
                depth: true,
                normal: true,
                albedo: true,
                ..Default::default()
            },
            ..Default::default()
        };
        let s = render::render_sequence(&scene, &opts, &mut quiet)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(s.rendered, 2, "{}", path.display());
        for f in 0..2 {
            let p: PathBuf = out.join(format!("r{rendered}.{f}.exr"));
            assert!(
                render::is_complete(
                    &p,
                    32,
                    24,
                    opts.aovs,
                    PixelType::Half,
                    &opts.options_string(s.plan.fps, s.plan.ambient, s.plan.default_light)
                ),
                "{}",
                p.display()
            );
        }
        rendered += 1;
    }
    eprintln!("rendered {rendered} shared scenes");
    assert!(rendered > 10);
    let _ = std::fs::remove_dir_all(&out);
}
