//! The built-in museum (`subfield::museum`, `subfield generate museum`): exact triangle
//! counts through our importer, byte-identical output for a seed, dynamic triangles that
//! follow the keys stored in the file (read back with the `gltf` crate, not our
//! importer) and blend linearly between them, the subset the Embree harness reads, and
//! the command line.

use std::path::Path;
#[cfg(feature = "cli")]
use std::process::Command;

use glam::Vec3;
use gltf::animation::util::{MorphTargetWeights, ReadOutputs};
use subfield::gen::museum::{museum_glb, MuseumError, MuseumParams, MIN_STATIC_TRIS};
use subfield::import;
use subfield::scene::{ClipSelection, LightKind, Scene, TriangleSoup};

fn load(bytes: &[u8]) -> Scene {
    import::from_gltf_slice(bytes, Path::new("museum.glb"), Path::new(".")).unwrap()
}

fn small(static_tris: usize, dynamic_tris: usize) -> MuseumParams {
    MuseumParams {
        static_tris,
        dynamic_tris,
        ..MuseumParams::default()
    }
}

/// The dynamic part as the file stores it, read with the `gltf` crate: key times, the
/// weights at each key, and every vertex at key `k` (base + target `k`), in scene order.
struct Keys {
    times: Vec<f32>,
    weights: Vec<Vec<f32>>,
    interpolation: gltf::animation::Interpolation,
    /// `positions[k][v]`: vertex `v` (three per triangle) at key `k`.
    positions: Vec<Vec<Vec3>>,
}

fn read_keys(bytes: &[u8]) -> Keys {
    let (doc, buffers, _) = gltf::import_slice(bytes).unwrap();
    let anims: Vec<_> = doc.animations().collect();
    assert_eq!(anims.len(), 1);
    let channels: Vec<_> = anims[0].channels().collect();
    assert_eq!(channels.len(), 1);
    let ch = &channels[0];
    assert_eq!(
        ch.target().property(),
        gltf::animation::Property::MorphTargetWeights
    );
    let node = ch.target().node();
    assert!(node.transform().matrix() == glam::Mat4::IDENTITY.to_cols_array_2d());
    let r = ch.reader(|b| Some(&buffers[b.index()]));
    let times: Vec<f32> = r.read_inputs().unwrap().collect();
    let flat: Vec<f32> = match r.read_outputs().unwrap() {
        ReadOutputs::MorphTargetWeights(MorphTargetWeights::F32(w)) => w.collect(),
        _ => panic!("weights are not f32"),
    };
    let width = flat.len() / times.len();
    let weights = flat.chunks(width).map(<[f32]>::to_vec).collect();
    let mut positions = vec![Vec::new(); width];
    for prim in node.mesh().unwrap().primitives() {
        assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
        let pr = prim.reader(|b| Some(&buffers[b.index()]));
        let base: Vec<Vec3> = pr.read_positions().unwrap().map(Vec3::from).collect();
        let order: Vec<usize> = match pr.read_indices() {
            Some(i) => i.into_u32().map(|i| i as usize).collect(),
            None => (0..base.len()).collect(),
        };
        let targets: Vec<Vec<Vec3>> = pr
            .read_morph_targets()
            .map(|(p, _, _)| p.unwrap().map(Vec3::from).collect())
            .collect();
        assert_eq!(targets.len(), width);
        for (k, t) in targets.iter().enumerate() {
            positions[k].extend(order.iter().map(|&v| base[v] + t[v]));
        }
    }
    Keys {
        times,
        weights,
        interpolation: ch.sampler().interpolation(),
        positions,
    }
}

fn dynamic_at(scene: &Scene, t: f32) -> Vec<Vec3> {
    let split = scene.split(ClipSelection::All);
    let mut soup = TriangleSoup::new();
    scene.dynamic_triangles_at(&split, t, &mut soup);
    soup.positions.iter().flatten().copied().collect()
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

#[test]
fn default_museum_has_the_requested_counts_camera_lights_and_fps() {
    let p = MuseumParams::default();
    let bytes = museum_glb(&p).unwrap();
    let scene = load(&bytes);
    let s = scene.split(ClipSelection::All).summary();
    assert_eq!(s.static_triangles, 10_284, "{s}");
    assert_eq!(s.dynamic_triangles, 16_384, "{s}");
    assert_eq!(scene.fps, Some(30.0));
    // The last key falls on frame 299.
    assert!((scene.duration(ClipSelection::All) - 299.0 / 30.0).abs() < 1e-5);
    assert_eq!(scene.cameras.len(), 1);
    let cam = scene.camera_at(ClipSelection::All, 0.0, None).unwrap();
    let lights = scene.lights_at(ClipSelection::All, 0.0);
    assert_eq!(lights.len(), 2);
    assert_eq!(lights[0].kind, LightKind::Point);
    assert!(matches!(lights[1].kind, LightKind::Spot { .. }));
    // Camera and lights inside the room, the camera looking towards its middle.
    for p in [cam.position, lights[0].position, lights[1].position] {
        assert!(
            p.abs().max_element() < 10.0 && p.y > 0.0 && p.y < 8.0,
            "{p}"
        );
    }
    let forward = cam.rotation * Vec3::NEG_Z;
    let to_middle = (Vec3::new(0.0, 3.5, 0.0) - cam.position).normalize();
    assert!(forward.dot(to_middle) > 0.95, "{forward} vs {to_middle}");
    // The spot aims at the action too.
    let to_middle = (Vec3::new(0.0, 3.5, 0.0) - lights[1].position).normalize();
    assert!(lights[1].direction.dot(to_middle) > 0.95);
    // Materials for the Whitted renderer: mirrors and glass.
    assert!(scene
        .materials
        .iter()
        .any(|m| m.metallic == 1.0 && m.roughness == 0.0));
    assert!(scene.materials.iter().any(|m| m.transmission > 0.0));
}

/// The renderer's default range is the whole animation, last key included: `frames`
/// frames, for frame counts whose last key time `(frames − 1) / fps` rounds below the
/// exact value in f32 (299 / 30 does).
#[test]
fn default_render_range_has_every_frame_of_the_museum() {
    for (frames, fps) in [
        (300, 30.0),
        (2, 30.0),
        (301, 24.0),
        (1000, 60.0),
        (97, 29.97),
    ] {
        let p = MuseumParams {
            frames,
            fps,
            ..small(MIN_STATIC_TRIS, 4)
        };
        let scene = load(&museum_glb(&p).unwrap());
        let opts = subfield::render::RenderOptions {
            output: "f.####.exr".into(),
            ..Default::default()
        };
        let plan = subfield::render::plan(&scene, &opts).unwrap();
        assert_eq!(
            (plan.range.start, plan.range.end),
            (0, frames),
            "{frames} frames at {fps} fps"
        );
    }
}

#[test]
fn static_count_is_exact_for_any_budget() {
    for (st, dy) in [
        (MIN_STATIC_TRIS, 1),
        (MIN_STATIC_TRIS + 1, 3),
        (4_097, 5),
        (10_285, 7),
        (60_001, 2),
    ] {
        let scene = load(&museum_glb(&small(st, dy)).unwrap());
        let s = scene.split(ClipSelection::All).summary();
        assert_eq!((s.static_triangles, s.dynamic_triangles), (st, dy), "{s}");
    }
}

#[test]
fn same_parameters_give_the_same_bytes_and_the_seed_moves_only_the_dynamic_part() {
    let p = small(5_000, 2_000);
    let a = museum_glb(&p).unwrap();
    let b = museum_glb(&p).unwrap();
    assert!(a == b, "two builds differ");
    let other = museum_glb(&MuseumParams { seed: 2, ..p }).unwrap();
    assert!(a != other);
    let (sa, sb) = (load(&a), load(&other));
    let statics = |s: &Scene| s.static_triangles(&s.split(ClipSelection::All)).positions;
    assert_eq!(statics(&sa), statics(&sb));
    assert!(max_distance(&dynamic_at(&sa, 0.0), &dynamic_at(&sb, 0.0)) > 1.0);
}

#[test]
fn dynamic_triangles_follow_the_stored_keys_and_blend_linearly_between_them() {
    let p = small(2_000, 3_001);
    let bytes = museum_glb(&p).unwrap();
    let keys = read_keys(&bytes);
    let scene = load(&bytes);
    let n = keys.times.len();
    assert!((8..=16).contains(&n), "{n} keys");
    assert_eq!(keys.interpolation, gltf::animation::Interpolation::Linear);
    assert_eq!(keys.times[0], 0.0);
    assert!((keys.times[n - 1] - (p.frames - 1) as f32 / p.fps).abs() < 1e-5);
    // One-hot weights: key k drives target k alone (what the Embree harness expects).
    for (k, w) in keys.weights.iter().enumerate() {
        let want: Vec<f32> = (0..n).map(|i| f32::from(u8::from(i == k))).collect();
        assert_eq!(w, &want, "key {k}");
    }
    for k in 0..n {
        let got = dynamic_at(&scene, keys.times[k]);
        assert_eq!(got.len(), 3 * 3_001);
        let d = max_distance(&got, &keys.positions[k]);
        assert!(d < 1e-5, "key {k}: off by {d}");
    }
    for k in 0..n - 1 {
        for a in [0.25f32, 0.5] {
            let t = keys.times[k] + a * (keys.times[k + 1] - keys.times[k]);
            let want: Vec<Vec3> = keys.positions[k]
                .iter()
                .zip(&keys.positions[k + 1])
                .map(|(p, q)| p.lerp(*q, a))
                .collect();
            let d = max_distance(&dynamic_at(&scene, t), &want);
            assert!(
                d < 1e-4,
                "between keys {k} and {}, a = {a}: off by {d}",
                k + 1
            );
        }
    }
    // Past the end the last key holds.
    let d = max_distance(&dynamic_at(&scene, 1e3), &keys.positions[n - 1]);
    assert!(d < 1e-5);
}

#[test]
fn triangles_move_independently_gather_and_stay_in_the_room() {
    let bytes = museum_glb(&small(2_000, 4_000)).unwrap();
    let keys = read_keys(&bytes);
    let extent = |v: &[Vec3]| {
        let lo = v.iter().fold(Vec3::INFINITY, |a, p| a.min(*p));
        let hi = v.iter().fold(Vec3::NEG_INFINITY, |a, p| a.max(*p));
        (lo, hi)
    };
    let mut gathered = 0;
    for (k, v) in keys.positions.iter().enumerate() {
        let (lo, hi) = extent(v);
        assert!(
            lo.cmpgt(Vec3::new(-10.0, 0.0, -10.0)).all(),
            "key {k}: {lo}"
        );
        assert!(hi.cmplt(Vec3::new(10.0, 8.0, 10.0)).all(), "key {k}: {hi}");
        if (hi - lo).max_element() < 7.0 {
            gathered += 1;
        }
    }
    // Scattered at the start and end, gathered into shapes (two keys each) between.
    let (lo, hi) = extent(&keys.positions[0]);
    assert!((hi - lo).min_element() > 6.0, "{lo} {hi}");
    assert!(gathered >= 6, "{gathered} gathered keys");
    // Unstructured: between two keys neighbouring triangles do not share a motion.
    let moves: Vec<Vec3> = (0..4_000)
        .map(|i| keys.positions[1][3 * i] - keys.positions[0][3 * i])
        .collect();
    let similar = moves
        .windows(2)
        .filter(|w| w[0].distance(w[1]) < 0.1 * w[0].length().max(1e-3))
        .count();
    assert!(similar < 40, "{similar} neighbours move alike");
}

#[test]
fn bad_parameters_are_refused_with_the_parameter_named() {
    let cases = [
        (small(MIN_STATIC_TRIS - 1, 10), "static triangles"),
        (small(10_284, 0), "dynamic triangles"),
        (
            MuseumParams {
                frames: 1,
                ..MuseumParams::default()
            },
            "frames",
        ),
        (
            MuseumParams {
                fps: 0.0,
                ..MuseumParams::default()
            },
            "fps",
        ),
        (
            MuseumParams {
                fps: f32::INFINITY,
                ..MuseumParams::default()
            },
            "fps",
        ),
    ];
    for (p, what) in cases {
        let e = museum_glb(&p).unwrap_err();
        assert!(matches!(e, MuseumError::Param { .. }), "{e:?}");
        assert!(e.to_string().contains(what), "{e}");
    }
}

#[cfg(feature = "cli")]
fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir()
        .join(format!("subfield-museum-{}", std::process::id()))
        .join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

// The command line (the `cli` feature) writing and refusing museums.
#[cfg(feature = "cli")]
#[test]
fn cli_writes_a_museum_that_loads() {
    let dir = temp_dir("cli");
    let out = dir.join("m.glb");
    let run = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(["generate", "museum", "-o"])
        .arg(&out)
        .args(["--static-tris", "3000", "--dynamic-tris", "500"])
        .args(["--frames", "61", "--fps", "24", "--seed", "7"])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report = String::from_utf8_lossy(&run.stdout);
    assert!(report.contains("3000 static + 500 dynamic"), "{report}");
    let scene = import::load(&out).unwrap();
    let s = scene.split(ClipSelection::All).summary();
    assert_eq!((s.static_triangles, s.dynamic_triangles), (3_000, 500));
    assert_eq!(scene.fps, Some(24.0));
    assert!((scene.duration(ClipSelection::All) - 60.0 / 24.0).abs() < 1e-5);
    // The same bytes as the library makes.
    let lib = museum_glb(&MuseumParams {
        static_tris: 3_000,
        dynamic_tris: 500,
        frames: 61,
        fps: 24.0,
        seed: 7,
    })
    .unwrap();
    assert!(std::fs::read(&out).unwrap() == lib);
    // Only the file itself in the folder: no temporary left behind.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
}

#[cfg(feature = "cli")]
#[test]
fn cli_refuses_bad_numbers_with_one_line_and_writes_nothing() {
    let dir = temp_dir("bad");
    let out = dir.join("m.glb");
    for (flag, value, says) in [
        ("--dynamic-tris", "0", "dynamic triangles 0"),
        ("--static-tris", "100", "static triangles 100"),
        ("--frames", "1", "frames 1"),
        ("--fps", "0", "fps 0"),
    ] {
        let run = Command::new(env!("CARGO_BIN_EXE_subfield"))
            .args(["generate", "museum", "-o"])
            .arg(&out)
            .args([flag, value])
            .output()
            .unwrap();
        assert!(!run.status.success(), "{flag} {value} accepted");
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(says), "{err}");
        assert!(!out.exists());
    }
}
