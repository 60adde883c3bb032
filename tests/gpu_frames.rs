//! The GPU frame path (`--device gpu` on a scene inside its subset, docs/GPU.md): whole
//! frames traced and shaded on the GPU agree with `--device cpu` within a stated bound,
//! two GPU runs give the same bytes, a scene outside the subset falls back to CPU
//! shading (bit for bit the CPU's frames, as before) and says why in the log, and the
//! rays the GPU makes carry the CPU's shear to the bit.
//!
//! The bound (`check_close`): the camera rays are the CPU's and so are their hits, so
//! `Z` is equal on at least 99.9 % of the pixels (in fact on all); the RGB mean absolute
//! difference is at most 1e-3 (times the image's mean RGB where that is above 1); and
//! outside a one-pixel band around the Z discontinuities, no pixel's channel differs by
//! more than [`PIXEL_BOUND`] (times the mean where above 1). Measured on lavapipe: mean
//! differences of 1e-7 to 2e-7 and at most 1e-4 in any pixel (the GPU's sqrt, division
//! and pow are not the CPU's to the last bit). A reflected or refracted ray made on the
//! GPU differs from the CPU's in its last bits, so on another driver one that grazes an
//! edge seen in a mirror or through glass could meet the other side of it: such a pixel
//! would break the per-pixel bound while the mean stays far inside its own.
//!
//! Needs a GPU adapter (lavapipe in CI): tests/common/gpu.rs.

mod common;

use std::path::{Path, PathBuf};

use common::build::{diffuse, mesh, placed, SceneBuilder};
use common::exr_read::read_exr;
use common::farm::{ok, ok_with, s, stderr};
use common::render_scene::{
    camera_and_lights, cube, files_under, floor_and_mirror, quad, room_materials, scene, temp_dir,
    tumbling, with_textured_lamp, write_scene,
};
use glam::Vec2;
use glam::{Quat, Vec3, Vec4};
use subfield::geometry::Ray;
use subfield::gpu::{packed_on_cpu, GpuShading};
use subfield::scene::{
    AlphaMode, CameraDef, Image, Projection, Texture, TextureRef, UvTransform, Wrap,
};
use subfield::scene::{Animation, Falloff, LightDef, LightKind, Material, Node, Scene};

/// Largest difference a pixel's channel may have outside the Z edges' band (relative to
/// the image's mean where that is above 1).
const PIXEL_BOUND: f32 = 1e-3;

/// A room inside the frame path's subset: a diffuse floor, a metal mirror, a half
/// mirror (polished, half metallic), a coloured metal, a glass cube (refraction and
/// Fresnel reflection), a rough red cube that moves and turns, a point, a spot (with a
/// range) and a directional light.
fn subset_scene() -> Scene {
    let mut b = SceneBuilder::new();
    let (grey, mirror) = room_materials(&mut b);
    let half = b.add_material(Material {
        metallic: 0.5,
        ..diffuse("half mirror", Vec4::new(0.3, 0.5, 0.8, 1.0), 0.01)
    });
    let gold = b.add_material(Material {
        metallic: 1.0,
        ..diffuse("gold", Vec4::new(1.0, 0.8, 0.3, 1.0), 0.6)
    });
    let glass = b.add_material(Material {
        transmission: 1.0,
        ior: 1.5,
        double_sided: true,
        ..diffuse("glass", Vec4::ONE, 0.0)
    });
    let red = b.add_material(diffuse("red", Vec4::new(0.8, 0.1, 0.1, 1.0), 0.4));
    let [floor, mirror_quad] = floor_and_mirror(5.0, grey, mirror);
    let statics = b.add_mesh(mesh(
        "room",
        vec![
            floor,
            mirror_quad,
            quad(
                Vec3::new(-3.0, 1.0, -1.0),
                Vec3::Z * 1.0,
                Vec3::Y * 1.0,
                half,
            ),
            cube(Vec3::splat(0.3), gold),
        ],
    ));
    let glass_cube = b.add_mesh(mesh("glass", vec![cube(Vec3::splat(0.5), glass)]));
    let red_cube = b.add_mesh(mesh("mover", vec![cube(Vec3::new(0.4, 0.4, 0.4), red)]));
    let spot = b.add_light(LightDef {
        name: Some("spot".into()),
        kind: LightKind::Spot {
            inner_cone_angle: 0.2,
            outer_cone_angle: 0.5,
        },
        color: Vec3::new(0.6, 0.8, 1.0),
        intensity: 60.0,
        range: Some(12.0),
        falloff: Falloff::InverseSquare,
    });
    let room = b.add_node(Node {
        name: Some("room".into()),
        mesh: Some(statics),
        ..Default::default()
    });
    let glass_node = b.add_node(Node {
        name: Some("glass".into()),
        mesh: Some(glass_cube),
        transform: placed(Vec3::new(-1.5, 0.5, 0.0), Quat::IDENTITY),
        ..Default::default()
    });
    let mover = b.add_node(Node {
        name: Some("mover".into()),
        mesh: Some(red_cube),
        transform: placed(Vec3::new(1.0, 0.4, 0.5), Quat::IDENTITY),
        ..Default::default()
    });
    let spot_node = b.add_node(Node {
        name: Some("spot".into()),
        light: Some(spot),
        // Down onto the floor in front of the mirror.
        transform: placed(
            Vec3::new(0.5, 4.0, 0.5),
            Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
        ),
        ..Default::default()
    });
    let [camera, bulb, sun_node] = camera_and_lights(&mut b);
    for n in [room, glass_node, mover, camera, bulb, spot_node, sun_node] {
        b.add_root(n);
    }
    b.add_animation(Animation {
        name: Some("move".into()),
        channels: tumbling(mover, Vec3::new(-0.5, 1.2, 1.0)).into(),
    });
    b.scene.fps = Some(24.0);
    b.finish()
}

/// Renders `scene` on `device` into `dir/folder` with `extra` flags; the run's stderr.
fn render(scene: &Path, dir: &Path, device: &str, folder: &str, extra: &[&str]) -> String {
    render_at("64x48", scene, dir, device, folder, extra)
}

/// [`render`] at image size `size`.
fn render_at(
    size: &str,
    scene: &Path,
    dir: &Path,
    device: &str,
    folder: &str,
    extra: &[&str],
) -> String {
    let out = dir.join(format!("{folder}/f.##.exr"));
    let mut args = vec![
        "render",
        s(scene),
        "-o",
        s(&out),
        "--size",
        size,
        "--float",
        "--device",
        device,
    ];
    // Every centre-ray AOV and Cryptomatte, unless `extra` names its own.
    if !extra.contains(&"--aov") {
        args.extend(["--aov", "depth,normal,albedo,position,motion,cryptomatte"]);
    }
    args.extend_from_slice(extra);
    // On the GPU, shading on the CPU where `device` says `gpu-cpu` (the diagnostic
    // switch `SUBFIELD_GPU_SHADING=cpu`).
    if device == "gpu-cpu" {
        let i = args
            .iter()
            .position(|a| *a == "gpu-cpu")
            .unwrap_or_default();
        args[i] = "gpu";
        return stderr(&ok_with(&args, &[("SUBFIELD_GPU_SHADING", "cpu")]));
    }
    stderr(&ok(&args))
}

fn channel<'a>(c: &'a [(String, Vec<f32>)], name: &str) -> &'a [f32] {
    &c.iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no channel {name}"))
        .1
}

/// What two frames' differences came to.
#[derive(Debug)]
struct Diff {
    z_equal: f64,
    mean_abs: f32,
    mean: f32,
    max_outside_band: f32,
}

fn compare(a: &Path, b: &Path) -> Diff {
    let (w, h, ca) = read_exr(a);
    let (wb, hb, cb) = read_exr(b);
    assert_eq!((w, h), (wb, hb));
    // Coverage and the AOVs come from the camera rays' (or the centre rays') hits, which
    // are the CPU's: equal to the bit.
    assert!(ca.iter().any(|(n, _)| n.starts_with("CryptoObject")));
    // The colours: the beauty's and the light-path passes' (their RGB channels).
    let colour = |n: &str| {
        ["R", "G", "B"].contains(&n)
            || ["diffuse.", "specular.", "transmission.", "emission."]
                .iter()
                .any(|p| n.starts_with(p))
    };
    for ((na, va), (nb, vb)) in ca.iter().zip(&cb) {
        assert_eq!(na, nb);
        if !colour(na) {
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(va), bits(vb), "{}: channel {na} differs", b.display());
        }
    }
    let (za, zb) = (channel(&ca, "Z"), channel(&cb, "Z"));
    let n = w * h;
    let z_equal = za
        .iter()
        .zip(zb)
        .filter(|(x, y)| x.to_bits() == y.to_bits())
        .count() as f64
        / n as f64;
    // The band: pixels with a neighbour (8-connected) whose Z differs by over 1 %.
    let edge = |i: usize, j: usize| {
        let (p, q) = (za[i], za[j]);
        if p.is_infinite() || q.is_infinite() {
            return p.is_infinite() != q.is_infinite();
        }
        (p - q).abs() > 0.01 * p.abs().max(q.abs())
    };
    let mut band = vec![false; n];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            for (dx, dy) in [(1i64, 0i64), (0, 1), (1, 1), (1, -1)] {
                let (x2, y2) = (x as i64 + dx, y as i64 + dy);
                if x2 < 0 || y2 < 0 || x2 >= w as i64 || y2 >= h as i64 {
                    continue;
                }
                let j = y2 as usize * w + x2 as usize;
                if edge(i, j) {
                    band[i] = true;
                    band[j] = true;
                }
            }
        }
    }
    let mut sum_abs = 0.0f64;
    let mut sum = 0.0f64;
    let mut per_pixel = vec![0.0f32; n];
    let colours: Vec<&str> = ca
        .iter()
        .map(|(c, _)| c.as_str())
        .filter(|c| colour(c))
        .collect();
    for &c in &colours {
        let (x, y) = (channel(&ca, c), channel(&cb, c));
        for i in 0..n {
            let d = (x[i] - y[i]).abs();
            assert!(y[i].is_finite(), "{}: {c} at {i} is {}", b.display(), y[i]);
            sum_abs += f64::from(d);
            sum += f64::from(x[i]);
            per_pixel[i] = per_pixel[i].max(d);
        }
    }
    let count = (colours.len() * n) as f64;
    let mean = (sum / count) as f32;
    let scale = mean.max(1.0);
    Diff {
        z_equal,
        mean_abs: (sum_abs / count) as f32,
        mean,
        max_outside_band: (0..n)
            .filter(|&i| !band[i])
            .map(|i| per_pixel[i] / scale)
            .fold(0.0, f32::max),
    }
}

/// The bound of the module docs, frame by frame; the differences found.
fn check_close(dir: &Path, cpu: &str, gpu: &str) -> Vec<Diff> {
    let frames = files_under(&dir.join(cpu));
    assert!(!frames.is_empty());
    assert_eq!(frames, files_under(&dir.join(gpu)));
    let mut out = Vec::new();
    for f in &frames {
        let d = compare(&dir.join(cpu).join(f), &dir.join(gpu).join(f));
        // Straight to stderr, so `--nocapture` shows the measured differences.
        eprintln!("{gpu} {}: {d:?}", f.display());
        assert!(
            d.z_equal >= 0.999,
            "{}: Z equal on {}",
            f.display(),
            d.z_equal
        );
        assert!(
            d.mean_abs <= 1e-3 * d.mean.max(1.0),
            "{}: mean |ΔRGB| {} (mean {})",
            f.display(),
            d.mean_abs,
            d.mean
        );
        assert!(
            d.max_outside_band <= PIXEL_BOUND,
            "{}: a pixel off by {} (relative) outside the Z edges ({d:?})",
            f.display(),
            d.max_outside_band
        );
        out.push(d);
    }
    out
}

fn write(dir: &Path, scene: &Scene) -> PathBuf {
    let p = dir.join("scene.glb");
    subfield::import::write_gltf(scene, &p).unwrap();
    p
}

/// Three frames of the moving cube, one sample a pixel, depth 3 (mirror in glass in
/// mirror); then two samples at depth 1 with an overscan border, an exposure and a
/// background that the mirrors and the glass show; then three samples at depth 0; each
/// against the CPU (RGB within the bound, alpha and the AOVs to the bit). The first
/// again, whole and in two shards: the same bytes.
#[test]
fn gpu_frames_agree_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames");
    let scene = write(&dir, &subset_scene());
    let a = ["--frames", "3..6", "--spp", "1", "--max-depth", "3"];
    let stats = |name: &str| {
        let p = dir.join(name);
        (p.clone(), p.to_str().unwrap().to_string())
    };
    let (cpu_stats, cs) = stats("cpu1.csv");
    let (gpu_stats, gs) = stats("gpu1.csv");
    render(
        &scene,
        &dir,
        "cpu",
        "cpu1",
        &[&a[..], &["--stats", &cs]].concat(),
    );
    let log = render(
        &scene,
        &dir,
        "gpu",
        "gpu1",
        &[&a[..], &["--stats", &gs]].concat(),
    );
    // The same rays: camera, shadow and secondary counts (columns 6-8) frame by frame,
    // so the GPU's shading made the CPU's decisions (which lights, which rays).
    let counts = |p: &Path| -> Vec<Vec<String>> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').skip(6).take(3).map(String::from).collect())
            .collect()
    };
    assert_eq!(counts(&cpu_stats), counts(&gpu_stats));
    assert_eq!(counts(&cpu_stats).len(), 3);
    assert!(
        !log.contains("shading on the CPU"),
        "the subset scene fell back: {log}"
    );
    check_close(&dir, "cpu1", "gpu1");

    let b = [
        "--frames",
        "12",
        "--spp",
        "2",
        "--max-depth",
        "1",
        "--overscan",
        "2",
        "--exposure",
        "0.5",
        "--background",
        "0.2,0.3,0.4",
    ];
    render(&scene, &dir, "cpu", "cpu2", &b);
    render(&scene, &dir, "gpu", "gpu2", &b);
    check_close(&dir, "cpu2", "gpu2");

    // No secondary rays at all, three samples (a 2x2 jitter grid, one cell empty).
    let c = ["--frames", "20", "--spp", "3", "--max-depth", "0"];
    render(&scene, &dir, "cpu", "cpu3", &c);
    render(&scene, &dir, "gpu", "gpu3", &c);
    check_close(&dir, "cpu3", "gpu3");

    // Twice on the GPU, and in two shards: the same bytes.
    render(&scene, &dir, "gpu", "gpu1again", &a);
    for shard in ["0/2", "1/2"] {
        let mut sharded = a.to_vec();
        sharded.extend(["--shard", shard]);
        render(&scene, &dir, "gpu", "gpu1sharded", &sharded);
    }
    for again in ["gpu1again", "gpu1sharded"] {
        assert_eq!(
            files_under(&dir.join("gpu1")),
            files_under(&dir.join(again))
        );
        for f in files_under(&dir.join("gpu1")) {
            assert_eq!(
                std::fs::read(dir.join("gpu1").join(&f)).unwrap(),
                std::fs::read(dir.join(again).join(&f)).unwrap(),
                "{}: {again} differs from the first GPU run",
                f.display()
            );
        }
    }
}

/// Glossy (GGX) reflection on the GPU: the subset's room with its half mirror and its
/// gold cube made glossy (roughness 0.2 and 0.3: one reflection ray a hit drawn from the
/// GGX lobe). The random numbers are the CPU's seeds to the bit, so the same directions
/// are drawn and the frames meet the bound (other numbers would put the GPU's noise
/// where the CPU has none, far past it), two samples a pixel, depth 2; the same ray
/// counts; two GPU runs the same bytes.
#[test]
fn glossy_reflection_agrees_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-glossy");
    let mut scene = subset_scene();
    for m in &mut scene.materials {
        match m.name.as_deref() {
            Some("half mirror") => m.roughness = 0.2,
            Some("gold") => m.roughness = 0.3,
            _ => {}
        }
    }
    let scene = write(&dir, &scene);
    let a = ["--frames", "4..6", "--spp", "2", "--max-depth", "2"];
    agree(&dir, &scene, "glossy", &a);
}

/// Renders `scene` with `a` on both devices into `dir/{name}-cpu` and `{name}-gpu` and
/// checks them: the GPU shaded (no note), the same ray counts frame by frame, the
/// bound, and a second GPU run, one frame in flight, the same bytes.
fn agree(dir: &Path, scene: &Path, name: &str, a: &[&str]) -> Vec<Diff> {
    let (cpu, gpu) = (format!("{name}-cpu"), format!("{name}-gpu"));
    let (cs, gs) = (
        dir.join(format!("{cpu}.csv")),
        dir.join(format!("{gpu}.csv")),
    );
    let (c, g) = (cs.to_str().unwrap(), gs.to_str().unwrap());
    render(scene, dir, "cpu", &cpu, &[a, &["--stats", c]].concat());
    let log = render(scene, dir, "gpu", &gpu, &[a, &["--stats", g]].concat());
    assert!(
        !log.contains("shading on the CPU"),
        "{name} fell back: {log}"
    );
    let counts = |p: &Path| -> Vec<Vec<String>> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').skip(6).take(3).map(String::from).collect())
            .collect()
    };
    assert_eq!(counts(&cs), counts(&gs), "{name}: ray counts");
    let diffs = check_close(dir, &cpu, &gpu);
    // Again one frame at a time (the first run renders two at once, the GPU's default
    // where the sequence has two frames or more): the same bytes.
    let again = format!("{name}-again");
    render(
        scene,
        dir,
        "gpu",
        &again,
        &[a, &["--frames-in-flight", "1"]].concat(),
    );
    for f in files_under(&dir.join(&gpu)) {
        assert_eq!(
            std::fs::read(dir.join(&gpu).join(&f)).unwrap(),
            std::fs::read(dir.join(&again).join(&f)).unwrap(),
            "{name} {}: a second GPU run (one frame in flight) differs",
            f.display()
        );
    }
    diffs
}

/// Area lights (emissive triangles) on the GPU: the shadow rays to them are drawn with
/// the CPU's numbers (the items' seeds), emitters by the CPU's table, points by its
/// strata, so the frames meet the bound and the ray counts are the CPU's. The room's
/// red cube made a two-sided emitter (a moving area light) at one sample a pixel, depth
/// 2 (its light seen in the mirror and through glass), and at three samples, depth 1
/// (three light samples a camera ray's hit, nine strata a pixel); the shared test
/// scene's one-sided lamp at two samples.
#[test]
fn area_lights_agree_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-area");
    let mut glowing = subset_scene();
    for m in &mut glowing.materials {
        if m.name.as_deref() == Some("red") {
            m.emissive = Vec3::new(0.9, 0.2, 0.1);
            m.emissive_strength = 3.0;
            m.double_sided = true;
        }
    }
    let glowing = write(&dir, &glowing);
    let one = ["--frames", "4..6", "--spp", "1", "--max-depth", "2"];
    agree(&dir, &glowing, "moving1", &one);
    let three = ["--frames", "5", "--spp", "3", "--max-depth", "1"];
    agree(&dir, &glowing, "moving3", &three);
    // Its own folder: `write_scene` and `write` both name the file scene.glb.
    let lamp_dir = dir.join("lamp");
    std::fs::create_dir_all(&lamp_dir).unwrap();
    let lamp = write_scene(&lamp_dir);
    let two = ["--frames", "2..4", "--spp", "2", "--max-depth", "2"];
    agree(&dir, &lamp, "lamp", &two);
    // The lamp's emission textured: each light sample reads the texture where it lands
    // (`uv_at`, the finest level).
    let textured_dir = dir.join("textured-lamp");
    std::fs::create_dir_all(&textured_dir).unwrap();
    let textured = write(&textured_dir, &with_textured_lamp(scene()));
    agree(&dir, &textured, "textured-lamp", &two);
}

/// An environment map and diffuse bounces on the GPU: misses look the map up (turned
/// and scaled), bounce rays are drawn with the CPU's numbers (`Purpose::Diffuse`, the
/// bounce's seed), add no emission of their own and go on past `--max-depth`: the room
/// under a 4x2 map at depth 2, with two bounces and two samples, and the lamp scene with
/// one bounce and no mirror depth.
#[test]
fn environment_and_bounces_agree_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-env");
    // A 4x2 Radiance map, flat scanlines (RGBE: these values are exact).
    let map = dir.join("sky.hdr");
    let mut hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n".to_vec();
    for k in 0..8u8 {
        hdr.extend_from_slice(&[64 + 16 * k, 128, 200 - 8 * k, 129]);
    }
    std::fs::write(&map, hdr).unwrap();
    let room = write(&dir, &subset_scene());
    let sky = ["--environment", s(&map), "--environment-rotation", "30"];
    let a = ["--frames", "4..6", "--spp", "1", "--max-depth", "2"];
    agree(&dir, &room, "env", &[&a[..], &sky[..]].concat());
    let b = [
        "--frames",
        "5",
        "--spp",
        "2",
        "--max-depth",
        "1",
        "--diffuse-bounces",
        "2",
    ];
    agree(&dir, &room, "bounces", &[&b[..], &sky[..]].concat());
    let lamp_dir = dir.join("lamp");
    std::fs::create_dir_all(&lamp_dir).unwrap();
    let lamp = write_scene(&lamp_dir);
    let c = [
        "--frames",
        "2",
        "--spp",
        "1",
        "--max-depth",
        "0",
        "--diffuse-bounces",
        "1",
    ];
    agree(&dir, &lamp, "lamp-bounce", &c);
}

/// A room of alpha below 1 (pass-through rays): a tinted `BLEND` window (alpha 0.5) in
/// front of a mirror (a pass-through ray meets the mirror, the mirror's ray the window
/// again from behind), `MASK` quads of constant alpha above and below the cutoff and
/// one whose base colour texture's alpha crosses it (texels of alpha 0 to 252, a
/// magnified and a minified copy), a `BLEND` quad of that texture's alpha over the
/// background, two overlapping `BLEND` quads (two passes) and a
/// stack of 18 `BLEND` quads of alpha 0.3 (more than `MAX_PASSES`, 16: the rest of the
/// coverage is lost at the 17th), over a floor, under a point and a directional light.
fn alpha_scene() -> Scene {
    let mut b = SceneBuilder::new();
    let holes = b.add_image(image(8, 8, |x, y| {
        [
            (30 * x + 20) as u8,
            (25 * y + 40) as u8,
            180,
            (36 * ((x + 2 * y) % 8)) as u8,
        ]
    }));
    let t_holes = b.add_texture(Texture {
        image: holes,
        wrap_s: Wrap::Repeat,
        wrap_t: Wrap::Repeat,
        nearest: false,
    });
    let grey = b.add_material(diffuse("floor", Vec4::new(0.7, 0.7, 0.7, 1.0), 0.8));
    let mirror = b.add_material(Material {
        metallic: 1.0,
        ..diffuse("mirror", Vec4::new(0.9, 0.9, 0.9, 1.0), 0.0)
    });
    let window = b.add_material(Material {
        alpha_mode: AlphaMode::Blend,
        ..diffuse("window", Vec4::new(0.3, 0.8, 0.4, 0.5), 0.5)
    });
    let mask = |name: &str, c: Vec4| Material {
        alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
        ..diffuse(name, c, 0.6)
    };
    let mask_on = b.add_material(mask("mask on", Vec4::new(0.9, 0.2, 0.2, 0.8)));
    let mask_off = b.add_material(mask("mask off", Vec4::new(0.2, 0.2, 0.9, 0.3)));
    let mask_tex = b.add_material(Material {
        base_color_texture: slot(t_holes, None),
        ..mask("mask texture", Vec4::new(1.0, 1.0, 1.0, 0.9))
    });
    let mask_fine = b.add_material(Material {
        base_color_texture: slot(
            t_holes,
            Some(UvTransform {
                offset: Vec2::new(0.1, 0.0),
                rotation: 0.3,
                scale: Vec2::splat(5.0),
            }),
        ),
        ..mask("mask fine", Vec4::new(1.0, 1.0, 1.0, 1.0))
    });
    let blend_tex = b.add_material(Material {
        alpha_mode: AlphaMode::Blend,
        base_color_texture: slot(t_holes, None),
        ..diffuse("blend texture", Vec4::new(1.0, 0.9, 0.8, 1.0), 0.6)
    });
    let blue = b.add_material(Material {
        alpha_mode: AlphaMode::Blend,
        ..diffuse("blue glass", Vec4::new(0.2, 0.3, 0.9, 0.5), 0.7)
    });
    let yellow = b.add_material(Material {
        alpha_mode: AlphaMode::Blend,
        double_sided: true,
        ..diffuse("yellow glass", Vec4::new(0.9, 0.8, 0.2, 0.4), 0.7)
    });
    let veils = b.add_material(Material {
        alpha_mode: AlphaMode::Blend,
        ..diffuse("veils", Vec4::new(0.8, 0.5, 0.7, 0.3), 0.7)
    });
    let (x, y) = (Vec3::X, Vec3::Y);
    let mut prims = vec![
        quad(Vec3::ZERO, Vec3::Z * 5.0, x * 5.0, grey),
        quad(Vec3::new(0.0, 1.5, -2.5), x * 2.0, y * 1.5, mirror),
        quad(Vec3::new(0.3, 1.5, -1.2), x * 0.9, y * 0.8, window),
        quad(Vec3::new(-2.4, 0.7, 0.5), x * 0.5, y * 0.5, mask_on),
        quad(Vec3::new(-1.2, 0.7, 0.5), x * 0.5, y * 0.5, mask_off),
        quad(Vec3::new(2.2, 0.9, 0.5), x * 0.7, y * 0.7, mask_tex),
        quad(Vec3::new(-1.5, 2.3, -1.8), x * 0.8, y * 0.6, mask_fine),
        quad(Vec3::new(2.8, 2.8, -1.0), x * 0.6, y * 0.6, blend_tex),
        quad(Vec3::new(-2.6, 2.4, 0.0), x * 0.4, y * 0.4, blue),
        quad(Vec3::new(-2.3, 2.6, -0.3), x * 0.4, y * 0.4, yellow),
    ];
    for k in 0..18 {
        let z = 2.6 - 0.04 * k as f32;
        prims.push(quad(Vec3::new(-0.6, 0.5, z), x * 0.3, y * 0.3, veils));
    }
    let room = b.add_mesh(mesh("room", prims));
    let room = b.add_node(Node {
        name: Some("room".into()),
        mesh: Some(room),
        ..Default::default()
    });
    let [camera, bulb, sun_node] = camera_and_lights(&mut b);
    for n in [room, camera, bulb, sun_node] {
        b.add_root(n);
    }
    b.finish()
}

/// Alpha below 1 on the GPU: `MASK` (constant and textured) and `BLEND` surfaces pass
/// rays through as the CPU does (weight and coverage × (1 − alpha), the same depth, up
/// to `MAX_PASSES`), and each sample's coverage is summed in the CPU's order, so alpha
/// is the CPU's to the bit and RGB meets the bound: [`alpha_scene`] at one and two
/// samples a pixel, depth 2 (the window seen in the mirror, the mirror through the
/// window); the same ray counts; two GPU runs the same bytes.
#[test]
fn alpha_pass_through_agrees_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-alpha");
    let scene = write(&dir, &alpha_scene());
    let one = ["--frames", "0", "--spp", "1", "--max-depth", "2"];
    agree(&dir, &scene, "alpha1", &one);
    let two = ["--frames", "0", "--spp", "2", "--max-depth", "2"];
    agree(&dir, &scene, "alpha2", &two);
    // With the light-path passes (a pass-through ray keeps its path) and blurred in two
    // steps (each step's coverage summed from its samples' terms).
    let paths = [
        "--frames",
        "0",
        "--spp",
        "2",
        "--max-depth",
        "2",
        "--aov",
        "depth,cryptomatte,diffuse,specular,transmission,emission",
        "--shutter",
        "0.5",
        "--motion-steps",
        "2",
    ];
    agree(&dir, &scene, "alpha-paths", &paths);
}

/// An image made in code: `f(x, y)` its texel's RGBA.
fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 4]) -> Image {
    let mut rgba8 = Vec::new();
    for y in 0..h {
        for x in 0..w {
            rgba8.extend(f(x, y));
        }
    }
    Image {
        name: None,
        width: w,
        height: h,
        rgba8,
    }
}

fn slot(texture: u32, transform: Option<UvTransform>) -> Option<TextureRef> {
    Some(TextureRef {
        texture,
        tex_coord: 0,
        transform,
    })
}

/// A room of textures inside the frame path's subset: a floor of coloured tiles (sRGB,
/// repeated six times by `KHR_texture_transform`: minified, many mip levels), a back
/// wall with a normal map of bumps (linear, turned and shifted) and a magnified 4×4
/// base colour (clamped, nearest), a cube whose metallic-roughness texture (linear)
/// varies the metal and keeps the roughness from 0.6 up, a mirror whose
/// metallic-roughness texture keeps it a mirror but varies its metal (base colour
/// mirrored-repeat, magnified, bilinear), a glass cube in front of the wall, a `MASK`
/// quad whose texture is opaque, and an emissive texture on a material that does not
/// emit (the only emissive texture inside the subset). The mirror and the glass make
/// deeper levels read the textures with wider cones. A perspective and an orthographic
/// camera.
fn textured_scene() -> Scene {
    let mut b = SceneBuilder::new();
    let tiles = b.add_image(image(64, 64, |x, y| {
        let c = ((x / 8) + (y / 8)) % 2 == 0;
        [(x * 4) as u8, (y * 4) as u8, if c { 230 } else { 40 }, 255]
    }));
    let bumps = b.add_image(image(32, 32, |x, y| {
        let (u, v) = (x as f32 / 32.0, y as f32 / 32.0);
        let n = Vec3::new(0.6 * (u * 12.0).sin(), 0.6 * (v * 9.0).cos(), 1.0).normalize();
        let e = |c: f32| ((c * 0.5 + 0.5) * 255.0).round() as u8;
        [e(n.x), e(n.y), e(n.z), 255]
    }));
    let small = b.add_image(image(4, 4, |x, y| {
        [
            (60 * x + 20) as u8,
            (60 * y + 20) as u8,
            200 - (30 * x) as u8,
            255,
        ]
    }));
    let rough = b.add_image(image(16, 16, |x, y| {
        [0, 153 + (6 * y) as u8, (x * 17) as u8, 255]
    }));
    let shiny = b.add_image(image(8, 8, |x, y| {
        [0, (x * 30) as u8, 128 + (y * 18) as u8, 255]
    }));
    let glow = b.add_image(image(2, 2, |x, _| [255, (x * 255) as u8, 0, 255]));
    let tex = |b: &mut SceneBuilder, image: u32, wrap: Wrap, nearest: bool| {
        b.add_texture(Texture {
            image,
            wrap_s: wrap,
            wrap_t: wrap,
            nearest,
        })
    };
    let t_tiles = tex(&mut b, tiles, Wrap::Repeat, false);
    let t_bumps = tex(&mut b, bumps, Wrap::Repeat, false);
    let t_small = tex(&mut b, small, Wrap::ClampToEdge, true);
    let t_small_mirrored = tex(&mut b, small, Wrap::MirroredRepeat, false);
    let t_rough = tex(&mut b, rough, Wrap::Repeat, false);
    let t_shiny = tex(&mut b, shiny, Wrap::Repeat, false);
    let t_glow = tex(&mut b, glow, Wrap::Repeat, false);
    let floor = b.add_material(Material {
        base_color_texture: slot(
            t_tiles,
            Some(UvTransform {
                offset: Vec2::new(0.1, 0.2),
                rotation: 0.0,
                scale: Vec2::splat(6.0),
            }),
        ),
        ..diffuse("floor", Vec4::new(0.9, 0.9, 0.9, 1.0), 0.8)
    });
    let wall = b.add_material(Material {
        base_color_texture: slot(t_small, None),
        normal_texture: slot(
            t_bumps,
            Some(UvTransform {
                offset: Vec2::new(0.3, -0.1),
                rotation: 0.4,
                scale: Vec2::new(2.0, 1.5),
            }),
        ),
        normal_scale: 0.8,
        ..diffuse("wall", Vec4::ONE, 0.5)
    });
    let metal = b.add_material(Material {
        metallic: 1.0,
        metallic_roughness_texture: slot(t_rough, None),
        normal_texture: slot(t_bumps, None),
        ..diffuse("patchy metal", Vec4::new(0.9, 0.7, 0.4, 1.0), 1.0)
    });
    let mirror = b.add_material(Material {
        metallic: 1.0,
        metallic_roughness_texture: slot(t_shiny, None),
        base_color_texture: slot(
            t_small_mirrored,
            Some(UvTransform {
                offset: Vec2::ZERO,
                rotation: 0.0,
                scale: Vec2::splat(3.0),
            }),
        ),
        ..diffuse("mirror", Vec4::new(0.95, 0.95, 0.95, 1.0), 0.02)
    });
    let glass = b.add_material(Material {
        transmission: 1.0,
        ior: 1.5,
        double_sided: true,
        ..diffuse("glass", Vec4::ONE, 0.0)
    });
    let masked = b.add_material(Material {
        alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
        base_color_texture: slot(t_tiles, None),
        emissive_texture: slot(t_glow, None),
        ..diffuse("masked", Vec4::new(0.8, 1.0, 0.8, 1.0), 0.9)
    });
    let statics = b.add_mesh(mesh(
        "room",
        vec![
            quad(Vec3::ZERO, Vec3::Z * 5.0, Vec3::X * 5.0, floor),
            quad(
                Vec3::new(0.0, 1.5, -3.0),
                Vec3::X * 3.0,
                Vec3::Y * 1.5,
                wall,
            ),
            quad(
                Vec3::new(2.2, 1.0, -1.0),
                Vec3::new(0.6, 0.0, 0.8),
                Vec3::Y * 1.0,
                mirror,
            ),
            quad(
                Vec3::new(-2.6, 0.8, 0.5),
                Vec3::Z * -0.8,
                Vec3::Y * 0.8,
                masked,
            ),
        ],
    ));
    let glass_cube = b.add_mesh(mesh("glass", vec![cube(Vec3::splat(0.45), glass)]));
    let metal_cube = b.add_mesh(mesh("metal", vec![cube(Vec3::splat(0.4), metal)]));
    let ortho = b.add_camera(CameraDef {
        name: Some("ortho".into()),
        projection: Projection::Orthographic {
            xmag: 3.2,
            ymag: 2.4,
            znear: 0.1,
            zfar: 100.0,
        },
    });
    let mut nodes = Vec::new();
    let mut node = |b: &mut SceneBuilder, n: Node| {
        let i = b.add_node(n);
        nodes.push(i);
    };
    node(
        &mut b,
        Node {
            name: Some("room".into()),
            mesh: Some(statics),
            ..Default::default()
        },
    );
    node(
        &mut b,
        Node {
            name: Some("glass".into()),
            mesh: Some(glass_cube),
            transform: placed(Vec3::new(-0.8, 0.45, -1.6), Quat::from_rotation_y(0.5)),
            ..Default::default()
        },
    );
    node(
        &mut b,
        Node {
            name: Some("metal".into()),
            mesh: Some(metal_cube),
            transform: placed(Vec3::new(0.9, 0.4, 0.3), Quat::from_rotation_y(-0.4)),
            ..Default::default()
        },
    );
    node(
        &mut b,
        Node {
            name: Some("ortho camera".into()),
            camera: Some(ortho),
            transform: placed(
                Vec3::new(1.0, 4.0, 6.0),
                Quat::from_rotation_y(0.15) * Quat::from_rotation_x(-0.6),
            ),
            ..Default::default()
        },
    );
    nodes.extend(camera_and_lights(&mut b));
    for n in nodes {
        b.add_root(n);
    }
    b.finish()
}

/// The textured room against the CPU (RGB within the bound, alpha and the AOVs to the
/// bit): one sample at depth 3 (the mirror and the glass read textures at deeper
/// levels), two samples at depth 2 with an overscan border, and the orthographic
/// camera (a cone of constant width); the first again on the GPU gives the same bytes.
#[test]
fn gpu_frames_with_textures_agree_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-textures");
    let scene = write(&dir, &textured_scene());
    let runs: [(&str, &[&str]); 3] = [
        ("t1", &["--spp", "1", "--max-depth", "3"]),
        ("t2", &["--spp", "2", "--max-depth", "2", "--overscan", "2"]),
        (
            "t3",
            &["--spp", "1", "--max-depth", "3", "--camera", "ortho"],
        ),
    ];
    for (name, args) in runs {
        let cpu = format!("cpu-{name}");
        let gpu = format!("gpu-{name}");
        render_at("96x72", &scene, &dir, "cpu", &cpu, args);
        let log = render_at("96x72", &scene, &dir, "gpu", &gpu, args);
        assert!(
            !log.contains("shading on the CPU"),
            "the textured scene fell back: {log}"
        );
        check_close(&dir, &cpu, &gpu);
    }
    render_at("96x72", &scene, &dir, "gpu", "gpu-t1again", runs[0].1);
    for f in files_under(&dir.join("gpu-t1")) {
        assert_eq!(
            std::fs::read(dir.join("gpu-t1").join(&f)).unwrap(),
            std::fs::read(dir.join("gpu-t1again").join(&f)).unwrap(),
            "{}: a second GPU run differs",
            f.display()
        );
    }
    // The patchy metal's roughness factor halved: its texture makes some hits glossy
    // (a GGX ray, which widens the cone the textures seen in it are read with) and
    // others too rough to reflect, hit by hit.
    let mut glossy = textured_scene();
    for m in &mut glossy.materials {
        if m.name.as_deref() == Some("patchy metal") {
            m.roughness = 0.5;
        }
    }
    let glossy_dir = dir.join("glossy");
    std::fs::create_dir_all(&glossy_dir).unwrap();
    let glossy = write(&glossy_dir, &glossy);
    let a = ["--frames", "0", "--spp", "2", "--max-depth", "2"];
    agree(&dir, &glossy, "textured-glossy", &a);
    // Materials' own ambient colours (AFF) under the scene's ambient light: the tiled
    // floor's and the wall's times their base colour textures, the metal's alone.
    let mut aff = textured_scene();
    aff.ambient = Some(Vec3::new(0.5, 0.4, 0.3));
    for m in &mut aff.materials {
        m.ambient = match m.name.as_deref() {
            Some("floor") => Some(Vec3::new(0.2, 0.6, 0.9)),
            Some("wall") => Some(Vec3::new(0.9, 0.3, 0.2)),
            Some("patchy metal") => Some(Vec3::new(0.1, 0.8, 0.1)),
            _ => m.ambient,
        };
    }
    let aff_dir = dir.join("aff");
    std::fs::create_dir_all(&aff_dir).unwrap();
    let aff = write(&aff_dir, &aff);
    agree(&dir, &aff, "textured-aff", &a);
}

/// Motion blur on the GPU: each time step traces its own samples (the CPU's choice,
/// `begin_blurred`), the steps' sums are added and `finish_blurred` averages them; the
/// AOVs come from the middle step (odd counts) or a pass of their own (even), and the
/// Cryptomatte ranks every sample whatever step traced it. The room's tumbling cube with
/// three steps at three samples (depth 2), two steps at four samples with glossy metal
/// (depth 1; two samples a pixel a step, so a step's coverage passes 1 before the
/// average), and two steps at one sample (a pixel's only sample in one step).
#[test]
fn motion_blur_agrees_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-blur");
    let room = write(&dir, &subset_scene());
    let three = [
        "--frames",
        "4..6",
        "--spp",
        "3",
        "--max-depth",
        "2",
        "--shutter",
        "0.5",
        "--motion-steps",
        "3",
    ];
    agree(&dir, &room, "blur3", &three);
    let mut glossy = subset_scene();
    for m in &mut glossy.materials {
        if m.name.as_deref() == Some("gold") {
            m.roughness = 0.3;
        }
    }
    let glossy_dir = dir.join("glossy");
    std::fs::create_dir_all(&glossy_dir).unwrap();
    let glossy = write(&glossy_dir, &glossy);
    let four = [
        "--frames",
        "5",
        "--spp",
        "4",
        "--max-depth",
        "1",
        "--shutter",
        "0.8",
        "--motion-steps",
        "2",
    ];
    agree(&dir, &glossy, "blur4", &four);
    let one = [
        "--frames",
        "6",
        "--spp",
        "1",
        "--shutter",
        "0.5",
        "--motion-steps",
        "2",
    ];
    agree(&dir, &room, "blur1", &one);
}

/// The light-path passes on the GPU: each term split as the CPU splits it (at a camera
/// ray's hit the diffuse lobe's light diffuse and the glint's specular, emission and
/// the background emission; deeper, all to the pass the first event named: reflection
/// specular, refraction transmission, a bounce diffuse), summed and averaged as the
/// beauty is: the room with the lamp scene's area light and two bounces, and blurred in
/// two steps. Each pass is held to the bound as the beauty is.
#[test]
fn light_path_passes_agree_with_the_cpu() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-paths");
    let room = write(&dir, &subset_scene());
    let passes = [
        "--aov",
        "depth,normal,motion,cryptomatte,diffuse,specular,transmission,emission",
    ];
    let a = ["--frames", "4..6", "--spp", "2", "--max-depth", "3"];
    agree(&dir, &room, "paths", &[&a[..], &passes[..]].concat());
    let lamp_dir = dir.join("lamp");
    std::fs::create_dir_all(&lamp_dir).unwrap();
    let lamp = write_scene(&lamp_dir);
    let b = [
        "--frames",
        "2",
        "--spp",
        "1",
        "--max-depth",
        "2",
        "--diffuse-bounces",
        "2",
        "--shutter",
        "0.5",
        "--motion-steps",
        "2",
    ];
    agree(&dir, &lamp, "paths-lamp", &[&b[..], &passes[..]].concat());
}

/// Asked to shade on the CPU (`SUBFIELD_GPU_SHADING=cpu`), a scene the frame path could
/// take traces on the GPU and shades on the CPU: its frames are the CPU's to the bit,
/// the log says why, and the options string says so (`shading=cpu`: `--resume` does
/// not keep such frames for a GPU-shaded sequence).
#[test]
fn shading_kept_on_the_cpu_gives_the_cpus_frames_and_says_why() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-fallback");
    let scene = write(&dir, &subset_scene());
    let a = ["--frames", "2", "--spp", "1"];
    render(&scene, &dir, "cpu", "cpu", &a);
    let log = render(&scene, &dir, "gpu-cpu", "gpu", &a);
    assert!(
        log.contains(
            "note: shading on the CPU, tracing on the GPU: the GPU frame path does not take \
             a render asked to shade on the CPU (SUBFIELD_GPU_SHADING=cpu)"
        ),
        "stderr: {log}"
    );
    let header = std::fs::read(dir.join("gpu").join("f.02.exr")).unwrap();
    assert!(
        header.windows(22).any(|w| w == b"device=gpu shading=cpu"),
        "no shading=cpu in the header"
    );
    for f in files_under(&dir.join("cpu")) {
        let (_, _, ca) = read_exr(&dir.join("cpu").join(&f));
        let (_, _, cb) = read_exr(&dir.join("gpu").join(&f));
        for ((na, va), (nb, vb)) in ca.iter().zip(&cb) {
            assert_eq!(na, nb);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(va), bits(vb), "{}: channel {na} differs", f.display());
        }
    }
}

/// Frames in flight on the GPU: four at once (more asked for: a note says four) give
/// the bytes of one at a time, frames of a sequence whose moving cube tumbles.
#[test]
fn frames_in_flight_on_the_gpu_give_the_same_bytes() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-frames-in-flight");
    let scene = write(&dir, &subset_scene());
    let a = ["--frames", "0..7", "--spp", "1", "--max-depth", "2"];
    render(
        &scene,
        &dir,
        "gpu",
        "one",
        &[&a[..], &["--frames-in-flight", "1"]].concat(),
    );
    let log = render(
        &scene,
        &dir,
        "gpu",
        "many",
        &[&a[..], &["--frames-in-flight", "9"]].concat(),
    );
    assert!(
        log.contains("note: --frames-in-flight 9: the GPU renders 4 frames at once at most"),
        "stderr: {log}"
    );
    let files = files_under(&dir.join("one"));
    assert_eq!(files.len(), 7);
    for f in files {
        assert!(
            std::fs::read(dir.join("one").join(&f)).unwrap()
                == std::fs::read(dir.join("many").join(&f)).unwrap(),
            "{}: four frames in flight differ from one",
            f.display()
        );
    }
}

/// The rays the frame path makes on the GPU (shadow, reflected, refracted) carry the
/// shear `geometry::Shear::new` computes, to the bit, and the same validity: random
/// directions of every octant and scale, axis-aligned ones, and invalid rays.
#[test]
fn gpu_made_shears_equal_the_cpus() {
    let Some(dev) = common::gpu::device() else {
        return;
    };
    let shading = GpuShading::new(dev, &[]).unwrap();
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut rays = Vec::new();
    for k in 0..200_000 {
        let d = Vec3::new(next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0);
        // Scales from 1e-6 to 1e6, some directions with a zero or tiny component.
        let scale = 10f32.powf(next() * 12.0 - 6.0);
        let mut d = d * scale;
        match k % 10 {
            0 => d.x = 0.0,
            1 => d.y = -0.0,
            2 => d.z *= 1e-7,
            _ => {}
        }
        let o = Vec3::new(next(), next(), next()) * 100.0 - 50.0;
        rays.push(Ray::segment(o, d, 0.0, next() * 10.0));
    }
    for d in [Vec3::X, -Vec3::Y, Vec3::Z, Vec3::ONE, -Vec3::ONE] {
        rays.push(Ray::new(Vec3::ZERO, d));
    }
    // Invalid: zero direction, NaN, infinite origin, NaN span.
    rays.push(Ray::new(Vec3::ONE, Vec3::ZERO));
    rays.push(Ray::new(Vec3::ONE, Vec3::new(f32::NAN, 1.0, 0.0)));
    rays.push(Ray::new(Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::X));
    rays.push(Ray::segment(Vec3::ONE, Vec3::X, f32::NAN, 1.0));
    let gpu = shading.rays_made_on_gpu(dev, &rays).unwrap();
    for (r, g) in rays.iter().zip(&gpu) {
        assert_eq!(*g, packed_on_cpu(r), "ray {r:?}");
    }
}
