//! Bad input: one test per case, each a clear error naming the file and the accessor,
//! node or URI, never a panic; then a seeded fuzz loop over mutated files.

mod common;

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};

use common::build::{linear, perspective, placed, targets, SceneBuilder};
use glam::{Quat, Vec3};
use serde_json::{json, Value};
use subfield::import;
use subfield::import::ImportError;
use subfield::scene::{
    Animation, Channel, ClipSelection, Falloff, Interpolation, LightDef, LightKind, Material, Mesh,
    Node, Primitive, Property, Scene, TriangleSoup,
};

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir()
        .join(format!("subfield-errors-{}", std::process::id()))
        .join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A one-triangle glTF with an external `tri.bin`: 3 float positions (36 bytes) then
/// 3 u16 indices (6 bytes, padded to 8).
fn triangle_files(name: &str, positions: [f32; 9], indices: [u16; 3]) -> (PathBuf, Value) {
    let dir = temp_dir(name);
    let mut bin: Vec<u8> = positions.iter().flat_map(|f| f.to_le_bytes()).collect();
    bin.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    bin.extend([0, 0]);
    std::fs::write(dir.join("tri.bin"), &bin).unwrap();
    let gltf = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"uri": "tri.bin", "byteLength": 44}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
        ]
    });
    (dir.join("tri.gltf"), gltf)
}

const TRI: [f32; 9] = [0., 0., 0., 1., 0., 0., 0., 1., 0.];

fn load_json(path: &Path, json: &Value) -> Result<Scene, ImportError> {
    std::fs::write(path, serde_json::to_vec(json).unwrap()).unwrap();
    import::load(path)
}

fn assert_names(e: &ImportError, path: &Path, parts: &[&str]) {
    let msg = e.to_string();
    assert!(
        msg.contains(&path.display().to_string()),
        "no file in: {msg}"
    );
    for p in parts {
        assert!(msg.contains(p), "{p:?} missing from: {msg}");
    }
}

#[test]
fn the_base_file_is_fine() {
    let (path, json) = triangle_files("base", TRI, [0, 1, 2]);
    let scene = load_json(&path, &json).unwrap();
    assert_eq!(scene.meshes[0].primitives[0].triangles, vec![[0, 1, 2]]);
}

#[test]
fn truncated_glb() {
    let glb = import::to_glb(&sample_scene()).unwrap();
    let dir = temp_dir("truncated");
    let path = dir.join("cut.glb");
    for cut in [glb.len() - 1, glb.len() / 2, 30, 13, 5] {
        std::fs::write(&path, &glb[..cut]).unwrap();
        let e = import::load(&path).unwrap_err();
        assert!(matches!(e, ImportError::Glb { .. }), "cut {cut}: {e}");
        assert_names(&e, &path, &["GLB"]);
    }
}

#[test]
fn accessor_outside_its_buffer() {
    let (path, mut json) = triangle_files("accessor", TRI, [0, 1, 2]);
    json["accessors"][0]["count"] = json!(4);
    let e = load_json(&path, &json).unwrap_err();
    assert!(
        matches!(e, ImportError::Accessor { accessor: 0, .. }),
        "{e}"
    );
    assert_names(
        &e,
        &path,
        &["accessors[0]", "POSITION", "run past bufferViews[0]"],
    );

    // A buffer view past the end of its buffer.
    let (path, mut json) = triangle_files("view", TRI, [0, 1, 2]);
    json["bufferViews"][1]["byteOffset"] = json!(40);
    let e = load_json(&path, &json).unwrap_err();
    assert_names(
        &e,
        &path,
        &["accessors[1]", "indices", "outside buffers[0]"],
    );

    // A buffer file shorter than its byteLength.
    let (path, mut json) = triangle_files("short", TRI, [0, 1, 2]);
    json["buffers"][0]["byteLength"] = json!(400);
    let e = load_json(&path, &json).unwrap_err();
    assert_names(&e, &path, &["buffers[0]", "byteLength is 400"]);
}

#[test]
fn index_past_the_vertex_count() {
    let (path, json) = triangle_files("index", TRI, [0, 1, 7]);
    let e = load_json(&path, &json).unwrap_err();
    assert!(
        matches!(e, ImportError::Accessor { accessor: 1, .. }),
        "{e}"
    );
    assert_names(&e, &path, &["accessors[1]", "index 7", "vertex count 3"]);
}

#[test]
fn non_finite_positions() {
    for (name, bad) in [
        ("nan", f32::NAN),
        ("inf", f32::INFINITY),
        ("neginf", f32::NEG_INFINITY),
    ] {
        let mut p = TRI;
        p[4] = bad;
        let (path, json) = triangle_files(name, p, [0, 1, 2]);
        let e = load_json(&path, &json).unwrap_err();
        assert!(
            matches!(e, ImportError::Accessor { accessor: 0, .. }),
            "{e}"
        );
        assert_names(
            &e,
            &path,
            &[
                "accessors[0]",
                "POSITION",
                "element 1 component 1",
                "not finite",
            ],
        );
    }
}

#[test]
fn missing_buffer_file() {
    let (path, mut json) = triangle_files("missing", TRI, [0, 1, 2]);
    json["buffers"][0]["uri"] = json!("nowhere.bin");
    let e = load_json(&path, &json).unwrap_err();
    assert!(matches!(e, ImportError::MissingFile { .. }), "{e}");
    assert_names(&e, &path, &["buffers[0]", "nowhere.bin"]);
}

#[test]
fn uri_leaving_the_folder_is_refused() {
    // Put a real file one level up so a lax importer would succeed in reading it.
    let (path, json) = triangle_files("escape", TRI, [0, 1, 2]);
    let above = path.parent().unwrap().parent().unwrap().join("tri.bin");
    std::fs::copy(path.parent().unwrap().join("tri.bin"), &above).unwrap();
    for uri in [
        "../tri.bin",
        "sub/../../tri.bin",
        "%2E%2E/tri.bin",
        "/etc/passwd",
        "file:///etc/passwd",
        "http://example.com/tri.bin",
    ] {
        let mut j = json.clone();
        j["buffers"][0]["uri"] = json!(uri);
        let e = load_json(&path, &j).unwrap_err();
        assert!(
            matches!(e, ImportError::UriOutsideFolder { .. }),
            "{uri}: {e}"
        );
        assert_names(&e, &path, &["buffers[0]", uri, "leaves the scene's folder"]);
    }
    // Going down and back up inside the folder is fine.
    let mut j = json.clone();
    j["buffers"][0]["uri"] = json!("sub/../tri.bin");
    load_json(&path, &j).unwrap();
    // A symbolic link out of the folder is refused (the policy AFF includes share), one
    // to a file inside it followed.
    #[cfg(unix)]
    {
        let folder = path.parent().unwrap();
        std::os::unix::fs::symlink(&above, folder.join("out.bin")).unwrap();
        std::os::unix::fs::symlink(folder.join("tri.bin"), folder.join("in.bin")).unwrap();
        let mut j = json.clone();
        j["buffers"][0]["uri"] = json!("out.bin");
        let e = load_json(&path, &j).unwrap_err();
        assert!(matches!(e, ImportError::UriOutsideFolder { .. }), "{e}");
        assert_names(
            &e,
            &path,
            &["buffers[0]", "out.bin", "leaves the scene's folder"],
        );
        j["buffers"][0]["uri"] = json!("in.bin");
        load_json(&path, &j).unwrap();
    }
}

#[test]
fn skin_with_a_missing_joint() {
    // A joint index naming no node: the gltf validation names skins[0].joints[1].
    let (path, mut json) = triangle_files("joint-node", TRI, [0, 1, 2]);
    json["nodes"][0]["skin"] = json!(0);
    json["skins"] = json!([{"joints": [0, 9]}]);
    let e = load_json(&path, &json).unwrap_err();
    assert!(matches!(e, ImportError::Invalid { .. }), "{e}");
    assert_names(&e, &path, &["skins[0].joints[1]"]);

    // JOINTS_0 using a joint number the skin does not have: names the node.
    let (path, mut json) = triangle_files("joint-number", TRI, [0, 1, 2]);
    let dir = path.parent().unwrap();
    let mut bin = std::fs::read(dir.join("tri.bin")).unwrap();
    let joints_at = bin.len();
    for v in 0..3u8 {
        bin.extend([if v == 2 { 3 } else { 0 }, 0, 0, 0]); // u8 joints, vertex 2 → joint 3
    }
    let weights_at = bin.len();
    for _ in 0..3 {
        bin.extend(1f32.to_le_bytes());
        bin.extend([0u8; 12]);
    }
    std::fs::write(dir.join("tri.bin"), &bin).unwrap();
    json["buffers"][0]["byteLength"] = json!(bin.len());
    json["bufferViews"].as_array_mut().unwrap().extend([
        json!({"buffer": 0, "byteOffset": joints_at, "byteLength": 12}),
        json!({"buffer": 0, "byteOffset": weights_at, "byteLength": 48}),
    ]);
    json["accessors"].as_array_mut().unwrap().extend([
        json!({"bufferView": 2, "componentType": 5121, "count": 3, "type": "VEC4"}),
        json!({"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC4"}),
    ]);
    let attrs = &mut json["meshes"][0]["primitives"][0]["attributes"];
    attrs["JOINTS_0"] = json!(2);
    attrs["WEIGHTS_0"] = json!(3);
    json["nodes"] = json!([{"mesh": 0, "skin": 0}, {}]);
    json["scenes"] = json!([{"nodes": [0, 1]}]);
    json["skins"] = json!([{"joints": [1]}]);
    let e = load_json(&path, &json).unwrap_err();
    assert!(matches!(e, ImportError::Node { node: 0, .. }), "{e}");
    assert_names(&e, &path, &["nodes[0]", "joint 3", "skins[0] has 1 joints"]);
}

#[test]
fn broken_hierarchies() {
    let (path, mut json) = triangle_files("cycle", TRI, [0, 1, 2]);
    json["nodes"] = json!([{"mesh": 0, "children": [1]}, {"children": [0], "name": "loop"}]);
    let e = load_json(&path, &json).unwrap_err();
    assert!(matches!(e, ImportError::Node { .. }), "{e}");
    assert_names(&e, &path, &["nodes["]);

    let (path, mut json) = triangle_files("two-parents", TRI, [0, 1, 2]);
    json["nodes"] = json!([{"children": [2]}, {"children": [2]}, {"mesh": 0}]);
    json["scenes"] = json!([{"nodes": [0, 1]}]);
    let e = load_json(&path, &json).unwrap_err();
    assert_names(&e, &path, &["nodes[2]", "child of both node 0 and node 1"]);
}

#[test]
fn bad_json_and_unsupported_extensions() {
    let dir = temp_dir("json");
    let path = dir.join("x.gltf");
    std::fs::write(&path, b"{ not json").unwrap();
    assert!(matches!(
        import::load(&path).unwrap_err(),
        ImportError::Json { .. }
    ));
    let (path, mut json) = triangle_files("draco", TRI, [0, 1, 2]);
    json["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    json["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    let e = load_json(&path, &json).unwrap_err();
    assert_names(&e, &path, &["KHR_draco_mesh_compression"]);
    let e = import::load(&dir.join("absent.glb")).unwrap_err();
    assert!(matches!(e, ImportError::Io { .. }), "{e}");
}

/// A scene using most of what the writer can express.
fn sample_scene() -> Scene {
    let mut b = SceneBuilder::new();
    let mat = b.add_material(Material {
        emissive: Vec3::new(2.0, 1.0, 0.0),
        transmission: 0.5,
        ior: 1.33,
        metallic: 0.0,
        ..Material::default()
    });
    let mesh = b.add_mesh(Mesh {
        name: Some("quad".into()),
        primitives: vec![Primitive {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            normals: Some(vec![Vec3::Z; 4]),
            uvs: Some(vec![glam::Vec2::ZERO; 4]),
            triangles: vec![[0, 1, 2], [2, 1, 3]],
            material: mat,
            morph_targets: targets(vec![vec![Vec3::Z; 4]]),
            ..Default::default()
        }],
        weights: vec![0.0],
    });
    let cam = b.add_camera(perspective("cam", 0.8, None, 0.1, None));
    let light = b.add_light(LightDef {
        name: None,
        kind: LightKind::Spot {
            inner_cone_angle: 0.1,
            outer_cone_angle: 0.5,
        },
        color: Vec3::ONE,
        intensity: 10.0,
        range: Some(5.0),
        falloff: Falloff::InverseSquare,
    });
    let child = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    let root = b.add_node(Node {
        children: vec![child],
        transform: placed(Vec3::ZERO, Quat::from_rotation_y(0.3)),
        ..Default::default()
    });
    let c = b.add_node(Node {
        camera: Some(cam),
        light: Some(light),
        ..Default::default()
    });
    b.add_root(root);
    b.add_root(c);
    b.add_animation(Animation {
        name: Some("a".into()),
        channels: vec![
            linear(
                root,
                Property::Rotation,
                vec![0.0, 1.0],
                vec![0., 0., 0., 1., 0., 1., 0., 0.],
            ),
            Channel {
                node: child,
                property: Property::Weights,
                interpolation: Interpolation::CubicSpline,
                times: vec![0.0, 1.0],
                values: vec![0., 0., 1., 0., 1., 0.],
            },
        ],
    });
    b.scene.fps = Some(30.0);
    b.finish()
}

/// Tiny deterministic generator (xorshift64*), so a failure names its seed.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn mutate(rng: &mut Rng, input: &[u8]) -> Vec<u8> {
    let mut b = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        if b.is_empty() {
            break;
        }
        let at = rng.below(b.len());
        match rng.below(6) {
            0 => b[at] ^= 1 << rng.below(8),
            1 => b[at] = rng.next() as u8,
            2 => b.truncate(at),
            3 => {
                // A little-endian u32 of an interesting size (offsets, counts, lengths).
                let v: u32 = [0, 1, 3, 255, 65535, 1 << 24, u32::MAX][rng.below(7)];
                for (k, byte) in v.to_le_bytes().iter().enumerate() {
                    if let Some(x) = b.get_mut(at + k) {
                        *x = *byte;
                    }
                }
            }
            4 => {
                // A digit changed: in JSON this alters indices, counts, offsets.
                if let Some(p) = b[at..].iter().position(|c| c.is_ascii_digit()) {
                    b[at + p] = b'0' + rng.below(10) as u8;
                }
            }
            _ => {
                let n = rng.below(8);
                b.drain(at..(at + n).min(b.len()));
            }
        }
    }
    b
}

/// Replaces a few numbers of the JSON (in a `.gltf` or inside a GLB's JSON chunk) with
/// awkward values: the file stays valid JSON, so the importer's own checks are reached.
fn mutate_json(rng: &mut Rng, input: &[u8]) -> Option<Vec<u8>> {
    let glb = input.starts_with(b"glTF");
    let (json_bytes, rest) = if glb {
        let jl = u32::from_le_bytes(input.get(12..16)?.try_into().ok()?) as usize;
        (input.get(20..20 + jl)?, input.get(20 + jl..)?)
    } else {
        (input, &[][..])
    };
    let mut v: Value = serde_json::from_slice(json_bytes).ok()?;
    /// Every number in `v`, in document order.
    fn numbers(v: &mut Value) -> Vec<&mut Value> {
        if v.is_number() {
            return vec![v];
        }
        match v {
            Value::Array(a) => a.iter_mut().flat_map(numbers).collect(),
            Value::Object(o) => o.values_mut().flat_map(numbers).collect(),
            _ => Vec::new(),
        }
    }
    for _ in 0..1 + rng.below(3) {
        let mut slots = numbers(&mut v);
        if slots.is_empty() {
            return None;
        }
        let pick = slots.swap_remove(rng.below(slots.len()));
        let awkward = [
            json!(0),
            json!(1),
            json!(-1),
            json!(2),
            json!(3),
            json!(255),
            json!(65536),
            json!(1e9),
            json!(4294967295u64),
            json!(1.5),
            json!(1e39),
        ];
        *pick = awkward[rng.below(awkward.len())].clone();
    }
    let mut out_json = serde_json::to_vec(&v).ok()?;
    if !glb {
        return Some(out_json);
    }
    while out_json.len() % 4 != 0 {
        out_json.push(b' ');
    }
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((20 + out_json.len() + rest.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(out_json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&out_json);
    out.extend_from_slice(rest);
    Some(out)
}

/// Import (and, when it succeeds, split and extract at a few times) must never panic.
#[test]
fn fuzz_mutated_files_never_panic() {
    let dir = temp_dir("fuzz");
    let b = sample_scene();
    let mut corpus: Vec<(String, Vec<u8>)> = vec![
        ("built.glb".into(), import::to_glb(&b).unwrap()),
        (
            "built.gltf".into(),
            import::to_gltf_json(&b).unwrap().into_bytes(),
        ),
    ];
    if let Some(shared) = common::shared_gltf() {
        for rel in [
            "SimpleSkin/SimpleSkin.gltf",
            "RiggedFigure/RiggedFigure.glb",
            "AnimatedMorphCube/AnimatedMorphCube.gltf",
        ] {
            let p = shared.join(rel);
            let bytes = std::fs::read(&p).unwrap();
            let folder = p.parent().unwrap().to_path_buf();
            // Shared files keep their folder (external .bin), so the name carries it.
            corpus.push((
                folder.join(p.file_name().unwrap()).display().to_string(),
                bytes,
            ));
        }
    }
    for (name, bytes) in &corpus {
        let path = Path::new(name);
        let folder = path
            .parent()
            .filter(|p| p.is_dir())
            .unwrap_or(&dir)
            .to_path_buf();
        import::from_gltf_slice(bytes, path, &folder)
            .unwrap_or_else(|e| panic!("unmutated {name}: {e}"));
    }
    let (mut ok, mut err) = (0, 0);
    // 600 by default (well under a second); SUBFIELD_FUZZ_ITERS=N runs a longer campaign.
    let iters: u64 = std::env::var("SUBFIELD_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(600);
    for seed in 1..=iters {
        let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
        let (name, original) = &corpus[rng.below(corpus.len())];
        let bytes = if seed % 2 == 0 {
            mutate_json(&mut rng, original).unwrap_or_else(|| mutate(&mut rng, original))
        } else {
            mutate(&mut rng, original)
        };
        let path = Path::new(name);
        let folder = path
            .parent()
            .filter(|p| p.is_dir())
            .unwrap_or(&dir)
            .to_path_buf();
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| {
            match import::from_gltf_slice(&bytes, path, &folder) {
                Ok(scene) => {
                    let split = scene.split(ClipSelection::All);
                    let _ = scene.static_triangles(&split);
                    let mut soup = TriangleSoup::new();
                    for t in [0.0, 0.4, 10.0] {
                        scene.dynamic_triangles_at(&split, t, &mut soup);
                    }
                    let _ = scene.camera_at(ClipSelection::All, 0.5, None);
                    let _ = scene.lights_at(ClipSelection::All, 0.5);
                    true
                }
                Err(e) => {
                    // Every error names the input.
                    let m = e.to_string();
                    assert!(
                        m.contains(name.as_str()),
                        "seed {seed}: error without file: {m}"
                    );
                    false
                }
            }
        }));
        match outcome {
            Ok(true) => ok += 1,
            Ok(false) => err += 1,
            Err(_) => panic!("seed {seed} ({name}) panicked"),
        }
    }
    eprintln!("fuzz: {ok} mutated files imported, {err} refused with an error");
    assert!(err > 0);
}
