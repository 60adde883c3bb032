//! The writer: a `Scene` built in code with everything the model holds (meshes with
//! normals, UVs, skin influences and morph targets, materials with textures, images,
//! samplers, nodes by TRS and by matrix, a skin, perspective and orthographic cameras,
//! lights, clips, fps, extras), written as `.glb` and `.gltf`, validated by the Khronos
//! validator, loaded back and compared with what was written.

mod common;

use common::build::{diffuse, linear, placed, tris, SceneBuilder};
use glam::{Mat4, Quat, Vec2, Vec3, Vec4};
use serde_json::{json, Value};
use subfield::import::{self, ImportError};
use subfield::scene::{
    AlphaMode, Animation, Channel, ClipSelection, Falloff, Image, Interpolation, LightDef,
    LightKind, Material, Mesh, MorphTarget, Node, NodeTransform, Primitive, Projection, Property,
    Scene, Skin, Texture, TextureRef, Wrap,
};

fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir()
        .join(format!("subfield-write-{}", std::process::id()))
        .join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn scene() -> Scene {
    let mut b = SceneBuilder::new();
    // A 2 × 2 image with one translucent pixel (written as RGBA) and an opaque one (RGB).
    let see_through = b.add_image(Image {
        name: Some("checker".into()),
        width: 2,
        height: 2,
        rgba8: vec![
            255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 128, 255, 255, 255, 255,
        ],
    });
    let opaque = b.add_image(Image {
        name: None,
        width: 1,
        height: 2,
        rgba8: vec![10, 20, 30, 255, 40, 50, 60, 255],
    });
    let checker = b.add_texture(Texture {
        image: see_through,
        wrap_s: Wrap::ClampToEdge,
        wrap_t: Wrap::MirroredRepeat,
        nearest: true,
    });
    let plain = b.add_texture(Texture {
        image: opaque,
        wrap_s: Wrap::Repeat,
        wrap_t: Wrap::Repeat,
        nearest: false,
    });
    let at = |texture| {
        Some(TextureRef {
            texture,
            tex_coord: 0,
            transform: None,
        })
    };
    // A KHR_texture_transform, written as the extension and read back.
    let moved = |texture| {
        Some(TextureRef {
            texture,
            tex_coord: 0,
            transform: Some(subfield::scene::UvTransform {
                offset: glam::Vec2::new(0.25, 0.5),
                rotation: 0.5,
                scale: glam::Vec2::new(2.0, 2.0),
            }),
        })
    };
    let glass = b.add_material(Material {
        transmission: 1.0,
        ior: 1.45,
        double_sided: true,
        base_color_texture: at(checker),
        ..diffuse("glass", Vec4::new(0.9, 0.95, 1.0, 1.0), 0.05)
    });
    let lamp = b.add_material(Material {
        emissive: Vec3::new(8.0, 4.0, 2.0),
        emissive_texture: moved(plain),
        metallic_roughness_texture: at(plain),
        alpha_mode: AlphaMode::Mask { cutoff: 0.3 },
        ..diffuse("lamp", Vec4::ONE, 1.0)
    });
    let skinned = b.add_material(Material {
        alpha_mode: AlphaMode::Blend,
        ..Material::default()
    });
    let quad = b.add_mesh(Mesh {
        name: Some("quad".into()),
        primitives: vec![
            Primitive {
                positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)],
                normals: Some(vec![Vec3::Z; 4]),
                uvs: Some(vec![Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE]),
                triangles: tris(&[0, 1, 2, 2, 1, 3]),
                material: glass,
                morph_targets: vec![
                    MorphTarget {
                        positions: vec![Vec3::Z; 4],
                        normals: vec![Vec3::X * 0.1; 4],
                    },
                    MorphTarget {
                        positions: vec![Vec3::X * 0.5; 4],
                        normals: vec![Vec3::ZERO; 4],
                    },
                ],
                ..Primitive::default()
            },
            // Triangles in vertex order: written without indices.
            Primitive {
                positions: vec![Vec3::ZERO, Vec3::Z, Vec3::Y],
                uvs: Some(vec![Vec2::ZERO, Vec2::X, Vec2::Y]),
                triangles: vec![[0, 1, 2]],
                material: lamp,
                morph_targets: vec![MorphTarget::default(), MorphTarget::default()],
                ..Primitive::default()
            },
        ],
        weights: vec![0.25, 0.0],
    });
    let plain_mesh = b.add_mesh(Mesh {
        name: None,
        primitives: vec![Primitive {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Z],
            triangles: vec![[0, 2, 1]],
            material: skinned,
            ..Primitive::default()
        }],
        weights: Vec::new(),
    });
    // Two influence sets per vertex.
    let arm = b.add_mesh(Mesh {
        name: Some("arm".into()),
        primitives: vec![Primitive {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 2.0, 0.0)],
            triangles: vec![[0, 1, 2]],
            material: skinned,
            // Vertex v: entries 2v (JOINTS_0 / WEIGHTS_0) and 2v + 1 (JOINTS_1 / WEIGHTS_1).
            joints: vec![
                [0, 1, 0, 0],
                [0, 0, 0, 0],
                [1, 0, 0, 0],
                [0, 0, 0, 0],
                [0, 0, 0, 0],
                [1, 0, 0, 0],
            ],
            weights: vec![
                [0.5, 0.5, 0.0, 0.0],
                [0.0, 0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 0.0, 0.0, 0.0],
                [0.75, 0.0, 0.0, 0.0],
                [0.25, 0.0, 0.0, 0.0],
            ],
            ..Primitive::default()
        }],
        weights: Vec::new(),
    });
    let cam = b.add_camera(common::build::perspective(
        "main",
        0.9,
        Some(1.5),
        0.05,
        Some(200.0),
    ));
    b.scene.cameras.push(subfield::scene::CameraDef {
        name: Some("plan".into()),
        projection: Projection::Orthographic {
            xmag: 3.0,
            ymag: 2.0,
            znear: 0.5,
            zfar: 50.0,
        },
    });
    let sun = b.add_light(LightDef {
        name: Some("sun".into()),
        kind: LightKind::Directional,
        color: Vec3::new(1.0, 0.9, 0.8),
        intensity: 3.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let spot = b.add_light(LightDef {
        name: Some("spot".into()),
        kind: LightKind::Spot {
            inner_cone_angle: 0.2,
            outer_cone_angle: 0.6,
        },
        color: Vec3::ONE,
        intensity: 500.0,
        range: Some(20.0),
        falloff: Falloff::InverseSquare,
    });
    let child = b.add_node(Node {
        name: Some("child".into()),
        mesh: Some(plain_mesh),
        transform: placed(Vec3::new(0.0, 2.0, 0.0), Quat::IDENTITY),
        ..Default::default()
    });
    let root = b.add_node(Node {
        name: Some("root".into()),
        mesh: Some(quad),
        children: vec![child],
        transform: common::build::trs(Vec3::ZERO, Quat::IDENTITY, Vec3::splat(2.0)),
        weights: Some(vec![0.5, 0.5]),
        ..Default::default()
    });
    let camera = b.add_node(Node {
        camera: Some(cam),
        transform: placed(Vec3::new(0.0, 1.0, 5.0), Quat::IDENTITY),
        ..Default::default()
    });
    let plan = b.add_node(Node {
        camera: Some(1),
        // Given as a matrix, kept as a matrix.
        transform: NodeTransform::Matrix(Mat4::from_rotation_translation(
            Quat::from_rotation_z(0.3),
            Vec3::new(1.0, 2.0, 3.0),
        )),
        ..Default::default()
    });
    let lights = b.add_node(Node {
        light: Some(sun),
        ..Default::default()
    });
    let spot_node = b.add_node(Node {
        light: Some(spot),
        transform: placed(
            Vec3::new(0.0, 4.0, 0.0),
            Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
        ),
        ..Default::default()
    });
    let bone = b.add_node(Node {
        name: Some("bone".into()),
        transform: placed(Vec3::Y, Quat::IDENTITY),
        ..Default::default()
    });
    let arm_node = b.add_node(Node {
        name: Some("arm".into()),
        mesh: Some(arm),
        skin: Some(0),
        children: vec![bone],
        ..Default::default()
    });
    b.scene.skins.push(Skin {
        name: Some("arm skin".into()),
        joints: vec![arm_node, bone],
        inverse_bind_matrices: vec![Mat4::IDENTITY, Mat4::from_translation(Vec3::NEG_Y)],
    });
    for n in [root, camera, plan, lights, spot_node, arm_node] {
        b.add_root(n);
    }
    b.add_animation(Animation {
        name: Some("move".into()),
        channels: vec![
            Channel {
                node: root,
                property: Property::Translation,
                interpolation: Interpolation::Step,
                times: vec![0.0, 1.0, 2.0],
                values: vec![0., 0., 0., 1., 0., 0., 2., 0., 0.],
            },
            linear(
                camera,
                Property::Rotation,
                vec![0.0, 2.0],
                [
                    Quat::IDENTITY.to_array(),
                    Quat::from_rotation_y(1.0).to_array(),
                ]
                .concat(),
            ),
        ],
    });
    b.add_animation(Animation {
        name: Some("morph".into()),
        channels: vec![Channel {
            node: root,
            property: Property::Weights,
            interpolation: Interpolation::CubicSpline,
            times: vec![0.0, 3.0],
            values: vec![0., 0., 0., 0., 0., 0., 0., 0., 1., 1., 0., 0.],
        }],
    });
    b.scene.fps = Some(25.0);
    b.scene
        .extras
        .scene
        .insert("note".into(), json!({ "made": "in code" }));
    b.scene.extras.materials = vec![None, Some(json!({ "aff": { "shine": 3.0 } }))];
    b.finish()
}

/// Everything the reader gives back is what was written (rotations: the reader
/// normalises them; emission: the factor stays in [0, 1], the strength carries the rest).
fn check_round_trip(back: &Scene, s: &Scene) {
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    assert_eq!(back.fps, s.fps);
    assert_eq!(back.meshes.len(), s.meshes.len());
    for (m, d) in back.meshes.iter().zip(&s.meshes) {
        assert_eq!((&m.name, &m.weights), (&d.name, &d.weights));
        assert_eq!(m.primitives.len(), d.primitives.len());
        for (p, pd) in m.primitives.iter().zip(&d.primitives) {
            assert_eq!(p.positions, pd.positions);
            assert_eq!(p.normals, pd.normals);
            assert_eq!(p.uvs, pd.uvs);
            assert_eq!(p.triangles, pd.triangles);
            assert_eq!(p.material, pd.material);
            assert_eq!((&p.joints, &p.weights), (&pd.joints, &pd.weights));
            assert_eq!(p.morph_targets.len(), pd.morph_targets.len());
            for (t, td) in p.morph_targets.iter().zip(&pd.morph_targets) {
                // No displacement is written as zeros.
                if td.positions.is_empty() {
                    assert!(t.positions.iter().all(|v| *v == Vec3::ZERO));
                } else {
                    assert_eq!(t.positions, td.positions);
                }
                assert_eq!(t.normals, td.normals);
            }
        }
    }
    assert_eq!(back.materials.len(), s.materials.len());
    for (m, d) in back.materials.iter().zip(&s.materials) {
        assert!(
            (m.emissive * m.emissive_strength).abs_diff_eq(d.emissive * d.emissive_strength, 1e-6)
        );
        assert!(m.emissive.max_element() <= 1.0);
        let same = Material {
            emissive: d.emissive,
            emissive_strength: d.emissive_strength,
            ..m.clone()
        };
        assert_eq!(&same, d);
    }
    assert_eq!(back.textures, s.textures);
    assert_eq!(back.images, s.images);
    assert_eq!(back.nodes.len(), s.nodes.len());
    for (n, d) in back.nodes.iter().zip(&s.nodes) {
        assert_eq!(
            (
                &n.name,
                n.parent,
                &n.children,
                n.mesh,
                n.skin,
                n.camera,
                n.light,
                &n.weights
            ),
            (
                &d.name,
                d.parent,
                &d.children,
                d.mesh,
                d.skin,
                d.camera,
                d.light,
                &d.weights
            )
        );
        match (n.transform, d.transform) {
            (NodeTransform::Trs(t), NodeTransform::Trs(u)) => {
                assert_eq!((t.translation, t.scale), (u.translation, u.scale));
                assert!(t.rotation.abs_diff_eq(u.rotation, 1e-7));
            }
            (NodeTransform::Matrix(a), NodeTransform::Matrix(b)) => assert_eq!(a, b),
            other => panic!("transform kind changed: {other:?}"),
        }
    }
    assert_eq!(back.roots, s.roots);
    assert_eq!(back.cameras, s.cameras);
    assert_eq!(back.lights, s.lights);
    assert_eq!(back.skins.len(), s.skins.len());
    for (k, d) in back.skins.iter().zip(&s.skins) {
        assert_eq!(
            (&k.name, &k.joints, &k.inverse_bind_matrices),
            (&d.name, &d.joints, &d.inverse_bind_matrices)
        );
    }
    assert_eq!(back.animations, s.animations);
}

/// The written JSON (of a `.gltf`), for what the reader does not keep: extras.
fn json_of(path: &std::path::Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn glb_round_trip() {
    let s = scene();
    let path = temp_dir("glb").join("scene.glb");
    import::write_gltf(&s, &path).unwrap();
    let (errors, warnings, report) = common::khronos_validate(&path);
    assert_eq!((errors, warnings), (0, 0), "{report}");
    let back = import::load(&path).unwrap();
    check_round_trip(&back, &s);
    // The posed scene behaves: the spot light points down, the camera starts at (0,1,5).
    let lights = back.lights_at(ClipSelection::All, 0.0);
    let spot = lights
        .iter()
        .find(|l| l.name.as_deref() == Some("spot"))
        .unwrap();
    assert!(
        spot.direction.abs_diff_eq(Vec3::NEG_Y, 1e-6),
        "{}",
        spot.direction
    );
    let cam = back
        .camera_at(ClipSelection::All, 0.0, Some("main"))
        .unwrap();
    assert_eq!(cam.position, Vec3::new(0.0, 1.0, 5.0));
    let (lo, hi) = back.bounds_at(ClipSelection::All, 0.0).unwrap();
    assert!(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all());
    // Written twice, the same bytes.
    assert_eq!(import::to_glb(&s).unwrap(), std::fs::read(&path).unwrap());
}

#[test]
fn gltf_round_trip_with_embedded_buffer_and_extras() {
    let s = scene();
    let path = temp_dir("gltf").join("scene.gltf");
    import::write_gltf(&s, &path).unwrap();
    let (errors, warnings, report) = common::khronos_validate(&path);
    assert_eq!((errors, warnings), (0, 0), "{report}");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("data:application/octet-stream;base64,"));
    check_round_trip(&import::load(&path).unwrap(), &s);
    let doc = json_of(&path);
    assert_eq!(
        doc["scenes"][0]["extras"]["note"],
        json!({ "made": "in code" })
    );
    assert_eq!(doc["scenes"][0]["extras"]["fps"], json!(25.0));
    assert!(doc["materials"][0].get("extras").is_none());
    assert_eq!(doc["materials"][1]["extras"]["aff"]["shine"], json!(3.0));
    // One sampler, for the texture that is not the default.
    assert_eq!(doc["samplers"].as_array().unwrap().len(), 1);
    assert!(doc["textures"][1].get("sampler").is_none());
    // The primitive whose triangles are its vertices in order has no indices.
    assert!(doc["meshes"][0]["primitives"][0].get("indices").is_some());
    assert!(doc["meshes"][0]["primitives"][1].get("indices").is_none());
}

#[test]
fn writes_atomically() {
    let dir = temp_dir("atomic");
    let path = dir.join("out.glb");
    std::fs::write(&path, b"old").unwrap();
    import::write_gltf(&scene(), &path).unwrap();
    assert!(std::fs::read(&path).unwrap().starts_with(b"glTF"));
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name() != "out.glb")
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    let missing = dir.join("no/such/folder/out.glb");
    let e = import::write_gltf(&scene(), &missing).unwrap_err();
    assert!(matches!(e, ImportError::WriteIo { .. }));
    assert!(e.to_string().contains("no/such/folder/out.glb"), "{e}");
}

#[test]
fn refuses_what_it_cannot_write() {
    let refused = |s: &Scene, want: &str| {
        let e = import::to_glb(s).unwrap_err();
        assert!(matches!(e, ImportError::Write { .. }), "{e:?}");
        assert!(e.to_string().contains(want), "{e}");
    };
    let mut s = scene();
    s.meshes[0].primitives[0].triangles[0] = [0, 1, 4];
    refused(&s, "vertex index 4 past the vertex count 4");
    let mut s = scene();
    s.extras.materials[1] = Some(json!([1, 2]));
    refused(&s, "extras must be a JSON object");
    let mut s = scene();
    s.meshes[1].primitives[0].triangles.clear();
    refused(&s, "no vertices or no triangles");
    let mut s = scene();
    s.nodes[0].children.push(2);
    refused(&s, "nodes[");
    let mut s = scene();
    s.fps = Some(-1.0);
    refused(&s, "fps");
}
