//! The one Scene model: geometry, materials, hierarchy, cameras, lights, animation
//! sampling, and the static/dynamic split.
//!
//! The model is format-neutral and knows no file format: the readers of the `import`
//! layer (glTF, AFF / NFF) and the generators of `gen` produce it, and every importer runs
//! the import layer's `validate` before handing a scene out. Past that border the rest of
//! the crate relies on the invariants it checks (every index in range, every float finite,
//! the node hierarchy a forest). Nothing in this module uses the import layer.
//!
//! Data flow: `Scene` → [`Scene::split`] → [`Scene::static_triangles`] (baked) and
//! [`Scene::dynamic_triangles_at`] (per frame, inserted into the dynamic layer).

mod animation;
mod error;
mod geometry;
mod points;
mod split;

use std::path::PathBuf;

use glam::{Mat4, Quat, Vec2, Vec3, Vec4};

pub use animation::{ClipSelection, Pose};
pub use error::SceneError;
pub use geometry::TriangleSoup;
pub use points::{PointCache, PointSample, Topology};
pub use split::{Instance, Split, SplitSummary};

/// A non-fatal problem found while importing (a skipped primitive, an ignored feature).
/// The library never prints: the CLI shows these.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Warning(pub String);

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// A whole scene: geometry, materials, hierarchy, cameras, lights and animation clips.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// The file it came from (named in errors).
    pub source: PathBuf,
    pub meshes: Vec<Mesh>,
    /// Every primitive's `material` indexes this; importers append a default material when
    /// some primitive has none (see [`Material::default`]).
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub images: Vec<Image>,
    pub nodes: Vec<Node>,
    /// Root nodes of the scene that is shown (glTF: the default scene).
    pub roots: Vec<usize>,
    pub cameras: Vec<CameraDef>,
    pub lights: Vec<LightDef>,
    pub skins: Vec<Skin>,
    pub animations: Vec<Animation>,
    /// Primitives whose points are given per sample time (USD time-sampled `points`),
    /// sorted by `(mesh, primitive)`; empty for glTF and AFF scenes.
    pub point_caches: Vec<PointCache>,
    /// The authored time range in seconds (a USD stage's `startTimeCode..endTimeCode`
    /// over `timeCodesPerSecond`): where set, the span a render covers by default
    /// ([`Scene::key_span`]).
    pub time_range: Option<(f32, f32)>,
    /// Frames per second recorded by the scene (`scenes[i].extras.fps` in glTF).
    pub fps: Option<f32>,
    /// Ambient light of the scene (linear RGB; AFF's `am`, `scenes[i].extras.ambient` in
    /// glTF): where set, it replaces the render options' ambient term
    /// ([`ShadingOptions::ambient`](crate::render::ShadingOptions::ambient)).
    pub ambient: Option<Vec3>,
    /// Application data carried beside the model, which the glTF writer passes on.
    pub extras: Extras,
    pub warnings: Vec<Warning>,
}

/// Application data a scene carries beside the model (glTF `extras`): nothing here changes
/// the picture. The AFF reader keeps the AFF numbers glTF has no place for here; the glTF
/// writer writes them back out.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Extras {
    /// Members of the scene's `extras` besides `fps` (which is [`Scene::fps`]).
    pub scene: serde_json::Map<String, serde_json::Value>,
    /// A material's `extras` (a JSON object), by material index; missing entries and
    /// `None` mean none.
    pub materials: Vec<Option<serde_json::Value>>,
}

/// A mesh: primitives drawn together, and the default weights of its morph targets.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub name: Option<String>,
    pub primitives: Vec<Primitive>,
    /// Default morph weights (glTF `mesh.weights`); empty means all zero.
    pub weights: Vec<f32>,
}

/// Triangles sharing one material, in the mesh's local space.
#[derive(Clone, Debug, Default)]
pub struct Primitive {
    pub positions: Vec<Vec3>,
    /// Per-vertex normals; `None` means flat normals computed from the posed triangle
    /// (what the glTF spec asks for when normals are absent).
    pub normals: Option<Vec<Vec3>>,
    /// The texture coordinates its material's textures use (`TEXCOORD_0` unless their
    /// `texCoord` names another set); `None` gives `(0, 0)`.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex indices (strips and fans already unrolled).
    pub triangles: Vec<[u32; 3]>,
    /// Index into [`Scene::materials`].
    pub material: u32,
    /// Skin influences: `joints.len() == weights.len() == positions.len() * sets`, vertex
    /// `v` uses entries `v*sets .. (v+1)*sets` (one entry per `JOINTS_n`/`WEIGHTS_n` set).
    /// Joint numbers index the skin's joint list. Empty when not skinned.
    pub joints: Vec<[u16; 4]>,
    pub weights: Vec<[f32; 4]>,
    pub morph_targets: Vec<MorphTarget>,
}

impl Primitive {
    /// Number of `JOINTS_n`/`WEIGHTS_n` sets (0 when the primitive carries no skin data).
    pub fn influence_sets(&self) -> usize {
        self.joints
            .len()
            .checked_div(self.positions.len())
            .unwrap_or(0)
    }
}

/// Per-vertex displacements of one morph target; an empty vector means "no displacement".
#[derive(Clone, Debug, Default)]
pub struct MorphTarget {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
}

/// Alpha handling of a material (glTF `alphaMode`).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[non_exhaustive]
pub enum AlphaMode {
    #[default]
    Opaque,
    Mask {
        cutoff: f32,
    },
    Blend,
}

/// A texture slot of a material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureRef {
    /// Index into [`Scene::textures`].
    pub texture: u32,
    /// Which texture-coordinate set the file names (`KHR_texture_transform`'s override
    /// applied). The importer gives each primitive this set as [`Primitive::uvs`].
    pub tex_coord: u32,
    /// `KHR_texture_transform`, applied to the uv before sampling; `None` is identity.
    pub transform: Option<UvTransform>,
}

/// A texture-coordinate transform (`KHR_texture_transform`): scale, then rotate
/// `rotation` radians, then offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    pub offset: Vec2,
    pub rotation: f32,
    pub scale: Vec2,
}

impl UvTransform {
    /// The transformed uv. The rotation follows the extension's worked example (offset
    /// `[0, 1]`, rotation π/2, scale `[0.5, 0.5]` maps the unit square onto the lower-left
    /// quadrant): `(u, v) → (cos·u + sin·v, −sin·u + cos·v)`.
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let s = uv * self.scale;
        let (sin, cos) = self.rotation.sin_cos();
        Vec2::new(cos * s.x + sin * s.y, cos * s.y - sin * s.x) + self.offset
    }

    /// Every parameter finite.
    pub fn is_finite(&self) -> bool {
        self.offset.is_finite() && self.rotation.is_finite() && self.scale.is_finite()
    }
}

/// A metallic-roughness material with the extensions we render (emissive strength,
/// transmission, index of refraction). Colours are linear.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: Option<String>,
    pub base_color: Vec4,
    pub base_color_texture: Option<TextureRef>,
    pub metallic: f32,
    pub roughness: f32,
    /// Blue channel metallic, green channel roughness (glTF convention).
    pub metallic_roughness_texture: Option<TextureRef>,
    pub emissive: Vec3,
    /// `KHR_materials_emissive_strength`; 1 when absent. Emitted radiance is
    /// `emissive * emissive_strength` (times the texture).
    pub emissive_strength: f32,
    pub emissive_texture: Option<TextureRef>,
    /// Tangent-space normal map (glTF `normalTexture`, linear RGB, +Y towards
    /// decreasing `v`); tangents come from the triangle's uvs (see `render::shade`).
    pub normal_texture: Option<TextureRef>,
    /// `normalTexture.scale`: multiplies the map's X and Y; 1 when absent.
    pub normal_scale: f32,
    /// `KHR_materials_transmission` factor; 0 when absent.
    pub transmission: f32,
    /// `KHR_materials_ior`; 1.5 when absent.
    pub ior: f32,
    pub double_sided: bool,
    pub alpha_mode: AlphaMode,
    /// The colour the ambient light is reflected with (AFF's per-material ambient colour;
    /// glTF `materials[i].extras.ambient`), times the base colour texture; `None`: the
    /// diffuse colour, as for every glTF material.
    pub ambient: Option<Vec3>,
}

impl Default for Material {
    /// The glTF default material: every property at its spec default (white base
    /// colour, metallic 1, roughness 1, no emission).
    fn default() -> Self {
        Material {
            name: None,
            base_color: Vec4::ONE,
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness_texture: None,
            emissive: Vec3::ZERO,
            emissive_strength: 1.0,
            emissive_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            transmission: 0.0,
            ior: 1.5,
            double_sided: false,
            alpha_mode: AlphaMode::Opaque,
            ambient: None,
        }
    }
}

/// Texture wrapping mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum Wrap {
    #[default]
    Repeat,
    MirroredRepeat,
    ClampToEdge,
}

/// A texture: an image and how to sample it.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Index into [`Scene::images`].
    pub image: u32,
    pub wrap_s: Wrap,
    pub wrap_t: Wrap,
    /// Magnification filter is nearest (else linear).
    pub nearest: bool,
}

/// A decoded image: RGBA, 8 bits per channel, rows top to bottom. Colour textures are
/// sRGB-encoded (as stored); the renderer linearises.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub name: Option<String>,
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
}

/// Translation, rotation, scale: `T * R * S`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Default for Trs {
    fn default() -> Self {
        Trs {
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        }
    }
}

impl Trs {
    pub fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// A node's rest transform as the file gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum NodeTransform {
    /// Kept exactly (a matrix may not be a pure TRS). An animated matrix node is animated
    /// on the TRS decomposition of the matrix.
    Matrix(Mat4),
    Trs(Trs),
}

impl Default for NodeTransform {
    fn default() -> Self {
        NodeTransform::Trs(Trs::default())
    }
}

impl NodeTransform {
    pub fn matrix(&self) -> Mat4 {
        match self {
            NodeTransform::Matrix(m) => *m,
            NodeTransform::Trs(t) => t.matrix(),
        }
    }

    pub fn trs(&self) -> Trs {
        match self {
            NodeTransform::Matrix(m) => {
                let (scale, rotation, translation) = m.to_scale_rotation_translation();
                Trs {
                    translation,
                    rotation,
                    scale,
                }
            }
            NodeTransform::Trs(t) => *t,
        }
    }
}

/// A node of the hierarchy.
#[derive(Clone, Debug, Default)]
pub struct Node {
    pub name: Option<String>,
    pub parent: Option<usize>,
    pub children: Vec<usize>,
    pub transform: NodeTransform,
    pub mesh: Option<usize>,
    pub skin: Option<usize>,
    pub camera: Option<usize>,
    pub light: Option<usize>,
    /// Morph weights overriding the mesh's defaults (glTF `node.weights`).
    pub weights: Option<Vec<f32>>,
}

/// A skin: joints (node indices) and their inverse bind matrices (same length).
#[derive(Clone, Debug, Default)]
pub struct Skin {
    pub name: Option<String>,
    pub joints: Vec<usize>,
    pub inverse_bind_matrices: Vec<Mat4>,
}

/// A camera's projection.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Projection {
    Perspective {
        /// Vertical field of view, radians.
        yfov: f32,
        /// Width over height; `None` means "the image's".
        aspect: Option<f32>,
        znear: f32,
        zfar: Option<f32>,
    },
    /// Kept so the renderer can reject or approximate it; importing never fails on it.
    Orthographic {
        xmag: f32,
        ymag: f32,
        znear: f32,
        zfar: f32,
    },
}

/// A camera as defined in the file (placed by the nodes that reference it).
#[derive(Clone, Debug, PartialEq)]
pub struct CameraDef {
    pub name: Option<String>,
    pub projection: Projection,
}

/// A posed camera: looks down its local `-Z` with `+Y` up.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub name: Option<String>,
    /// The node that places it.
    pub node: usize,
    /// Rigid world-from-camera transform (scale of the node removed).
    pub world_from_camera: Mat4,
    pub position: Vec3,
    pub rotation: Quat,
    pub projection: Projection,
}

impl Camera {
    /// Vertical field of view in radians; `None` for an orthographic camera.
    pub fn yfov(&self) -> Option<f32> {
        match self.projection {
            Projection::Perspective { yfov, .. } => Some(yfov),
            Projection::Orthographic { .. } => None,
        }
    }

    /// Aspect ratio recorded by the file (perspective), or `xmag / ymag` (orthographic).
    pub fn aspect(&self) -> Option<f32> {
        match self.projection {
            Projection::Perspective { aspect, .. } => aspect,
            Projection::Orthographic { xmag, ymag, .. } => Some(xmag / ymag),
        }
    }

    pub fn is_orthographic(&self) -> bool {
        matches!(self.projection, Projection::Orthographic { .. })
    }
}

/// Luminous efficacy that turns the photometric units of glTF's `KHR_lights_punctual`
/// (candela, lux) into the model's radiometric ones (W/sr, W/m²): 683 lm/W, the SI
/// candela's definition at 555 nm and the factor Blender's glTF importer and exporter use
/// (`PBR_WATTS_TO_LUMENS`). The glTF reader divides by it, the glTF writer multiplies.
pub const LUMENS_PER_WATT: f64 = 683.0;

/// Kind of a punctual light (`KHR_lights_punctual`). The model is radiometric: see
/// [`LightDef::intensity`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum LightKind {
    /// Intensity is radiant intensity, W/sr (a glTF file's candela / 683).
    Point,
    /// Intensity in W/sr, as a point light's; cone angles in radians from the axis.
    Spot {
        inner_cone_angle: f32,
        outer_cone_angle: f32,
    },
    /// Intensity is irradiance, W/m² (a glTF file's lux / 683); shines along the
    /// node's `-Z`.
    Directional,
}

/// How the irradiance of a point or spot light changes with distance (a directional
/// light has none).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum Falloff {
    /// `E = intensity / d²`, intensity in W/sr: physical, and the only falloff of
    /// glTF's `KHR_lights_punctual`.
    #[default]
    InverseSquare,
    /// `E = intensity` at any distance (intensity in W/m², as for a directional light):
    /// the positional lights of NFF and AFF (BART), whose intensity does not fall off.
    /// glTF keeps it in the light's `extras` (`"falloff": "none"`); other glTF readers
    /// see an inverse-square light.
    None,
}

/// A light as defined in the file.
#[derive(Clone, Debug, PartialEq)]
pub struct LightDef {
    pub name: Option<String>,
    pub kind: LightKind,
    /// Linear RGB.
    pub color: Vec3,
    /// Radiometric, the unit of the renderer's radiance (W·sr⁻¹·m⁻²): radiant intensity
    /// in W/sr for point and spot lights, irradiance in W/m² for directional ones (and
    /// for point and spot lights without falloff, [`Falloff::None`]). A glTF file gives
    /// candela and lux, which the reader divides by [`LUMENS_PER_WATT`] (and the writer
    /// multiplies back); AFF/NFF lights are set so that BART's shading comes out.
    pub intensity: f32,
    /// Distance where the light's influence ends; `None` is infinite.
    pub range: Option<f32>,
    /// Falloff with distance of a point or spot light (ignored for directional ones).
    pub falloff: Falloff,
}

/// A posed light, in world space.
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    pub name: Option<String>,
    pub node: usize,
    pub kind: LightKind,
    pub color: Vec3,
    /// W/sr or W/m², as [`LightDef::intensity`].
    pub intensity: f32,
    pub range: Option<f32>,
    pub falloff: Falloff,
    pub position: Vec3,
    /// Unit direction the light shines along (the node's world `-Z`).
    pub direction: Vec3,
}

/// The property an animation channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Property {
    Translation,
    Rotation,
    Scale,
    /// Morph target weights.
    Weights,
}

/// Keyframe interpolation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Interpolation {
    Step,
    /// Slerp for rotations.
    Linear,
    /// Hermite spline; each keyframe stores in-tangent, value, out-tangent.
    CubicSpline,
}

/// One animated property of one node.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    pub node: usize,
    pub property: Property,
    pub interpolation: Interpolation,
    /// Keyframe times in seconds, non-decreasing.
    pub times: Vec<f32>,
    /// `width` floats per keyframe (3 translation/scale, 4 rotation `xyzw`, number of
    /// morph targets for weights); `3 * width` for CUBICSPLINE (in-tangent, value,
    /// out-tangent).
    pub values: Vec<f32>,
}

impl Channel {
    /// Floats per keyframe value.
    pub fn width(&self) -> usize {
        let per_key = match self.interpolation {
            Interpolation::CubicSpline => 3,
            _ => 1,
        };
        self.values
            .len()
            .checked_div(self.times.len() * per_key)
            .unwrap_or(0)
    }
}

/// An animation clip.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Animation {
    pub name: Option<String>,
    pub channels: Vec<Channel>,
}

impl Scene {
    /// Whether a render of this scene sends parallel shadow rays: towards a directional
    /// light, or towards the default light (directional) that a scene without lights or
    /// emissive materials gets. No point grid gathers such rays; the bake's default
    /// keeps more directions for them (`PsfParams::for_scene`).
    pub fn has_parallel_light(&self) -> bool {
        let emits = self
            .materials
            .iter()
            .any(|m| m.emissive * m.emissive_strength != Vec3::ZERO);
        self.lights
            .iter()
            .any(|l| matches!(l.kind, LightKind::Directional))
            || (self.lights.is_empty() && !emits)
    }

    /// Index of the material that primitives without one use; appends it when missing.
    pub fn default_material_index(&mut self) -> u32 {
        if let Some(i) = self
            .materials
            .iter()
            .position(|m| m.name.as_deref() == Some(DEFAULT_MATERIAL_NAME))
        {
            return i as u32;
        }
        self.materials.push(Material {
            name: Some(DEFAULT_MATERIAL_NAME.to_string()),
            ..Material::default()
        });
        (self.materials.len() - 1) as u32
    }

    /// Sets every node's `parent` from the `children` lists (for scenes built in code,
    /// which list children and leave parents to this).
    pub fn link_parents(&mut self) {
        for n in &mut self.nodes {
            n.parent = None;
        }
        for p in 0..self.nodes.len() {
            for k in 0..self.nodes[p].children.len() {
                let c = self.nodes[p].children[k];
                if let Some(child) = self.nodes.get_mut(c) {
                    child.parent = Some(p);
                }
            }
        }
    }

    /// The point cache of a primitive, if its points are time-sampled.
    pub fn point_cache(&self, mesh: usize, primitive: usize) -> Option<&PointCache> {
        self.point_caches
            .binary_search_by_key(&(mesh, primitive), |c| (c.mesh, c.primitive))
            .ok()
            .map(|i| &self.point_caches[i])
    }

    /// Names of the clips, as `"INDEX: NAME"` (for messages and `--animation` help).
    pub fn clip_names(&self) -> Vec<String> {
        self.animations
            .iter()
            .enumerate()
            .map(|(i, a)| match &a.name {
                Some(n) => format!("{i}: {n}"),
                None => format!("{i}: (unnamed)"),
            })
            .collect()
    }

    /// Nodes of the shown scene, parents before children (depth first from the roots).
    pub fn scene_nodes(&self) -> Vec<usize> {
        let mut out = Vec::with_capacity(self.nodes.len());
        let mut stack: Vec<usize> = self.roots.iter().rev().copied().collect();
        let mut seen = vec![false; self.nodes.len()];
        while let Some(n) = stack.pop() {
            // `validate` guarantees a forest; `seen` also keeps a root listed twice single.
            if n >= self.nodes.len() || std::mem::replace(&mut seen[n], true) {
                continue;
            }
            out.push(n);
            stack.extend(self.nodes[n].children.iter().rev().copied());
        }
        out
    }
}

/// Name given to the material appended for primitives that have none.
pub const DEFAULT_MATERIAL_NAME: &str = "subfield:default";

#[cfg(test)]
mod parallel_light_tests {
    use super::*;

    fn light(kind: LightKind) -> LightDef {
        LightDef {
            name: None,
            kind,
            color: Vec3::ONE,
            intensity: 1.0,
            range: None,
            falloff: Falloff::InverseSquare,
        }
    }

    #[test]
    fn parallel_shadow_rays_come_from_a_sun_or_the_default_light() {
        let mut scene = Scene::default();
        // No lights, no emitters: the default light, a directional one.
        assert!(scene.has_parallel_light());
        // An emissive material lights the scene instead: no default light.
        scene.materials.push(Material {
            emissive: Vec3::ONE,
            ..Material::default()
        });
        assert!(!scene.has_parallel_light());
        scene.materials.clear();
        scene.lights.push(light(LightKind::Point));
        scene.lights.push(light(LightKind::Spot {
            inner_cone_angle: 0.1,
            outer_cone_angle: 0.3,
        }));
        assert!(!scene.has_parallel_light());
        scene.lights.push(light(LightKind::Directional));
        assert!(scene.has_parallel_light());
    }
}
