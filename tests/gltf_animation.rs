//! Posed vertex positions checked against values worked out in the test from the files'
//! raw numbers (tests/common reads JSON and bytes itself and evaluates channels, node
//! hierarchies and skins with its own code), plus clip selection and the split rules on
//! scenes built in code.

mod common;

use common::build::{soup_prim, targets, SceneBuilder};
use common::{max_dist, RawGltf};
use glam::{Mat4, Quat, Vec3};
use subfield::import;
use subfield::scene::{
    Animation, Channel, ClipSelection, Interpolation, Mesh, Node, Property, Scene, TriangleSoup,
};

/// The library's posed vertices, recovered from its triangles through the file's own
/// index list (each corner of triangle `t` is vertex `indices[3t + k]`).
fn vertices_from_soup(soup: &[[Vec3; 3]], indices: &[usize], nv: usize) -> Vec<Vec3> {
    assert_eq!(soup.len() * 3, indices.len());
    let mut out = vec![Vec3::NAN; nv];
    for (t, tri) in soup.iter().enumerate() {
        for k in 0..3 {
            out[indices[3 * t + k]] = tri[k];
        }
    }
    assert!(
        out.iter().all(|v| v.is_finite()),
        "a vertex no triangle uses"
    );
    out
}

fn raw_indices(raw: &RawGltf, prim: &serde_json::Value) -> Vec<usize> {
    let (i, _) = raw.accessor(prim["indices"].as_u64().unwrap() as usize);
    i.iter().map(|&x| x as usize).collect()
}

/// Expected skinned positions: sum_k w_k (world[joint_k] * ibm_k) v, from raw data.
fn expected_skinned(raw: &RawGltf, mesh_node: usize, t: f64) -> Vec<Vec3> {
    let node = &raw.json["nodes"][mesh_node];
    let skin = &raw.json["skins"][node["skin"].as_u64().unwrap() as usize];
    let prim = &raw.json["meshes"][node["mesh"].as_u64().unwrap() as usize]["primitives"][0];
    let attr = |k: &str| prim["attributes"][k].as_u64().unwrap() as usize;
    let pos = raw.vec3s(attr("POSITION"));
    let (joints, _) = raw.accessor(attr("JOINTS_0"));
    let (weights, _) = raw.accessor(attr("WEIGHTS_0"));
    let (ibm, _) = raw.accessor(skin["inverseBindMatrices"].as_u64().unwrap() as usize);
    let joint_nodes: Vec<usize> = skin["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j.as_u64().unwrap() as usize)
        .collect();
    let world = raw.world_at(t);
    let jm: Vec<Mat4> = joint_nodes
        .iter()
        .enumerate()
        .map(|(j, &n)| {
            let m: Vec<f32> = ibm[16 * j..16 * j + 16].iter().map(|&x| x as f32).collect();
            world[n] * Mat4::from_cols_slice(&m)
        })
        .collect();
    pos.iter()
        .enumerate()
        .map(|(v, p)| {
            let mut acc = Vec3::ZERO;
            for k in 0..4 {
                let w = weights[4 * v + k] as f32;
                acc += w * jm[joints[4 * v + k] as usize].transform_point3(*p);
            }
            acc
        })
        .collect()
}

fn dynamic_soup(scene: &Scene, t: f32) -> TriangleSoup {
    let split = scene.split(ClipSelection::All);
    let mut soup = TriangleSoup::new();
    scene.dynamic_triangles_at(&split, t, &mut soup);
    soup
}

#[test]
fn simple_skin_by_hand() {
    let Some(path) = common::shared_scene("gltf/SimpleSkin/SimpleSkin.gltf") else {
        return;
    };
    let scene = import::load(&path).unwrap();
    let raw = RawGltf::open(&path);
    let prim = &raw.json["meshes"][0]["primitives"][0];
    let idx = raw_indices(&raw, prim);

    // By hand: vertex 9 = (1, 2, 0) hangs on joint 1 (node 2) alone. Node 2 is a child of
    // node 1 (translation (0, 1, 0)); both inverse bind matrices translate by
    // (-0.5, -1, 0). Node 2 rotates about +Z; between two keyframes about the same axis
    // slerp turns the angle linearly. So at angle θ:
    //   v' = (0, 1, 0) + Rz(θ) (0.5, 1, 0) = (0.5 cos θ − sin θ, 1 + 0.5 sin θ + cos θ, 0).
    let (times, _) = raw.accessor(5);
    let (rot, _) = raw.accessor(6);
    let angle = |k: usize| 2.0 * rot[4 * k + 2].atan2(rot[4 * k + 3]);
    for t in [0.0f64, 0.25, 0.6, 1.2, 3.9, 5.5] {
        let k = times
            .iter()
            .rposition(|&x| x <= t)
            .unwrap()
            .min(times.len() - 2);
        let s = ((t - times[k]) / (times[k + 1] - times[k])).clamp(0.0, 1.0);
        let th = angle(k) + s * (angle(k + 1) - angle(k));
        let want = Vec3::new(
            (0.5 * th.cos() - th.sin()) as f32,
            (1.0 + 0.5 * th.sin() + th.cos()) as f32,
            0.0,
        );
        let soup = dynamic_soup(&scene, t as f32);
        let got = vertices_from_soup(&soup.positions, &idx, 10);
        assert!(
            got[9].abs_diff_eq(want, 1e-5),
            "t={t}: {} vs {want}",
            got[9]
        );
        // And every vertex against the general formula.
        let all = expected_skinned(&raw, 0, t);
        assert!(max_dist(&got, &all) < 1e-5, "t={t}");
    }
}

#[test]
fn rigged_figure_and_other_skins_match_independent_skinning() {
    let Some(dir) = common::shared_gltf() else {
        return;
    };
    for (file, mesh_node, times) in [
        (
            "RiggedFigure/RiggedFigure.glb",
            1usize,
            vec![0.0f64, 0.3, 0.77, 1.25],
        ),
        ("CesiumMan/CesiumMan.glb", 2, vec![0.1, 0.9, 1.7]),
    ] {
        let path = dir.join(file);
        let scene = import::load(&path).unwrap();
        let raw = RawGltf::open(&path);
        let node = &raw.json["nodes"][mesh_node];
        assert!(
            node.get("skin").is_some(),
            "{file}: node {mesh_node} is the skinned one"
        );
        let prim = &raw.json["meshes"][node["mesh"].as_u64().unwrap() as usize]["primitives"][0];
        let idx = raw_indices(&raw, prim);
        for t in times {
            let want = expected_skinned(&raw, mesh_node, t);
            let soup = dynamic_soup(&scene, t as f32);
            let got = vertices_from_soup(&soup.positions, &idx, want.len());
            let scale = want.iter().map(|v| v.length()).fold(0.0, f32::max);
            let d = max_dist(&got, &want);
            assert!(d < 1e-5 * scale.max(1.0), "{file} t={t}: off by {d}");
        }
    }
}

#[test]
fn animated_morph_cube_matches_weights_by_hand() {
    let Some(path) = common::shared_scene("gltf/AnimatedMorphCube/AnimatedMorphCube.gltf") else {
        return;
    };
    let scene = import::load(&path).unwrap();
    let raw = RawGltf::open(&path);
    let prim = &raw.json["meshes"][0]["primitives"][0];
    let idx = raw_indices(&raw, prim);
    let base = raw.vec3s(prim["attributes"]["POSITION"].as_u64().unwrap() as usize);
    let d0 = raw.vec3s(prim["targets"][0]["POSITION"].as_u64().unwrap() as usize);
    let d1 = raw.vec3s(prim["targets"][1]["POSITION"].as_u64().unwrap() as usize);
    let sampler = &raw.json["animations"][0]["samplers"][0];
    assert_eq!(sampler["interpolation"], "LINEAR");
    let (times, _) = raw.accessor(sampler["input"].as_u64().unwrap() as usize);
    let (w, _) = raw.accessor(sampler["output"].as_u64().unwrap() as usize);
    let (t, r, s) = raw.rest_trs(0);
    let node = Mat4::from_translation(t) * Mat4::from_quat(r) * Mat4::from_scale(s);
    for time in [0.0f64, 0.7, 1.3, 2.1, 3.33, 4.2] {
        // Two weights per keyframe, interpolated linearly by hand.
        let k = times
            .iter()
            .rposition(|&x| x <= time)
            .unwrap()
            .min(times.len() - 2);
        let a = ((time - times[k]) / (times[k + 1] - times[k])).clamp(0.0, 1.0);
        let w0 = (w[2 * k] + a * (w[2 * k + 2] - w[2 * k])) as f32;
        let w1 = (w[2 * k + 1] + a * (w[2 * k + 3] - w[2 * k + 1])) as f32;
        let want: Vec<Vec3> = (0..base.len())
            .map(|v| node.transform_point3(base[v] + w0 * d0[v] + w1 * d1[v]))
            .collect();
        let soup = dynamic_soup(&scene, time as f32);
        let got = vertices_from_soup(&soup.positions, &idx, base.len());
        let d = max_dist(&got, &want);
        assert!(d < 1e-4, "t={time}: off by {d} (cube is 100 units wide)");
    }
}

#[test]
fn box_animated_hierarchy() {
    let Some(path) = common::shared_scene("gltf/BoxAnimated/BoxAnimated.gltf") else {
        return;
    };
    let scene = import::load(&path).unwrap();
    let raw = RawGltf::open(&path);
    // Node 2 (mesh 0) rotates under node 0, which translates: dynamic. Node 3 (mesh 1)
    // is not animated: static.
    let split = scene.split(ClipSelection::All);
    assert_eq!(split.dynamic_instances.len(), 1);
    assert_eq!(split.dynamic_instances[0].node, 2);
    assert_eq!(split.static_instances.len(), 1);
    assert_eq!(split.static_instances[0].node, 3);
    let prim = &raw.json["meshes"][0]["primitives"][0];
    let idx = raw_indices(&raw, prim);
    let pos = raw.vec3s(prim["attributes"]["POSITION"].as_u64().unwrap() as usize);
    let mut soup = TriangleSoup::new();
    for t in [0.0f64, 0.5, 1.7, 2.9, 3.7] {
        let world = raw.world_at(t)[2];
        let want: Vec<Vec3> = pos.iter().map(|p| world.transform_point3(*p)).collect();
        scene.dynamic_triangles_at(&split, t as f32, &mut soup);
        let got = vertices_from_soup(&soup.positions, &idx, pos.len());
        let d = max_dist(&got, &want);
        assert!(d < 1e-5, "t={t}: off by {d}");
    }
    // The static box sits where its rest transform puts it.
    let prim1 = &raw.json["meshes"][1]["primitives"][0];
    let pos1 = raw.vec3s(prim1["attributes"]["POSITION"].as_u64().unwrap() as usize);
    let stat = scene.static_triangles(&split);
    let got = vertices_from_soup(&stat.positions, &raw_indices(&raw, prim1), pos1.len());
    assert!(max_dist(&got, &pos1) < 1e-6);
}

/// CUBICSPLINE on a real file: the camera and a light of AnimatedCameraAndLight, against
/// the Hermite formula evaluated in the test from the raw keyframes.
#[test]
fn cubic_spline_camera_and_light() {
    let Some(path) =
        common::shared_scene("gltf/AnimatedCameraAndLight/animated_camera_and_light.glb")
    else {
        return;
    };
    let scene = import::load(&path).unwrap();
    let raw = RawGltf::open(&path);
    let anim = &raw.json["animations"][1];
    assert_eq!(anim["name"], "CameraAnimation");
    let sampler = |k: usize| {
        let s = &anim["samplers"][k];
        assert_eq!(s["interpolation"], "CUBICSPLINE");
        let (times, _) = raw.accessor(s["input"].as_u64().unwrap() as usize);
        let (vals, w) = raw.accessor(s["output"].as_u64().unwrap() as usize);
        (times, vals, w)
    };
    let (tt, tv, tw) = sampler(0);
    let (rt, rv, rw) = sampler(1);
    for t in [0.0f64, 0.37, 1.1, 2.5, 3.3, 5.0, 7.7, 100.0] {
        let p = common::sample_raw(&tt, &tv, tw, "CUBICSPLINE", false, t);
        let q = common::sample_raw(&rt, &rv, rw, "CUBICSPLINE", true, t);
        let q = Quat::from_xyzw(q[0], q[1], q[2], q[3]).normalize();
        let cam = scene.camera_at(ClipSelection::All, t as f32, None).unwrap();
        assert!(
            cam.position.abs_diff_eq(Vec3::new(p[0], p[1], p[2]), 1e-4),
            "t={t}: {} vs {p:?}",
            cam.position
        );
        assert!(
            cam.rotation.dot(q).abs() > 1.0 - 1e-6,
            "t={t}: {} vs {q}",
            cam.rotation
        );
        // The one clip alone gives the same camera.
        let alone = scene
            .camera_at(ClipSelection::One(1), t as f32, None)
            .unwrap();
        assert_eq!(alone.position, cam.position);
    }
    // LightFront (node 3) rotates by CUBICSPLINE too: its direction is R * -Z.
    let la = &raw.json["animations"][2];
    let s = &la["samplers"][0];
    let (times, _) = raw.accessor(s["input"].as_u64().unwrap() as usize);
    let (vals, w) = raw.accessor(s["output"].as_u64().unwrap() as usize);
    for t in [0.2f64, 1.9, 4.4] {
        let q = common::sample_raw(&times, &vals, w, "CUBICSPLINE", true, t);
        let q = Quat::from_xyzw(q[0], q[1], q[2], q[3]).normalize();
        let lights = scene.lights_at(ClipSelection::All, t as f32);
        let front = lights.iter().find(|l| l.node == 3).unwrap();
        assert!(front.direction.abs_diff_eq(q * Vec3::NEG_Z, 1e-5), "t={t}");
    }
}

/// One triangle with the scene's default material (which `material` names).
fn triangle_mesh(material: u32) -> Mesh {
    Mesh {
        primitives: vec![soup_prim(vec![Vec3::X, Vec3::Y, Vec3::ZERO], material)],
        ..Default::default()
    }
}

/// A builder whose scene has the default material, and its index.
fn builder() -> (SceneBuilder, u32) {
    let mut b = SceneBuilder::new();
    let m = b.scene.default_material_index();
    (b, m)
}

/// The scene written as `name` and imported again.
fn built(b: SceneBuilder, name: &str) -> Scene {
    let dir = std::env::temp_dir().join(format!("subfield-anim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    import::write_gltf(&b.finish(), &path).unwrap();
    import::load(&path).unwrap()
}

/// A triangle translated by a CUBICSPLINE channel; expected positions by hand.
#[test]
fn cubic_spline_vertices_by_hand() {
    let (mut b, m) = builder();
    let mesh = b.add_mesh(triangle_mesh(m));
    let node = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    b.add_root(node);
    // key 0 at t=0: in (0,0,0), value (0,0,0), out (1,0,0)
    // key 1 at t=2: in (0,1,0), value (4,0,0), out (0,0,0)
    b.add_animation(Animation {
        name: Some("spline".into()),
        channels: vec![Channel {
            node,
            property: Property::Translation,
            interpolation: Interpolation::CubicSpline,
            times: vec![0.0, 2.0],
            values: vec![
                0., 0., 0., 0., 0., 0., 1., 0., 0., 0., 1., 0., 4., 0., 0., 0., 0., 0.,
            ],
        }],
    });
    let scene = built(b, "spline.glb");
    // t = 1: s = 1/2, td = 2; h00 = 1/2, h10 = 1/8, h01 = 1/2, h11 = -1/8:
    //   p = 1/8·2·(1,0,0) + 1/2·(4,0,0) − 1/8·2·(0,1,0) = (2.25, −0.25, 0)
    // t = 0.5: s = 1/4: h10 = 9/64, h01 = 5/32, h11 = −3/64:
    //   p = 9/64·2·(1,0,0) + 5/32·(4,0,0) − 3/64·2·(0,1,0) = (0.90625, −0.09375, 0)
    for (t, offset) in [
        (0.0, Vec3::ZERO),
        (0.5, Vec3::new(0.90625, -0.09375, 0.0)),
        (1.0, Vec3::new(2.25, -0.25, 0.0)),
        (2.0, Vec3::new(4.0, 0.0, 0.0)),
        (3.0, Vec3::new(4.0, 0.0, 0.0)),
    ] {
        let soup = dynamic_soup(&scene, t);
        assert_eq!(soup.len(), 1);
        let want = [Vec3::X + offset, Vec3::Y + offset, offset];
        for (got, want) in soup.positions[0].iter().zip(want) {
            assert!(
                got.abs_diff_eq(want, 1e-6),
                "t={t}: {:?}",
                soup.positions[0]
            );
        }
    }
}

/// Two clips driving the same translation: all clips → the later wins; one clip → its own.
#[test]
fn later_clip_wins_and_selection() {
    let (mut b, m) = builder();
    let mesh = b.add_mesh(triangle_mesh(m));
    let node = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    b.add_root(node);
    let clip = |name: &str, x: f32, end: f32| Animation {
        name: Some(name.into()),
        channels: vec![Channel {
            node,
            property: Property::Translation,
            interpolation: Interpolation::Linear,
            times: vec![0.0, end],
            values: vec![0.0, 0.0, 0.0, x, 0.0, 0.0],
        }],
    };
    b.add_animation(clip("first", 10.0, 1.0));
    b.add_animation(clip("second", -2.0, 4.0));
    let scene = built(b, "clips.gltf");
    assert_eq!(scene.duration(ClipSelection::All), 4.0);
    assert_eq!(scene.duration(ClipSelection::One(0)), 1.0);
    let x_at = |sel, t| {
        let split = scene.split(sel);
        let mut soup = TriangleSoup::new();
        scene.dynamic_triangles_at(&split, t, &mut soup);
        soup.positions[0][2].x // the vertex at the origin
    };
    assert_eq!(x_at(ClipSelection::All, 1.0), -0.5);
    assert_eq!(x_at(ClipSelection::One(0), 1.0), 10.0);
    assert_eq!(x_at(ClipSelection::One(1), 2.0), -1.0);
    assert_eq!(scene.resolve_clip("second").unwrap(), ClipSelection::One(1));
    assert_eq!(scene.resolve_clip("0").unwrap(), ClipSelection::One(0));
    let e = scene.resolve_clip("7").unwrap_err().to_string();
    assert!(e.contains("0: first") && e.contains("1: second"), "{e}");
}

/// The split rules, each on its own node.
#[test]
fn split_rules() {
    let (mut b, m) = builder();
    let tri = b.add_mesh(triangle_mesh(m));
    let morph = b.add_mesh(Mesh {
        primitives: vec![subfield::scene::Primitive {
            morph_targets: targets(vec![vec![Vec3::Z; 3]]),
            ..soup_prim(vec![Vec3::X, Vec3::Y, Vec3::ZERO], m)
        }],
        weights: vec![0.5],
        ..Default::default()
    });
    let still = b.add_node(Node {
        mesh: Some(tri),
        ..Default::default()
    });
    let constant = b.add_node(Node {
        mesh: Some(tri),
        ..Default::default()
    });
    let child = b.add_node(Node {
        mesh: Some(tri),
        ..Default::default()
    });
    let mover = b.add_node(Node {
        children: vec![child],
        ..Default::default()
    });
    let morphing = b.add_node(Node {
        mesh: Some(morph),
        ..Default::default()
    });
    let morph_still = b.add_node(Node {
        mesh: Some(morph),
        ..Default::default()
    });
    for n in [still, constant, mover, morphing, morph_still] {
        b.add_root(n);
    }
    let ch = |node, property, values: Vec<f32>| Channel {
        node,
        property,
        interpolation: Interpolation::Linear,
        times: vec![0.0, 1.0],
        values,
    };
    b.add_animation(Animation {
        name: None,
        channels: vec![
            ch(
                constant,
                Property::Translation,
                vec![1., 2., 3., 1., 2., 3.],
            ),
            ch(mover, Property::Scale, vec![1., 1., 1., 2., 2., 2.]),
            ch(morphing, Property::Weights, vec![0.0, 1.0]),
            ch(morph_still, Property::Weights, vec![0.25, 0.25]),
        ],
    });
    let scene = built(b, "split.glb");
    let split = scene.split(ClipSelection::All);
    let nodes = |v: &[subfield::scene::Instance]| v.iter().map(|i| i.node).collect::<Vec<_>>();
    assert_eq!(
        nodes(&split.static_instances),
        vec![still, constant, morph_still]
    );
    assert_eq!(nodes(&split.dynamic_instances), vec![child, morphing]);
    let s = split.summary();
    assert_eq!(
        (
            s.static_instances,
            s.dynamic_instances,
            s.static_triangles,
            s.dynamic_triangles
        ),
        (3, 2, 3, 2)
    );
    // Static geometry is the t = 0 pose: the constant channel's translation applies, the
    // constant weight 0.25 displaces the morph node by 0.25 along +Z.
    let stat = scene.static_triangles(&split);
    assert_eq!(stat.positions[1][2], Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(stat.positions[2][2], Vec3::new(0.0, 0.0, 0.25));
    // The morphing node at t = 0.5: weight 0.5 → +0.5 Z; the child at t = 0.5 scaled 1.5.
    let mut soup = TriangleSoup::new();
    scene.dynamic_triangles_at(&split, 0.5, &mut soup);
    assert_eq!(soup.positions[0][0], Vec3::new(1.5, 0.0, 0.0));
    assert_eq!(soup.positions[1][2], Vec3::new(0.0, 0.0, 0.5));
    // Reused without reallocating, same count each time.
    let cap = soup.positions.capacity();
    for t in [0.0, 0.3, 0.9] {
        scene.dynamic_triangles_at(&split, t, &mut soup);
        assert_eq!(soup.len(), 2);
        assert_eq!(soup.positions.capacity(), cap);
    }
}
