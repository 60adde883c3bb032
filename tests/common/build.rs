//! Scenes built in code: a few helpers over the one `Scene` model, so a test names what it
//! builds (a material, a primitive, a placed node) and the index bookkeeping stays here.
//! Write the result with `import::write_gltf` / `import::to_glb`.
#![allow(dead_code)]

use glam::{Quat, Vec3, Vec4};
use subfield::scene::{
    Animation, CameraDef, Channel, Image, Interpolation, LightDef, Material, Mesh, MorphTarget,
    Node, NodeTransform, Primitive, Projection, Property, Scene, Texture, Trs, Wrap,
};

/// A scene under construction: `add_*` return the index of what they add; [`finish`]
/// links every node's parent from the children lists.
///
/// [`finish`]: SceneBuilder::finish
#[derive(Default)]
pub struct SceneBuilder {
    pub scene: Scene,
}

fn push<T>(v: &mut Vec<T>, x: T) -> usize {
    v.push(x);
    v.len() - 1
}

impl SceneBuilder {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn add_material(&mut self, m: Material) -> u32 {
        push(&mut self.scene.materials, m) as u32
    }
    pub fn add_mesh(&mut self, m: Mesh) -> usize {
        push(&mut self.scene.meshes, m)
    }
    pub fn add_camera(&mut self, c: CameraDef) -> usize {
        push(&mut self.scene.cameras, c)
    }
    pub fn add_light(&mut self, l: LightDef) -> usize {
        push(&mut self.scene.lights, l)
    }
    pub fn add_node(&mut self, n: Node) -> usize {
        push(&mut self.scene.nodes, n)
    }
    /// Adds `node` to the roots of the scene.
    pub fn add_root(&mut self, node: usize) {
        self.scene.roots.push(node);
    }
    pub fn add_animation(&mut self, a: Animation) -> usize {
        push(&mut self.scene.animations, a)
    }
    pub fn add_image(&mut self, i: Image) -> u32 {
        push(&mut self.scene.images, i) as u32
    }
    pub fn add_texture(&mut self, t: Texture) -> u32 {
        push(&mut self.scene.textures, t) as u32
    }
    /// The scene, parents linked.
    pub fn finish(mut self) -> Scene {
        self.scene.link_parents();
        self.scene
    }
}

/// A material with the spec's defaults except metallic 0 (a dielectric, which is what a
/// test scene means by a coloured surface).
pub fn diffuse(name: &str, base_color: Vec4, roughness: f32) -> Material {
    Material {
        name: Some(name.to_string()),
        base_color,
        metallic: 0.0,
        roughness,
        ..Material::default()
    }
}

/// Triangles from a flat index list (three per triangle).
pub fn tris(indices: &[u32]) -> Vec<[u32; 3]> {
    indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect()
}

/// Consecutive vertices as triangles: `0 1 2`, `3 4 5`, ...
pub fn consecutive(vertices: usize) -> Vec<[u32; 3]> {
    (0..vertices as u32 / 3)
        .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
        .collect()
}

/// A primitive of `positions` and `indices` (three per triangle) with `material`.
pub fn prim(positions: Vec<Vec3>, indices: &[u32], material: u32) -> Primitive {
    Primitive {
        positions,
        triangles: tris(indices),
        material,
        ..Primitive::default()
    }
}

/// A triangle soup: every three vertices one triangle.
pub fn soup_prim(positions: Vec<Vec3>, material: u32) -> Primitive {
    Primitive {
        triangles: consecutive(positions.len()),
        positions,
        material,
        ..Primitive::default()
    }
}

/// Morph targets displacing positions only.
pub fn targets(displacements: Vec<Vec<Vec3>>) -> Vec<MorphTarget> {
    displacements
        .into_iter()
        .map(|positions| MorphTarget {
            positions,
            normals: Vec::new(),
        })
        .collect()
}

/// A mesh of `primitives`, no default morph weights.
pub fn mesh(name: &str, primitives: Vec<Primitive>) -> Mesh {
    Mesh {
        name: Some(name.to_string()),
        primitives,
        weights: Vec::new(),
    }
}

/// A TRS rest transform.
pub fn trs(translation: Vec3, rotation: Quat, scale: Vec3) -> NodeTransform {
    NodeTransform::Trs(Trs {
        translation,
        rotation,
        scale,
    })
}

/// A translation and a rotation, unit scale.
pub fn placed(translation: Vec3, rotation: Quat) -> NodeTransform {
    trs(translation, rotation, Vec3::ONE)
}

/// A node showing `mesh` at `translation`.
pub fn mesh_node(name: &str, mesh: usize, translation: Vec3) -> Node {
    Node {
        name: Some(name.to_string()),
        mesh: Some(mesh),
        transform: placed(translation, Quat::IDENTITY),
        ..Node::default()
    }
}

/// A perspective camera.
pub fn perspective(
    name: &str,
    yfov: f32,
    aspect: Option<f32>,
    znear: f32,
    zfar: Option<f32>,
) -> CameraDef {
    CameraDef {
        name: Some(name.to_string()),
        projection: Projection::Perspective {
            yfov,
            aspect,
            znear,
            zfar,
        },
    }
}

/// A LINEAR channel.
pub fn linear(node: usize, property: Property, times: Vec<f32>, values: Vec<f32>) -> Channel {
    Channel {
        node,
        property,
        interpolation: Interpolation::Linear,
        times,
        values,
    }
}

/// Adds a 2×2 checker (sRGB 255 / 0 texels, repeated, nearest filtering where it is
/// magnified) to `scene` as an image and a texture; returns the texture's index.
pub fn add_checker(scene: &mut Scene) -> u32 {
    scene.images.push(Image {
        name: None,
        width: 2,
        height: 2,
        rgba8: vec![
            255, 255, 255, 255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255, 255,
        ],
    });
    scene.textures.push(Texture {
        image: (scene.images.len() - 1) as u32,
        wrap_s: Wrap::Repeat,
        wrap_t: Wrap::Repeat,
        nearest: true,
    });
    (scene.textures.len() - 1) as u32
}
