//! A small scene built in code for the renderer's tests: a floor, a mirror, a glass
//! cube (static), a cube that moves and turns (dynamic), an animated camera, a point
//! light and a directional light, as a `Scene` (see `build`), written as .glb.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3, Vec4};
use subfield::scene::{
    Animation, Channel, Falloff, LightDef, LightKind, Material, Node, Primitive, Property, Scene,
};

use super::build::{diffuse, linear, mesh, perspective, placed, tris, SceneBuilder};

/// A fresh, empty folder under the system temp dir for one test.
pub fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir()
        .join(format!("subfield-render-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// An axis-aligned box of half size `h` around the origin: 24 vertices with face
/// normals, 36 indices.
pub fn cube(h: Vec3, material: u32) -> Primitive {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut indices = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            let a = n.any_orthonormal_vector();
            let b = n.cross(a);
            let base = positions.len() as u32;
            for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                positions.push((n + a * s + b * t) * h);
                normals.push(n);
            }
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
    }
    Primitive {
        positions,
        normals: Some(normals),
        triangles: tris(&indices),
        material,
        ..Primitive::default()
    }
}

/// A rectangle in the plane through `centre` spanned by `a` and `b` (half extents),
/// facing `a × b`.
pub fn quad(centre: Vec3, a: Vec3, b: Vec3, material: u32) -> Primitive {
    let n = a.cross(b).normalize();
    Primitive {
        positions: vec![
            centre - a - b,
            centre + a - b,
            centre + a + b,
            centre - a + b,
        ],
        normals: Some(vec![n; 4]),
        uvs: Some(vec![
            glam::Vec2::new(0.0, 0.0),
            glam::Vec2::new(1.0, 0.0),
            glam::Vec2::new(1.0, 1.0),
            glam::Vec2::new(0.0, 1.0),
        ]),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        material,
        ..Primitive::default()
    }
}

/// The test rooms' first two materials, added in this order: the grey floor's and the
/// mirror's.
pub fn room_materials(b: &mut SceneBuilder) -> (u32, u32) {
    let grey = b.add_material(diffuse("floor", Vec4::new(0.7, 0.7, 0.7, 1.0), 0.8));
    let mirror = b.add_material(Material {
        metallic: 1.0,
        ..diffuse("mirror", Vec4::new(0.9, 0.9, 0.9, 1.0), 0.0)
    });
    (grey, mirror)
}

/// The test rooms' floor (at y = 0, `half` each way in x and z) and the mirror behind
/// it (4 × 3 at z = −2.5, facing +z).
pub fn floor_and_mirror(half: f32, grey: u32, mirror: u32) -> [Primitive; 2] {
    [
        quad(Vec3::ZERO, Vec3::Z * half, Vec3::X * half, grey),
        quad(
            Vec3::new(0.0, 1.5, -2.5),
            Vec3::X * 2.0,
            Vec3::Y * 1.5,
            mirror,
        ),
    ]
}

/// The moving cube's channels: over 1 s from (1, 0.4, 0.5) to `to`, turning 1.5 rad
/// about +Y.
pub fn tumbling(node: usize, to: Vec3) -> [Channel; 2] {
    [
        linear(
            node,
            Property::Translation,
            vec![0.0, 1.0],
            vec![1.0, 0.4, 0.5, to.x, to.y, to.z],
        ),
        linear(
            node,
            Property::Rotation,
            vec![0.0, 1.0],
            [
                Quat::IDENTITY.to_array(),
                Quat::from_rotation_y(1.5).to_array(),
            ]
            .concat(),
        ),
    ]
}

/// The test scene (1 s of animation, 24 fps recorded in `extras.fps`).
pub fn scene() -> Scene {
    scene_of(true)
}

/// The test scene without its emissive lamp (so no random numbers are drawn at one
/// sample a pixel) and with the point light moving between frames 3 and 6 (0.125 s to
/// 0.25 s) and still before and after.
pub fn scene_without_emitters() -> Scene {
    scene_of(false)
}

fn scene_of(lamp_on: bool) -> Scene {
    let mut b = SceneBuilder::new();
    let (grey, mirror) = room_materials(&mut b);
    let glass = b.add_material(Material {
        transmission: 1.0,
        ior: 1.5,
        double_sided: true,
        ..diffuse("glass", Vec4::ONE, 0.0)
    });
    let red = b.add_material(diffuse("red", Vec4::new(0.8, 0.1, 0.1, 1.0), 0.4));
    let lamp = b.add_material(Material {
        emissive: Vec3::new(1.0, 0.9, 0.6),
        ..diffuse("lamp", Vec4::ONE, 1.0)
    });
    let mut room_quads = floor_and_mirror(5.0, grey, mirror).to_vec();
    if lamp_on {
        room_quads.push(quad(
            Vec3::new(3.0, 2.5, -2.0),
            Vec3::X * 0.5,
            Vec3::Y * 0.5,
            lamp,
        ));
    }
    let statics = b.add_mesh(mesh("room", room_quads));
    let glass_cube = b.add_mesh(mesh("glass", vec![cube(Vec3::splat(0.5), glass)]));
    let red_cube = b.add_mesh(mesh("mover", vec![cube(Vec3::new(0.4, 0.4, 0.4), red)]));
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
    // After the meshes' nodes: tests move `nodes[0]`, the room.
    let [camera, bulb, sun_node] = camera_and_lights(&mut b);
    let side = b.add_camera(perspective("side", 1.0, Some(1.0), 0.1, None));
    let side_cam = b.add_node(Node {
        name: Some("side camera".into()),
        camera: Some(side),
        transform: placed(
            Vec3::new(6.0, 1.5, 0.0),
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
        ),
        ..Default::default()
    });
    for n in [room, glass_node, mover, camera, side_cam, bulb, sun_node] {
        b.add_root(n);
    }
    let mut channels: Vec<Channel> = tumbling(mover, Vec3::new(0.0, 1.2, 1.0)).into();
    channels.push(linear(
        camera,
        Property::Translation,
        vec![0.0, 1.0],
        vec![0.0, 2.0, 6.0, 0.8, 2.2, 5.5],
    ));
    if !lamp_on {
        channels.push(linear(
            bulb,
            Property::Translation,
            vec![0.0, 0.125, 0.25, 1.0],
            vec![2.0, 4.0, 3.0, 2.0, 4.0, 3.0, 0.5, 3.5, 2.0, 0.5, 3.5, 2.0],
        ));
    }
    b.add_animation(Animation {
        name: Some("move".into()),
        channels,
    });
    b.scene.fps = Some(24.0);
    b.finish()
}

/// The test rooms' view and light (this file's scene's and `tests/gpu_frames.rs`'s): the main camera (node "camera") looking down at the
/// room from 6 in front, a point light ("bulb") up and to the right, and a sun; their
/// nodes, to add as roots.
pub fn camera_and_lights(b: &mut SceneBuilder) -> [usize; 3] {
    let cam = b.add_camera(perspective("main", 0.8, None, 0.1, None));
    let point = b.add_light(LightDef {
        name: Some("bulb".into()),
        kind: LightKind::Point,
        color: Vec3::new(1.0, 0.95, 0.9),
        intensity: 40.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let sun = b.add_light(LightDef {
        name: Some("sun".into()),
        kind: LightKind::Directional,
        color: Vec3::ONE,
        intensity: 1.5,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let camera = b.add_node(Node {
        name: Some("camera".into()),
        camera: Some(cam),
        transform: placed(
            Vec3::new(0.0, 2.0, 6.0),
            Quat::from_rotation_x(-(2.0f32 / 6.0).atan()),
        ),
        ..Default::default()
    });
    let bulb = b.add_node(Node {
        name: Some("bulb".into()),
        light: Some(point),
        transform: placed(Vec3::new(2.0, 4.0, 3.0), Quat::IDENTITY),
        ..Default::default()
    });
    let sun_node = b.add_node(Node {
        name: Some("sun".into()),
        light: Some(sun),
        transform: placed(
            Vec3::ZERO,
            Quat::from_rotation_x(-1.0) * Quat::from_rotation_y(0.5),
        ),
        ..Default::default()
    });
    [camera, bulb, sun_node]
}

/// Writes [`scene_without_emitters`] as `dir/still.glb`.
pub fn write_scene_without_emitters(dir: &Path) -> PathBuf {
    let p = dir.join("still.glb");
    subfield::import::write_gltf(&scene_without_emitters(), &p).unwrap();
    p
}

/// Writes the test scene as `dir/scene.glb`.
pub fn write_scene(dir: &Path) -> PathBuf {
    let p = dir.join("scene.glb");
    subfield::import::write_gltf(&scene(), &p).unwrap();
    p
}

/// Every regular file under `dir` (recursively), relative, sorted.
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

/// `scene` with its lamp's emission textured (a 2x2 sRGB image, warm to cold across
/// the quad, bilinear): the area light's samples read the texture where they land.
#[allow(dead_code)]
pub fn with_textured_lamp(mut scene: Scene) -> Scene {
    let image = scene.images.len() as u32;
    scene.images.push(subfield::scene::Image {
        name: None,
        width: 2,
        height: 2,
        rgba8: vec![
            255, 200, 120, 255, 120, 160, 255, 255, 255, 255, 255, 255, 40, 40, 40, 255,
        ],
    });
    let texture = scene.textures.len() as u32;
    scene.textures.push(subfield::scene::Texture {
        image,
        wrap_s: subfield::scene::Wrap::ClampToEdge,
        wrap_t: subfield::scene::Wrap::ClampToEdge,
        nearest: false,
    });
    for m in &mut scene.materials {
        if m.name.as_deref() == Some("lamp") {
            m.emissive_texture = Some(subfield::scene::TextureRef {
                texture,
                tex_coord: 0,
                transform: None,
            });
        }
    }
    scene
}
