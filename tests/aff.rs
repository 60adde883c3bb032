//! BART AFF / NFF import: hand-made inputs with values worked out by hand (or by an
//! independent evaluation of the Kochanek–Bartels formula written here), error cases, a
//! bounded fuzz loop, and the animart generator.
//!
//! Over 800 lines: one file for the one format, its cases grouped by statement (views,
//! lights, materials, meshes, keyframes, includes, errors); each is short and stands alone.

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use subfield::gen::animart::{generate_animart, AnimartParams};
use subfield::import;
use subfield::import::aff::shapes;
use subfield::import::aff::AffScene;
use subfield::import::ImportError;
use subfield::scene::{ClipSelection, Scene, TriangleSoup};

/// A fresh folder under the target directory for one test.
fn temp_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("aff-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes `files` (name, text) into a fresh folder; returns the path of the first.
fn write_scene(test: &str, files: &[(&str, &str)]) -> PathBuf {
    let d = temp_dir(test);
    for (name, text) in files {
        std::fs::write(d.join(name), text).unwrap();
    }
    d.join(files[0].0)
}

fn soup_at(scene: &Scene, t: f32) -> Vec<[Vec3; 3]> {
    let mut soup = TriangleSoup::new();
    scene.triangles_into(&scene.instances(), ClipSelection::All, t, &mut soup);
    soup.positions
}

fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).abs().max_element() <= tol
}

fn assert_close(a: Vec3, b: Vec3, tol: f32, what: &str) {
    assert!(close(a, b, tol), "{what}: {a} vs {b}");
}

#[test]
fn polygons_are_fanned_and_patch_normals_normalised() {
    let path = write_scene(
        "polygons",
        &[(
            "p.aff",
            "# a pentagon, then a quad patch\n\
             p 5\n 0 0 0\n 1 0 0\n 2 1 0\n 1 2 0\n 0 1 0\n\
             pp 4\n 0 0 1  0 0 2\n 1 0 1  0 0 3\n 1 1 1  0 0 1\n 0 1 1  0 0 5\n",
        )],
    );
    let aff = AffScene::load(&path).unwrap();
    assert_eq!(aff.triangle_count(), 3 + 2);
    let tris = aff.triangles_at(0.0);
    let v = [
        Vec3::ZERO,
        Vec3::X,
        Vec3::new(2.0, 1.0, 0.0),
        Vec3::new(1.0, 2.0, 0.0),
        Vec3::Y,
    ];
    // Fan: (0,1,2), (0,2,3), (0,3,4).
    assert_eq!(tris[0], [v[0], v[1], v[2]]);
    assert_eq!(tris[1], [v[0], v[2], v[3]]);
    assert_eq!(tris[2], [v[0], v[3], v[4]]);
    let z1 = Vec3::new(0.0, 0.0, 1.0);
    assert_eq!(
        tris[3],
        [z1, Vec3::new(1.0, 0.0, 1.0), Vec3::new(1.0, 1.0, 1.0)]
    );
    assert_eq!(
        tris[4],
        [z1, Vec3::new(1.0, 1.0, 1.0), Vec3::new(0.0, 1.0, 1.0)]
    );

    // Through glTF: same triangles; the patch's normals arrive unit length.
    let scene = import::load(&path).unwrap();
    let mut soup = TriangleSoup::new();
    scene.triangles_into(&scene.instances(), ClipSelection::All, 0.0, &mut soup);
    assert_eq!(soup.positions, tris);
    for n in soup.normals[3].iter().chain(&soup.normals[4]) {
        assert_close(*n, Vec3::Z, 1e-6, "pp normal");
    }
}

#[test]
fn static_transforms_compose_scale_rotate_translate_and_nest() {
    // Outer: scale 2, rotate 90° about z, translate (1,0,0). Inner: translate (0,0,5).
    let path = write_scene(
        "xs",
        &[(
            "xs.aff",
            "xs 2 2 2  0 0 1 90  1 0 0\n{\n  p 3\n 1 0 0\n 0 1 0\n 0 0 1\n\
               xs 1 1 1  1 0 0 0  0 0 5 { p 3  1 0 0  0 1 0  0 0 1 }\n}\n",
        )],
    );
    let aff = AffScene::load(&path).unwrap();
    let tris = aff.triangles_at(0.0);
    // (1,0,0) → scale (2,0,0) → rotate (0,2,0) → translate (1,2,0).
    // (0,1,0) → (0,2,0) → (−2,0,0) → (−1,0,0).  (0,0,1) → (0,0,2) → (0,0,2) → (1,0,2).
    let outer = [
        Vec3::new(1.0, 2.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 2.0),
    ];
    // Inner first moves by (0,0,5): (1,0,5) → (2,0,10) → (0,2,10) → (1,2,10), etc.
    let inner = [
        Vec3::new(1.0, 2.0, 10.0),
        Vec3::new(-1.0, 0.0, 10.0),
        Vec3::new(1.0, 0.0, 12.0),
    ];
    for (got, want) in tris[0].iter().zip(&outer).chain(tris[1].iter().zip(&inner)) {
        assert_close(*got, *want, 1e-5, "AFF evaluation");
    }
    let scene = import::load(&path).unwrap();
    let via_gltf = soup_at(&scene, 0.0);
    for (got, want) in via_gltf.iter().flatten().zip(outer.iter().chain(&inner)) {
        assert_close(*got, *want, 1e-5, "through glTF");
    }
}

/// Kochanek–Bartels as in the paper / textbooks: cubic Hermite between `p1` and `p2` with
/// the source (outgoing) tangent at `p1` and the destination (incoming) tangent at `p2`,
/// each scaled for uneven key spacing.
#[allow(clippy::too_many_arguments)]
fn kb_reference(p: [f64; 4], t: [f64; 4], tcb1: [f64; 3], tcb2: [f64; 3], time: f64) -> f64 {
    let [p0, p1, p2, p3] = p;
    let [t0, t1, t2, t3] = t;
    let (te, c, b) = (tcb1[0], tcb1[1], tcb1[2]);
    let source = (1.0 - te) * (1.0 + c) * (1.0 + b) / 2.0 * (p1 - p0)
        + (1.0 - te) * (1.0 - c) * (1.0 - b) / 2.0 * (p2 - p1);
    let source = source * 2.0 * (t2 - t1) / (t2 - t0);
    let (te, c, b) = (tcb2[0], tcb2[1], tcb2[2]);
    let dest = (1.0 - te) * (1.0 - c) * (1.0 + b) / 2.0 * (p2 - p1)
        + (1.0 - te) * (1.0 + c) * (1.0 - b) / 2.0 * (p3 - p2);
    let dest = dest * 2.0 * (t2 - t1) / (t3 - t1);
    let s = (time - t1) / (t2 - t1);
    let h00 = 2.0 * s * s * s - 3.0 * s * s + 1.0;
    let h10 = s * s * s - 2.0 * s * s + s;
    let h01 = -2.0 * s * s * s + 3.0 * s * s;
    let h11 = s * s * s - s * s;
    h00 * p1 + h10 * source + h01 * p2 + h11 * dest
}

#[test]
fn keyframe_splines_match_an_independent_kochanek_bartels_evaluation() {
    // Keys at 0, 1, 2, 3.5, 4 (uneven), x values 5, 1, 3, 4, 9, with TCB on the inner keys.
    // Rotation about +Y through 0°, 30°, 90°, 100°, 60°: about one axis the quaternion
    // spline is the same Hermite spline of the angles.
    // Frames: a 0 4 9 → t = 0, 0.5, ..., 4.
    let path = write_scene(
        "spline",
        &[(
            "k.aff",
            "a 0 4 9\n\
             x mover {\n p 3\n 0 0 0\n 0 1 0\n 0 0 1\n}\n\
             k mover {\n\
               transl 5\n\
                 0   5 0 0  0 0 0\n\
                 1   1 0 0  0.2 -0.3 0.5\n\
                 2   3 0 0  -0.4 0.25 -0.1\n\
                 3.5 4 0 0  0.1 0.2 0.3\n\
                 4   9 0 0  0 0 0\n\
               rot 5\n\
                 0   0 1 0 0    0 0 0\n\
                 1   0 2 0 30   0.2 -0.3 0.5\n\
                 2   0 1 0 90   -0.4 0.25 -0.1\n\
                 3.5 0 1 0 100  0.1 0.2 0.3\n\
                 4   0 1 0 60   0 0 0\n\
             }\n",
        )],
    );
    let times = [0.0, 1.0, 2.0, 3.5, 4.0];
    let xs = [5.0, 1.0, 3.0, 4.0, 9.0];
    let angles = [0.0, 30.0, 90.0, 100.0, 60.0];
    let tcb = [
        [0.0, 0.0, 0.0],
        [0.2, -0.3, 0.5],
        [-0.4, 0.25, -0.1],
        [0.1, 0.2, 0.3],
        [0.0, 0.0, 0.0],
    ];
    let expect = |vals: [f64; 5], t: f64| -> f64 {
        // Clamped to the second and next-to-last keys.
        if t <= times[1] {
            return vals[1];
        }
        if t >= times[3] {
            return vals[3];
        }
        let i = if t < times[2] { 0 } else { 1 };
        kb_reference(
            [vals[i], vals[i + 1], vals[i + 2], vals[i + 3]],
            [times[i], times[i + 1], times[i + 2], times[i + 3]],
            tcb[i + 1],
            tcb[i + 2],
            t,
        )
    };

    let aff = AffScene::load(&path).unwrap();
    let tr = &aff.tracks["mover"];
    // Exactly at keys, and at midpoints of both segments, and clamped ends.
    for t in [0.5, 1.0, 1.5, 1.25, 2.0, 2.75, 3.5, 3.9] {
        let got = tr.translation_at(t).unwrap().x;
        let want = expect(xs, t);
        assert!((got - want).abs() < 1e-9, "transl at {t}: {got} vs {want}");
        let q = tr.rotation_at(t).unwrap();
        let want_q = glam::DQuat::from_axis_angle(glam::DVec3::Y, expect(angles, t).to_radians());
        assert!(
            q.angle_between(want_q) < 1e-9,
            "rot at {t}: {q} vs {want_q}"
        );
    }
    assert_eq!(tr.translation_at(1.0).unwrap().x, 1.0);

    // Through glTF at the frames: glTF time i / fps is AFF frame i.
    let scene = import::load(&path).unwrap();
    let fps = scene.fps.unwrap();
    assert!((fps - 2.0).abs() < 1e-6, "fps {fps}");
    for i in 0..9 {
        let t = f64::from(i) * 0.5;
        let q = Quat::from_axis_angle(Vec3::Y, expect(angles, t).to_radians() as f32);
        let offset = Vec3::new(expect(xs, t) as f32, 0.0, 0.0);
        let want = [Vec3::ZERO, Vec3::Y, Vec3::Z].map(|p| q * p + offset);
        let got = soup_at(&scene, i as f32 / fps)[0];
        for k in 0..3 {
            assert_close(got[k], want[k], 1e-5, &format!("frame {i} vertex {k}"));
        }
    }
}

#[test]
fn animated_triangles_interpolate_linearly_and_clamp() {
    // Keys at 1, 3, 5; frames a -1 7 9 → t = -1, 0, 1, ..., 7.
    let path = write_scene(
        "tpa",
        &[(
            "tpa.aff",
            "a -1 7 9\n\
             tpa 3\n\
             1\n 0 0 0  0 0 1\n 1 0 0  0 0 1\n 0 1 0  0 0 1\n\
             3\n 0 0 2  0 0 1\n 1 0 2  0 0 1\n 0 1 2  0 0 1\n\
             5\n 4 0 2  0 0 1\n 5 0 2  0 0 1\n 4 1 2  0 0 1\n",
        )],
    );
    let base = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let expect = |t: f32| -> Vec3 {
        // Offset of the triangle: (0,0,0) until t=1, to (0,0,2) at 3, to (4,0,2) at 5.
        if t <= 1.0 {
            Vec3::ZERO
        } else if t <= 3.0 {
            Vec3::new(0.0, 0.0, (t - 1.0) / 2.0 * 2.0)
        } else if t <= 5.0 {
            Vec3::new((t - 3.0) / 2.0 * 4.0, 0.0, 2.0)
        } else {
            Vec3::new(4.0, 0.0, 2.0)
        }
    };
    let aff = AffScene::load(&path).unwrap();
    assert_eq!(aff.animated_triangle_count(), 1);
    let scene = import::load(&path).unwrap();
    let fps = scene.fps.unwrap();
    for i in 0..9 {
        let t = -1.0 + i as f32;
        let direct = aff.triangles_at(f64::from(t))[0];
        let via = soup_at(&scene, i as f32 / fps)[0];
        for k in 0..3 {
            let want = base[k] + expect(t);
            assert_close(direct[k], want, 1e-6, &format!("AFF at t={t}"));
            assert_close(via[k], want, 1e-5, &format!("glTF at frame {i}"));
        }
    }
    // In between keys, not on a frame: t = 2 (glTF time 3).
    let via = soup_at(&scene, 3.0)[0];
    assert_close(via[0], Vec3::new(0.0, 0.0, 1.0), 1e-5, "t = 2");
}

#[test]
fn the_default_range_is_the_a_lines_frames_whatever_the_keys_cover() {
    // Keys at AFF times 1..5 of a line `a -1 7 9`: its frames are 0..9 (t = -1 .. 7),
    // not the keys' 2..7; the same through the glTF that `convert` writes.
    let path = write_scene(
        "range",
        &[(
            "range.aff",
            "a -1 7 9\n\
             tpa 2\n\
             1\n 0 0 0  0 0 1\n 1 0 0  0 0 1\n 0 1 0  0 0 1\n\
             5\n 4 0 2  0 0 1\n 5 0 2  0 0 1\n 4 1 2  0 0 1\n",
        )],
    );
    let plan_of = |scene: &Scene| {
        let opts = subfield::render::RenderOptions {
            output: path.with_file_name("o/f.####.exr"),
            width: 8,
            height: 6,
            ..Default::default()
        };
        let plan = subfield::render::plan(scene, &opts).unwrap();
        plan.frames.iter().collect::<Vec<u32>>()
    };
    let scene = import::load(&path).unwrap();
    assert_eq!(plan_of(&scene), (0..9).collect::<Vec<u32>>());
    let glb = path.with_file_name("range.glb");
    import::write_gltf(&scene, &glb).unwrap();
    let converted = import::load(&glb).unwrap();
    assert_eq!(converted.time_range, scene.time_range);
    assert_eq!(plan_of(&converted), (0..9).collect::<Vec<u32>>());
}

#[test]
fn spheres_are_closed_round_and_outward() {
    let c = Vec3::new(1.0, -2.0, 3.0);
    for r in [0.5f32, -2.0] {
        let t = shapes::sphere(c, r);
        assert!(t.indices.len() / 3 >= 1000, "too coarse to look round");
        for p in &t.positions {
            let d = (*p - c).length();
            assert!(
                (d - r.abs()).abs() < 1e-5 * r.abs().max(1.0),
                "vertex off the sphere: {d}"
            );
        }
        check_closed_and_oriented(&t.positions, &t.indices, |centroid| {
            (centroid - c) * r.signum()
        });
        // Longest edge: a small fraction of the radius (round enough).
        let longest = t
            .indices
            .chunks_exact(3)
            .flat_map(|f| {
                let p = f
                    .iter()
                    .map(|&i| t.positions[i as usize])
                    .collect::<Vec<_>>();
                [
                    (p[0] - p[1]).length(),
                    (p[1] - p[2]).length(),
                    (p[2] - p[0]).length(),
                ]
            })
            .fold(0.0f32, f32::max);
        assert!(longest < 0.2 * r.abs(), "edge {longest}");
        // Flat facets stay within 1% of the surface (measured at their centroids).
        for f in t.indices.chunks_exact(3) {
            let centroid = f.iter().map(|&i| t.positions[i as usize]).sum::<Vec3>() / 3.0;
            assert!((centroid - c).length() > 0.99 * r.abs());
        }
    }
}

/// Every undirected edge is shared by exactly two triangles that use it in opposite
/// directions (a closed, consistently oriented surface), and every triangle faces
/// `outward(centroid)`.
fn check_closed_and_oriented(p: &[Vec3], idx: &[u32], outward: impl Fn(Vec3) -> Vec3) {
    use std::collections::HashMap;
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for f in idx.chunks_exact(3) {
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            *directed.entry((a, b)).or_default() += 1;
        }
        let [a, b, c] = [p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]];
        let n = (b - a).cross(c - a);
        assert!(
            n.dot(outward((a + b + c) / 3.0)) > 0.0,
            "triangle faces inwards"
        );
    }
    for (&(a, b), &count) in &directed {
        assert_eq!(count, 1, "edge {a}->{b} used twice in one direction");
        assert_eq!(directed.get(&(b, a)), Some(&1), "edge {a}-{b} is a border");
    }
}

#[test]
fn cones_are_round_open_tubes_facing_out() {
    let base = Vec3::new(0.0, 1.0, 0.0);
    let apex = Vec3::new(1.0, 3.0, -1.0);
    let axis = (apex - base).normalize();
    for (r0, r1) in [(0.5f32, 0.25f32), (0.3, 0.3), (-0.4, -0.2)] {
        let t = shapes::cone(base, r0, apex, r1);
        assert_eq!(t.indices.len() / 3, 2 * shapes::CONE_SLICES);
        for p in &t.positions {
            let along = (*p - base).dot(axis);
            let radial = (*p - base - axis * along).length();
            let at_base = along.abs() < 1e-5;
            let at_apex = (along - (apex - base).length()).abs() < 1e-5;
            assert!(at_base || at_apex, "vertex off both rims");
            let want = if at_base { r0.abs() } else { r1.abs() };
            assert!((radial - want).abs() < 1e-5, "radius {radial} vs {want}");
        }
        // Closed around the axis: every edge but the rims is shared by two triangles.
        use std::collections::HashMap;
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        for f in t.indices.chunks_exact(3) {
            for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
            let [a, b, c] = [0, 1, 2].map(|k| t.positions[f[k] as usize]);
            let centroid = (a + b + c) / 3.0;
            let along = (centroid - base).dot(axis);
            let out = (centroid - base - axis * along) * r0.signum();
            assert!(
                (b - a).cross(c - a).dot(out) > 0.0,
                "cone triangle faces inwards"
            );
        }
        // Base vertices are even, apex vertices odd: a rim edge joins two of a kind.
        let rim = |a: u32, b: u32| a % 2 == b % 2;
        for (&(a, b), &n) in &edges {
            assert_eq!(n, if rim(a, b) { 1 } else { 2 }, "edge {a}-{b}");
        }
    }
}

#[test]
fn time_range_gives_frame_times_and_fps() {
    let path = write_scene(
        "time",
        &[("t.aff", "a -1.0 5.0 300 % frames\np 3 0 0 0 1 0 0 0 1 0\n")],
    );
    let aff = AffScene::load(&path).unwrap();
    let r = aff.time.unwrap();
    assert_eq!((r.start, r.end, r.frames), (-1.0, 5.0, 300));
    assert_eq!(r.frame_time(0), -1.0);
    assert_eq!(r.frame_time(299), 5.0);
    assert!((r.frame_time(100) - (-1.0 + 100.0 * 6.0 / 299.0)).abs() < 1e-12);
    assert!((r.fps().unwrap() - 299.0 / 6.0).abs() < 1e-12);
    let g = aff.to_scene().unwrap();
    assert_eq!(g.fps, Some((299.0f64 / 6.0) as f32));
    assert_eq!(aff.frame_times().len(), 300);
    // A single frame: no clip, no fps.
    let one = AffScene::parse_str("a 2 2 1\n", Path::new("one.aff"), Path::new(".")).unwrap();
    assert_eq!(one.time.unwrap().fps(), None);
    assert_eq!(one.to_scene().unwrap().fps, None);
}

#[test]
fn camera_follows_view_then_keyframes() {
    let path = write_scene(
        "camera",
        &[(
            "cam.aff",
            "v\nfrom 0 1 5\nat 0 1 0\nup 0 1 0\nangle 40\nhither 0.01\nresolution 800 400\n\
             a 0 2 3\n\
             p 3 0 0 0 1 0 0 0 1 0\n\
             k camera {\n transl 4\n -1 0 0 0 0 0 0\n 0 1 2 3 0 0 0\n 2 3 2 1 0 0 0\n 3 0 0 0 0 0 0\n}\n",
        )],
    );
    let aff = AffScene::load(&path).unwrap();
    let scene = import::load(&path).unwrap();
    let fps = scene.fps.unwrap();
    for i in 0..3 {
        let t = f64::from(i);
        let a = aff.camera_at(t).unwrap();
        let c = scene
            .camera_at(ClipSelection::All, i as f32 / fps, None)
            .unwrap();
        assert_close(c.position, a.position.as_vec3(), 1e-5, "camera position");
        // Orientation from the v line: looking down -Z toward `at` (here along -Z).
        assert_close(
            c.rotation * Vec3::NEG_Z,
            Vec3::NEG_Z,
            1e-5,
            "view direction",
        );
        assert_close(c.rotation * Vec3::Y, Vec3::Y, 1e-5, "up");
        assert!((c.yfov().unwrap() - 40f32.to_radians()).abs() < 1e-6);
        assert_eq!(c.aspect(), Some(2.0));
    }
    assert_close(
        aff.camera_at(0.0).unwrap().position.as_vec3(),
        Vec3::new(1.0, 2.0, 3.0),
        1e-9,
        "key 1",
    );
    assert_close(
        aff.camera_at(2.0).unwrap().position.as_vec3(),
        Vec3::new(3.0, 2.0, 1.0),
        1e-9,
        "key 2",
    );
}

#[test]
fn textures_materials_lights_and_visibility_convert() {
    // A 2×1 binary PPM: red, then blue.
    let d = temp_dir("texture");
    let mut ppm = b"P6\n2 1\n255\n".to_vec();
    ppm.extend_from_slice(&[255, 0, 0, 0, 0, 255]);
    std::fs::write(d.join("rb.ppm"), &ppm).unwrap();
    let text = "a 0 4 5\n\
                l 1 2 3 0.5 0.5 0.5\nla lamp 0 0 0\n\
                fm 0.1 0.1 0.1  0.8 0.4 0.2  0.6 0.5 0.4  30 0.5 1.33\n\
                x blink {\n tt rb.ppm\n 0 0 0 0 0\n 1 0 0 1 0\n 0 1 0 0 1\n}\n\
                k blink { visibility 3\n 1 0\n 2 1\n 3 0\n }\n\
                k lamp { transl 4\n 0 0 0 0 0 0 0\n 1 0 0 0 0 0 0\n 3 2 0 0 0 0 0\n 4 2 0 0 0 0 0\n }\n";
    std::fs::write(d.join("s.aff"), text).unwrap();
    let path = d.join("s.aff");
    let aff = AffScene::load(&path).unwrap();
    assert_eq!(aff.textures[0].rgb8, vec![255, 0, 0, 0, 0, 255]);
    let scene = import::load(&path).unwrap();
    assert_eq!(scene.images.len(), 1);
    assert_eq!(scene.images[0].rgba8, vec![255, 0, 0, 255, 0, 0, 255, 255]);
    let m = scene
        .materials
        .iter()
        .find(|m| m.base_color_texture.is_some())
        .unwrap();
    // Transmissive: base colour min(1, kd + T), transmission T / max(base), so the
    // brightest channel passes T untinted, as AFF's refraction (issue 35).
    assert_close(
        m.base_color.truncate(),
        Vec3::new(1.0, 0.9, 0.7),
        1e-6,
        "diffuse",
    );
    assert!((m.metallic - 0.6).abs() < 1e-6);
    assert!((m.roughness - (2.0f32 / 32.0).powf(0.25)).abs() < 1e-6);
    assert_eq!(m.transmission, 0.5);
    assert!((m.ior - 1.33).abs() < 1e-6);
    assert!(m.double_sided);
    // Visible at t=0, hidden at 1, visible at 2, hidden from 3 on (scale 0 collapses it).
    for (t, visible) in [
        (0.0f32, true),
        (1.0, false),
        (2.0, true),
        (3.0, false),
        (4.0, false),
    ] {
        let tri = soup_at(&scene, t)[0];
        let area = (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
        assert_eq!(area > 0.0, visible, "visibility at {t}");
        assert_eq!(
            aff.triangles_at(f64::from(t))[0][1] != aff.triangles_at(f64::from(t))[0][0],
            visible
        );
    }
    // Lights: the static one with its colour; the named one moved by its keyframes.
    let lights = scene.lights_at(ClipSelection::All, 2.0);
    assert_eq!(lights.len(), 2);
    assert_close(lights[0].position, Vec3::new(1.0, 2.0, 3.0), 1e-6, "light");
    assert_close(lights[0].color, Vec3::splat(0.5), 1e-6, "light colour");
    let lamp = aff.tracks["lamp"].translation_at(2.0).unwrap().as_vec3();
    assert_close(lights[1].position, lamp, 1e-5, "lamp");
    assert!(lamp.x > 0.0 && lamp.x < 2.0);
}

#[test]
fn includes_honour_detail_levels_and_meshes_index_correctly() {
    let path = write_scene(
        "include",
        &[
            ("top.aff", "d 1\ni 0 low.aff\ni 1 mid.aff\ni 2 high.aff\n"),
            (
                "low.aff",
                "m\n vertices 4\n 0 0 0\n 1 0 0\n 1 1 0\n 0 1 0\n triangles 2\n 0 1 2\n 0 2 3\n",
            ),
            ("mid.aff", "s 0 0 0 1\n"),
            ("high.aff", "this file is never read\n"),
        ],
    );
    let aff = AffScene::load(&path).unwrap();
    let tris = aff.triangles_at(0.0);
    assert_eq!(tris[0], [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)]);
    assert_eq!(tris[1], [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]);
    let sphere = shapes::sphere(Vec3::ZERO, 1.0).indices.len() / 3;
    assert_eq!(aff.triangle_count(), 2 + sphere);
}

/// `text` as the file `bad.aff` (plus `extra` files) must fail; returns the message.
fn error_of(test: &str, text: &str, extra: &[(&str, &[u8])]) -> String {
    let d = temp_dir(test);
    for (n, b) in extra {
        std::fs::write(d.join(n), b).unwrap();
    }
    std::fs::write(d.join("bad.aff"), text).unwrap();
    let e = AffScene::load(&d.join("bad.aff")).unwrap_err();
    // import::load reports the same problem.
    let s = import::load(&d.join("bad.aff")).unwrap_err().to_string();
    assert_eq!(s, e.to_string());
    e.to_string()
}

#[test]
fn malformed_input_names_file_and_line() {
    let e = error_of("unknown", "p 3 0 0 0 1 0 0 0 1 0\n\nbogus 1 2 3\n", &[]);
    assert!(
        e.contains("bad.aff:3:") && e.contains("unknown keyword \"bogus\""),
        "{e}"
    );

    let e = error_of("include", "\ni 0 nowhere.aff\n", &[]);
    assert!(
        e.contains("bad.aff:2:") && e.contains("cannot read include \"nowhere.aff\""),
        "{e}"
    );

    // Too few numbers: the polygon runs into the next keyword, or into the end of file.
    let e = error_of("few", "p 3\n 0 0 0\n 1 0 0\ns 0 0 0 1\n", &[]);
    assert!(
        e.contains("bad.aff:4:") && e.contains("expected a number") && e.contains("\"s\""),
        "{e}"
    );
    let e = error_of("eof", "fm 1 1 1  1 1 1\n", &[]);
    assert!(
        e.contains("bad.aff:1:") && e.contains("unexpected end of file"),
        "{e}"
    );

    // An error inside an include names the included file and its line.
    let e = error_of(
        "nested",
        "i 0 part.aff\n",
        &[("part.aff", b"\n\ns 1 2 x 4\n")],
    );
    assert!(e.contains("part.aff:3:") && e.contains("\"x\""), "{e}");

    // Bad textures: missing, and not an image.
    let e = error_of(
        "notex",
        "tt gone.ppm\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n",
        &[],
    );
    assert!(
        e.contains("bad.aff:1:") && e.contains("texture \"gone.ppm\"") && e.contains("cannot read"),
        "{e}"
    );
    let e = error_of(
        "badtex",
        "\ntt junk.ppm\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n",
        &[("junk.ppm", b"P6\n4 4\n255\nshort")],
    );
    assert!(
        e.contains("bad.aff:2:")
            && e.contains("texture \"junk.ppm\"")
            && e.contains("cannot decode"),
        "{e}"
    );

    // Blocks and keyframes.
    let e = error_of("unclosed", "xs 1 1 1 0 1 0 0 0 0 0\n{\n", &[]);
    assert!(
        e.contains("bad.aff:1:") && e.contains("never closed"),
        "{e}"
    );
    let e = error_of("extra", "}\n", &[]);
    assert!(
        e.contains("bad.aff:1:") && e.contains("without an open block"),
        "{e}"
    );
    let e = error_of(
        "fewkeys",
        "x a { }\nk a {\n rot 3\n 0 0 1 0 0 0 0 0\n 1 0 1 0 0 0 0 0\n 2 0 1 0 0 0 0 0\n}\n",
        &[],
    );
    assert!(e.contains("bad.aff:3:") && e.contains("at least 4"), "{e}");
    let e = error_of("track", "x a { }\nk a {\n wobble 1\n}\n", &[]);
    assert!(
        e.contains("bad.aff:3:") && e.contains("unknown track"),
        "{e}"
    );
    let e = error_of(
        "index",
        "m\nvertices 3\n0 0 0\n1 0 0\n0 1 0\ntriangles 1\n0 1 3\n",
        &[],
    );
    assert!(
        e.contains("bad.aff:7:") && e.contains("vertex index 3 out of range"),
        "{e}"
    );
    let e = error_of("frames", "a 5 1 10\n", &[]);
    assert!(e.contains("bad.aff:1:") && e.contains("not after"), "{e}");
    let e = error_of("tpa", "tpa 2\n1\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n1\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n", &[]);
    assert!(
        e.contains("bad.aff:6:") && e.contains("must increase"),
        "{e}"
    );
    let e = error_of("cycle", "i 0 bad.aff\n", &[]);
    assert!(e.contains("nested more than"), "{e}");
}

/// Issue 25: an include or a texture name is a file in the scene's folder, under the
/// policy of glTF URIs. An absolute path, a `..` above the folder and a symbolic link out
/// of it were followed, and the parse error then quoted the outside file's first word.
#[test]
fn aff_includes_and_textures_outside_the_scene_folder_are_refused() {
    let root = temp_dir("confined");
    let folder = root.join("scene");
    std::fs::create_dir_all(folder.join("parts")).unwrap();
    // Outside files a lax reader would read: an "AFF" whose first word is a secret, and
    // an image.
    std::fs::write(root.join("outside.aff"), "secretword 1 2 3\n").unwrap();
    let mut ppm = b"P6\n1 1\n255\n".to_vec();
    ppm.extend_from_slice(&[1, 2, 3]);
    std::fs::write(root.join("outside.ppm"), &ppm).unwrap();
    std::fs::write(folder.join("parts/inside.aff"), "s 0 0 0 1\n").unwrap();
    std::fs::write(folder.join("parts/inside.ppm"), &ppm).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::symlink;
        symlink(root.join("outside.aff"), folder.join("link.aff")).unwrap();
        symlink(root.join("outside.ppm"), folder.join("link.ppm")).unwrap();
        symlink(&root, folder.join("up")).unwrap();
        symlink(folder.join("parts/inside.aff"), folder.join("near.aff")).unwrap();
    }
    let abs_aff = root.join("outside.aff").display().to_string();
    let abs_ppm = root.join("outside.ppm").display().to_string();
    let tri = "0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n";
    let mut cases: Vec<(String, &str, &str)> = vec![
        (format!("\ni 0 {abs_aff}\n"), "include", "an absolute path"),
        (
            "\ni 0 ../outside.aff\n".into(),
            "include",
            "above the folder",
        ),
        (
            "\ni 0 parts/../../outside.aff\n".into(),
            "include",
            "above the folder",
        ),
        (
            format!("\ntt {abs_ppm}\n{tri}"),
            "texture",
            "an absolute path",
        ),
        (
            format!("\ntt ../outside.ppm\n{tri}"),
            "texture",
            "above the folder",
        ),
    ];
    if cfg!(unix) {
        cases.push(("\ni 0 link.aff\n".into(), "include", "symbolic link"));
        cases.push(("\ni 0 up/outside.aff\n".into(), "include", "symbolic link"));
        cases.push((format!("\ntt link.ppm\n{tri}"), "texture", "symbolic link"));
    }
    let top = folder.join("top.aff");
    for (text, what, why) in &cases {
        std::fs::write(&top, text).unwrap();
        let e = AffScene::load(&top).unwrap_err();
        assert!(
            matches!(e, ImportError::OutsideFolder { .. }),
            "{text:?}: {e}"
        );
        let msg = e.to_string();
        let name = text
            .split_whitespace()
            .nth(if *what == "include" { 2 } else { 1 })
            .unwrap();
        // One line naming the file and line, the include or texture, and the folder.
        assert!(!msg.contains('\n'), "{msg}");
        assert!(
            msg.starts_with(&format!("{}:2: {what} {name:?}", top.display())),
            "{msg}"
        );
        assert!(
            msg.contains(&format!("leaves the scene's folder {}", folder.display()))
                && msg.contains(why),
            "{msg}"
        );
        // Nothing outside was read: its contents are never quoted.
        assert!(!msg.contains("secretword"), "{msg}");
        assert_eq!(import::load(&top).unwrap_err().to_string(), msg);
    }
    // Inside the folder, through a sub-folder, `..` that stays inside, or a link to a file
    // inside: read.
    let mut ok = vec![
        "i 0 parts/inside.aff\n".to_string(),
        "i 0 parts/../parts/inside.aff\n".into(),
        format!("tt parts/inside.ppm\n{tri}"),
    ];
    if cfg!(unix) {
        ok.push("i 0 near.aff\n".into());
    }
    for text in ok {
        std::fs::write(&top, &text).unwrap();
        let aff = AffScene::load(&top).unwrap_or_else(|e| panic!("{text:?}: {e}"));
        assert!(aff.triangle_count() > 0, "{text:?}");
    }
}

#[test]
fn keyframes_naming_nothing_are_a_warning_not_an_error() {
    // BART's robots scene has `k old_camera` that nothing uses; BART ignores it, so do we
    // (with a warning that names the file and line).
    let path = write_scene(
        "orphan",
        &[(
            "o.aff",
            "p 3 0 0 0 1 0 0 0 1 0\n\nk ghost {\n transl 4\n 0 0 0 0 0 0 0\n 1 0 0 0 0 0 0\n 2 0 0 0 0 0 0\n 3 0 0 0 0 0 0\n}\n",
        )],
    );
    let aff = AffScene::load(&path).unwrap();
    assert_eq!(aff.warnings.len(), 1);
    assert!(aff.warnings[0].contains("o.aff:3:") && aff.warnings[0].contains("ghost"));
    let scene = import::load(&path).unwrap();
    assert!(scene.warnings.iter().any(|w| w.0.contains("ghost")));
}

const FUZZ_SEED_TEXT: &str = "b 0.1 0.2 0.3\nv\nfrom 0 1 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 0.1\nresolution 64 48\n\
l 1 1 1\nla lamp 0 2 0 1 1 1\nf 1 0 0 1 0.5 10 0 1\n\
fm 0.1 0.1 0.1 0.5 0.5 0.5 0.2 0.2 0.2 20 0.5 1.5\n\
p 4\n0 0 0\n1 0 0\n1 1 0\n0 1 0\npp 3\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n\
s 0 0 0 0.5\nc 0 0 0 0.2 0 1 0 0.1\n\
xs 1 2 1 0 1 0 45 1 0 0\n{\nx spin\n{\nm\nvertices 3\n0 0 0\n1 0 0\n0 1 0\nnormals 1\n0 0 1\ntriangles 1\n0 1 2 0 0 0\n}\n}\n\
tpa 2\n0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n1\n0 0 1 0 0 1\n1 0 1 0 0 1\n0 1 1 0 0 1\n\
a 0 1 5\n\
k spin {\nrot 4\n0 0 1 0 0 0 0 0\n0.3 0 1 0 90 0 0 0\n0.6 0 1 0 180 0 0 0\n1 0 1 0 270 0 0 0\nvisibility 2\n0.2 0\n0.5 1\n}\n\
k lamp {\ntransl 4\n0 0 0 0 0 0 0\n0.3 1 0 0 0 0 0\n0.6 1 1 0 0 0 0\n1 0 1 0 0 0 0\n}\n";

#[test]
fn mutated_input_never_panics() {
    // The seed text is valid and uses most statements.
    let folder = temp_dir("fuzz");
    let name = folder.join("fuzz.aff");
    let seed = AffScene::parse_str(FUZZ_SEED_TEXT, &name, &folder).unwrap();
    assert!(seed.triangle_count() > 0);
    import::to_glb(&seed.to_scene().unwrap()).unwrap();

    let mut state = 0x1234_5678_9abc_def0u64;
    let mut rnd = |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    let alphabet = b"0123456789-.e{}#% \nabcdfilmpstvxk";
    let (mut ok, mut failed) = (0, 0);
    for _ in 0..400 {
        let mut text = FUZZ_SEED_TEXT.as_bytes().to_vec();
        for _ in 0..1 + rnd(4) {
            let at = rnd(text.len());
            match rnd(4) {
                0 => {
                    text.remove(at);
                }
                1 => text.insert(at, alphabet[rnd(alphabet.len())]),
                2 => text[at] = alphabet[rnd(alphabet.len())],
                _ => {
                    let end = (at + 1 + rnd(20)).min(text.len());
                    let chunk = text[at..end].to_vec();
                    let to = rnd(text.len());
                    text.splice(to..to, chunk);
                }
            }
        }
        let text = String::from_utf8_lossy(&text).into_owned();
        // Parse, convert, write and import again: errors are fine, panics are not.
        match AffScene::parse_str(&text, &name, &folder) {
            Ok(s) => match s.to_scene().and_then(|g| import::to_glb(&g)) {
                Ok(glb) => {
                    let _ = s.triangles_at(0.5);
                    match import::from_gltf_slice(&glb, &name, &folder) {
                        Ok(_) => ok += 1,
                        Err(_) => failed += 1,
                    }
                }
                Err(_) => failed += 1,
            },
            Err(e) => {
                assert!(
                    matches!(e, ImportError::Syntax { .. } | ImportError::Texture { .. }),
                    "{e}"
                );
                assert!(e.to_string().contains("fuzz.aff:"), "{e}");
                failed += 1;
            }
        }
    }
    eprintln!("fuzz: {ok} parsed and converted, {failed} rejected");
    assert!(ok > 0 && failed > 0);
}

#[test]
fn animart_generator_is_deterministic_and_parses() {
    let p = AnimartParams {
        triangles: 300,
        seed: 7,
        frames: 120,
    };
    let text = generate_animart(&p);
    assert_eq!(text, generate_animart(&p));
    assert_ne!(text, generate_animart(&AnimartParams { seed: 8, ..p }));
    let folder = temp_dir("animart");
    let aff = AffScene::parse_str(&text, &folder.join("animart.aff"), &folder).unwrap();
    assert_eq!(aff.triangle_count(), 300);
    assert_eq!(aff.animated_triangle_count(), 300);
    let r = aff.time.unwrap();
    assert_eq!((r.start, r.end, r.frames), (-1.0, 5.0, 120));
    // Inside the museum animart's box at every key, and really moving.
    let (lo, hi) = (Vec3::new(-1.3, 1.4, -1.3), Vec3::new(1.3, 4.45, 1.3));
    let mut previous: Option<Vec<[Vec3; 3]>> = None;
    for t in [0.0, 1.0, 2.0, 3.0, 4.0] {
        let tris = aff.triangles_at(t);
        for p in tris.iter().flatten() {
            assert!(
                p.cmpge(lo).all() && p.cmple(hi).all(),
                "{p} outside at t={t}"
            );
        }
        if let Some(prev) = &previous {
            let moved = prev
                .iter()
                .zip(&tris)
                .filter(|(a, b)| (a[0] - b[0]).length() > 1e-3)
                .count();
            assert!(moved > 250, "only {moved} triangles moved before t={t}");
        }
        previous = Some(tris);
    }
    // Key 2 is a cube of tiles and key 3 a sphere around (0, 2.6, 0).
    let c = Vec3::new(0.0, 2.6, 0.0);
    for p in aff.triangles_at(3.0).iter().flatten() {
        assert!(((*p - c).length() - 0.6).abs() < 1e-4);
    }
    for p in aff.triangles_at(2.0).iter().flatten() {
        assert!(((*p - c).abs().max_element() - 0.5).abs() < 1e-4);
    }
}

/// A plain NFF file (the AFF subset Eric Haines' SPD scenes use): viewpoint, background,
/// lights, a fill material, a polygon, a sphere and a cone load through `import::load` by
/// its `.nff` extension, with the camera where `v` puts it, the lights, and the geometry;
/// `subfield render` takes it like any scene.
#[test]
fn plain_nff_loads_and_renders() {
    let path = write_scene(
        "nff",
        &[(
            "spd.nff",
            "v\nfrom 0 -6 2\nat 0 0 0.5\nup 0 0 1\nangle 45\nhither 0.01\nresolution 64 48\n\
             b 0.1 0.2 0.3\n\
             l 4 -4 6\nl -4 -4 6 1 1 1\n\
             f 0.8 0.6 0.4 0.7 0.3 20 0 1\n\
             p 4\n-3 -3 0\n3 -3 0\n3 3 0\n-3 3 0\n\
             f 0.2 0.5 0.9 0.5 0.5 40 0.5 1\n\
             s 0 0 1 0.75\n\
             c 1.5 0 0 0.4 1.5 0 1.2 0.1\n",
        )],
    );
    let scene = import::load(&path).unwrap();
    let tris = soup_at(&scene, 0.0);
    let aff = AffScene::load(&path).unwrap();
    assert_eq!(tris.len(), aff.triangle_count());
    // The square floor is 2 triangles; the sphere and the cone add many more.
    assert!(tris.len() > 2 + 50, "{} triangles", tris.len());
    assert!(
        tris.iter().take(2).flatten().all(|p| p.z == 0.0),
        "the floor comes first, at z = 0"
    );
    // The sphere's triangles lie on it (within tessellation: vertices exactly).
    let on_sphere = tris
        .iter()
        .flatten()
        .filter(|p| ((**p - Vec3::new(0.0, 0.0, 1.0)).length() - 0.75).abs() < 1e-5)
        .count();
    assert!(on_sphere > 100, "{on_sphere} vertices on the sphere");

    let cam = scene
        .camera_at(ClipSelection::All, 0.0, None)
        .expect("the NFF viewpoint becomes a camera");
    assert_close(
        cam.position,
        Vec3::new(0.0, -6.0, 2.0),
        1e-5,
        "camera position",
    );
    let fwd = cam.rotation * Vec3::NEG_Z;
    let want = (Vec3::new(0.0, 0.0, 0.5) - Vec3::new(0.0, -6.0, 2.0)).normalize();
    assert_close(fwd, want, 1e-5, "camera looks at `at`");
    let lights = scene.lights_at(ClipSelection::All, 0.0);
    assert_eq!(lights.len(), 2);
    assert_close(
        lights[0].position,
        Vec3::new(4.0, -4.0, 6.0),
        1e-5,
        "light 0",
    );

    // The render through the command line, which the `cli` feature builds.
    #[cfg(feature = "cli")]
    {
        let out = path.with_file_name("f.exr");
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_subfield"))
            .args([
                "render",
                path.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--size",
                "64x48",
                "--quiet",
            ])
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        assert!(out.exists());
    }
}
