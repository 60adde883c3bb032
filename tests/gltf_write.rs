//! The writer: build a scene in code, write `.glb` and `.gltf`, load it back, compare.

use glam::{Quat, Vec2, Vec3, Vec4};
use subfield::import;
use subfield::import::{
    AnimationDesc, CameraDesc, ChannelDesc, GltfBuilder, ImportError, MaterialDesc, MeshDesc,
    NodeDesc, PrimitiveDesc,
};
use subfield::scene::{
    ClipSelection, Interpolation, LightDef, LightKind, NodeTransform, Projection, Property, Scene,
};

fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir()
        .join(format!("subfield-write-{}", std::process::id()))
        .join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn builder() -> GltfBuilder {
    let mut b = GltfBuilder::new();
    let glass = b.add_material(MaterialDesc {
        name: Some("glass".into()),
        base_color: Vec4::new(0.9, 0.95, 1.0, 1.0),
        metallic: 0.0,
        roughness: 0.05,
        emissive: Vec3::ZERO,
        transmission: 1.0,
        ior: 1.45,
        double_sided: true,
        ..Default::default()
    });
    let lamp = b.add_material(MaterialDesc {
        name: Some("lamp".into()),
        emissive: Vec3::new(8.0, 4.0, 2.0),
        ..Default::default()
    });
    let quad = b.add_mesh(MeshDesc {
        name: Some("quad".into()),
        primitives: vec![
            PrimitiveDesc {
                positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)],
                normals: Some(vec![Vec3::Z; 4]),
                uvs: Some(vec![Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE]),
                indices: Some(vec![0, 1, 2, 2, 1, 3]),
                material: Some(glass),
                morph_targets: vec![vec![Vec3::Z; 4], vec![Vec3::X * 0.5; 4]],
                ..Default::default()
            },
            PrimitiveDesc {
                positions: vec![Vec3::ZERO, Vec3::Z, Vec3::Y],
                material: Some(lamp),
                morph_targets: vec![vec![Vec3::ZERO; 3], vec![Vec3::ZERO; 3]],
                ..Default::default()
            },
        ],
        weights: vec![0.25, 0.0],
    });
    let plain = b.add_mesh(MeshDesc {
        primitives: vec![PrimitiveDesc {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Z],
            ..Default::default()
        }],
        ..Default::default()
    });
    let cam = b.add_camera(CameraDesc {
        name: Some("main".into()),
        yfov: 0.9,
        aspect: Some(1.5),
        znear: 0.05,
        zfar: Some(200.0),
    });
    let sun = b.add_light(LightDef {
        name: Some("sun".into()),
        kind: LightKind::Directional,
        color: Vec3::new(1.0, 0.9, 0.8),
        intensity: 3.0,
        range: None,
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
    });
    let child = b.add_node(NodeDesc {
        name: Some("child".into()),
        mesh: Some(plain),
        translation: Vec3::new(0.0, 2.0, 0.0),
        ..Default::default()
    });
    let root = b.add_node(NodeDesc {
        name: Some("root".into()),
        mesh: Some(quad),
        children: vec![child],
        rotation: Quat::from_rotation_x(0.5),
        scale: Vec3::new(2.0, 2.0, 2.0),
        weights: Some(vec![0.5, 0.5]),
        ..Default::default()
    });
    let camera = b.add_node(NodeDesc {
        camera: Some(cam),
        translation: Vec3::new(0.0, 1.0, 5.0),
        ..Default::default()
    });
    let lights = b.add_node(NodeDesc {
        light: Some(sun),
        children: vec![],
        ..Default::default()
    });
    let spot_node = b.add_node(NodeDesc {
        light: Some(spot),
        translation: Vec3::new(0.0, 4.0, 0.0),
        rotation: Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
        ..Default::default()
    });
    for n in [root, camera, lights, spot_node] {
        b.add_root(n);
    }
    b.add_animation(AnimationDesc {
        name: Some("move".into()),
        channels: vec![
            ChannelDesc {
                node: root,
                property: Property::Translation,
                interpolation: Interpolation::Step,
                times: vec![0.0, 1.0, 2.0],
                values: vec![0., 0., 0., 1., 0., 0., 2., 0., 0.],
            },
            ChannelDesc {
                node: camera,
                property: Property::Rotation,
                interpolation: Interpolation::Linear,
                times: vec![0.0, 2.0],
                values: [
                    Quat::IDENTITY.to_array(),
                    Quat::from_rotation_y(1.0).to_array(),
                ]
                .concat(),
            },
        ],
    });
    b.add_animation(AnimationDesc {
        name: Some("morph".into()),
        channels: vec![ChannelDesc {
            node: root,
            property: Property::Weights,
            interpolation: Interpolation::CubicSpline,
            times: vec![0.0, 3.0],
            values: vec![0., 0., 0., 0., 0., 0., 0., 0., 1., 1., 0., 0.],
        }],
    });
    b.fps = Some(25.0);
    b
}

fn check_round_trip(scene: &Scene, b: &GltfBuilder) {
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(scene.fps, Some(25.0));
    assert_eq!(scene.meshes.len(), b.meshes.len());
    for (m, d) in scene.meshes.iter().zip(&b.meshes) {
        assert_eq!(m.name, d.name);
        assert_eq!(m.weights, d.weights);
        for (p, pd) in m.primitives.iter().zip(&d.primitives) {
            assert_eq!(p.positions, pd.positions);
            assert_eq!(p.normals, pd.normals);
            assert_eq!(p.uvs, pd.uvs);
            let want: Vec<[u32; 3]> = match &pd.indices {
                Some(i) => i.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
                None => (0..pd.positions.len() as u32 / 3)
                    .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                    .collect(),
            };
            assert_eq!(p.triangles, want);
            let targets: Vec<Vec<Vec3>> = p
                .morph_targets
                .iter()
                .map(|t| t.positions.clone())
                .collect();
            assert_eq!(targets, pd.morph_targets);
            match pd.material {
                Some(i) => {
                    let (m, md) = (
                        &scene.materials[p.material as usize],
                        &b.materials[i as usize],
                    );
                    assert_eq!(m.name, md.name);
                    assert_eq!(m.base_color, md.base_color);
                    assert_eq!((m.metallic, m.roughness), (md.metallic, md.roughness));
                    assert!((m.emissive * m.emissive_strength).abs_diff_eq(md.emissive, 1e-6));
                    assert!(m.emissive.max_element() <= 1.0);
                    assert_eq!(
                        (m.transmission, m.ior, m.double_sided),
                        (md.transmission, md.ior, md.double_sided)
                    );
                }
                None => assert_eq!(scene.materials[p.material as usize].base_color, Vec4::ONE),
            }
        }
    }
    for (n, d) in scene.nodes.iter().zip(&b.nodes) {
        assert_eq!(n.name, d.name);
        let NodeTransform::Trs(t) = n.transform else {
            panic!("TRS expected")
        };
        assert_eq!((t.translation, t.scale), (d.translation, d.scale));
        assert!(t.rotation.abs_diff_eq(d.rotation, 1e-7));
        let children: Vec<usize> = d.children.iter().map(|&c| c as usize).collect();
        assert_eq!(n.children, children);
        assert_eq!(n.mesh, d.mesh.map(|x| x as usize));
        assert_eq!(n.camera, d.camera.map(|x| x as usize));
        assert_eq!(n.light, d.light.map(|x| x as usize));
        assert_eq!(n.weights, d.weights);
    }
    assert_eq!(
        scene.roots,
        b.roots.iter().map(|&r| r as usize).collect::<Vec<_>>()
    );
    assert_eq!(
        scene.cameras[0].projection,
        Projection::Perspective {
            yfov: 0.9,
            aspect: Some(1.5),
            znear: 0.05,
            zfar: Some(200.0)
        }
    );
    assert_eq!(scene.lights, b.lights);
    assert_eq!(scene.animations.len(), b.animations.len());
    for (a, d) in scene.animations.iter().zip(&b.animations) {
        assert_eq!(a.name, d.name);
        for (c, cd) in a.channels.iter().zip(&d.channels) {
            assert_eq!(c.node, cd.node as usize);
            assert_eq!(
                (c.property, c.interpolation),
                (cd.property, cd.interpolation)
            );
            assert_eq!((&c.times, &c.values), (&cd.times, &cd.values));
        }
    }
}

#[test]
fn glb_round_trip() {
    let b = builder();
    let path = temp_dir("glb").join("scene.glb");
    b.write(&path).unwrap();
    let scene = import::load(&path).unwrap();
    check_round_trip(&scene, &b);
    // The posed scene behaves: the spot light points down, the camera starts at (0,1,5).
    let lights = scene.lights_at(ClipSelection::All, 0.0);
    let spot = lights
        .iter()
        .find(|l| l.name.as_deref() == Some("spot"))
        .unwrap();
    assert!(spot.direction.abs_diff_eq(Vec3::NEG_Y, 1e-6));
    let cam = scene
        .camera_at(ClipSelection::All, 0.0, Some("main"))
        .unwrap();
    assert_eq!(cam.position, Vec3::new(0.0, 1.0, 5.0));
    let (lo, hi) = scene.bounds_at(ClipSelection::All, 0.0).unwrap();
    assert!(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all());
}

#[test]
fn gltf_round_trip_with_embedded_buffer() {
    let b = builder();
    let path = temp_dir("gltf").join("scene.gltf");
    b.write(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("data:application/octet-stream;base64,"));
    check_round_trip(&import::load(&path).unwrap(), &b);
}

#[test]
fn writes_atomically() {
    let dir = temp_dir("atomic");
    let path = dir.join("out.glb");
    std::fs::write(&path, b"old").unwrap();
    builder().write(&path).unwrap();
    assert!(std::fs::read(&path).unwrap().starts_with(b"glTF"));
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name() != "out.glb")
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    let missing = dir.join("no/such/folder/out.glb");
    let e = builder().write(&missing).unwrap_err();
    assert!(matches!(e, ImportError::WriteIo { .. }));
    assert!(e.to_string().contains("no/such/folder/out.glb"), "{e}");
}
