//! The smallest scene that shows how an emissive quad lights a floor: a grey Lambertian
//! floor (base colour 0.8, metallic 0, roughness 1; the plane y = 0, ±5) under a 1 × 1
//! emitter of radiance 1 at height 2 facing down, written as glTF, and the floor's
//! radiance under the emitter's centre from the irradiance integrated on a fine grid
//! (`0.8/π · E`). docs/IMAGES.md renders it with subfield and Blender Cycles to find
//! why CornellBox looked darker than Cycles.
//!
//! `cargo run --release --example lamp_floor [-- OUT.glb]` (default `out/lamp_floor.glb`).

use glam::{Vec3, Vec4};
use subfield::import;
use subfield::scene::{Material, Mesh, Node, Primitive, Scene};

/// A rectangle through `centre` spanned by the half extents `a` and `b`, facing `a × b`.
fn quad(centre: Vec3, a: Vec3, b: Vec3, material: u32) -> Primitive {
    let n = a.cross(b).normalize();
    Primitive {
        positions: vec![
            centre - a - b,
            centre + a - b,
            centre + a + b,
            centre - a + b,
        ],
        normals: Some(vec![n; 4]),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        material,
        ..Primitive::default()
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "out/lamp_floor.glb".into());
    let floor = Material {
        base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
        metallic: 0.0,
        roughness: 1.0,
        ..Material::default()
    };
    let lamp = Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        metallic: 0.0,
        emissive: Vec3::ONE,
        ..Material::default()
    };
    let scene = Scene {
        materials: vec![floor, lamp],
        meshes: vec![Mesh {
            primitives: vec![
                // Z × X = +Y: the floor faces up; X × Z = -Y: the lamp faces down.
                quad(Vec3::ZERO, Vec3::Z * 5.0, Vec3::X * 5.0, 0),
                quad(Vec3::new(0.0, 2.0, 0.0), Vec3::X * 0.5, Vec3::Z * 0.5, 1),
            ],
            ..Mesh::default()
        }],
        nodes: vec![Node {
            mesh: Some(0),
            ..Node::default()
        }],
        roots: vec![0],
        ..Scene::default()
    };
    let path = std::path::Path::new(&out);
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    import::write_gltf(&scene, path)?;

    let n = 1000;
    let mut e = 0.0f64;
    for i in 0..n {
        for j in 0..n {
            let x = -0.5 + (f64::from(i) + 0.5) / f64::from(n);
            let z = -0.5 + (f64::from(j) + 0.5) / f64::from(n);
            let d2 = x * x + 4.0 + z * z;
            // cos at the floor = cos at the lamp = 2/d.
            e += 4.0 / d2 / d2;
        }
    }
    e /= f64::from(n * n);
    println!(
        "{out}: irradiance under the lamp {e:.5}, floor radiance 0.8/π·E = {:.5}",
        0.8 / std::f64::consts::PI * e
    );
    Ok(())
}
