//! BART AFF (and its subset NFF) import: a streaming parser into an [`AffScene`], direct
//! evaluation of that scene at any time (splines, visibility, animated triangles), and its
//! mapping onto the one [`Scene`] model ([`AffScene::to_scene`]).
//!
//! `import::load` accepts `.aff` / `.nff` through [`load_scene`]: the file is parsed and
//! mapped onto a [`Scene`], which the border check `import::validate` then checks like any
//! imported scene. `subfield convert` writes that same `Scene` with the glTF writer, and
//! the model is built as the glTF reader builds it from that file, so `bake`, `render` and
//! a converted `.glb` see the same scene.
//!
//! Includes (`i`) and texture names are files in the scene's folder, under the policy of
//! glTF URIs (`import::folder`): an absolute path, a `..` above the folder or a symbolic
//! link out of it is refused with one line naming the name and the folder.
//!
//! # Time
//! AFF frame `i` of `a t0 t1 n` is at `t0 + i·(t1−t0)/(n−1)`. The model's clock starts at
//! `t0` (key times are AFF times minus `t0`) and [`Scene::fps`] (the converted file's
//! `scenes[0].extras.fps`) records `(n−1)/(t1−t0)`, so time `i / fps` is AFF frame `i`.
//! Without an `a` line (or with one frame) no clip is made and the scene is posed at `t0`
//! (0 without `a`).
//!
//! # What the mapping carries exactly, and what it approximates
//! * Static transforms `xs` become node TRS (exact: AFF composes `T·R·S` as glTF does).
//! * Animated transforms `x name` driven by `k name`: the Kochanek–Bartels translation and
//!   scale splines and the quaternion rotation spline cannot be carried by glTF's
//!   interpolations, so they are sampled at every AFF frame time into LINEAR channels:
//!   exact at the frames, linear between them.
//! * Visibility tracks: a child node under the animated node whose scale is 1 or 0,
//!   STEP-interpolated at the visibility keys (exact).
//! * Animated triangles `tpa`: one primitive per (block, material, key times) with a morph
//!   target per key after the first (`key_k − key_0`), and a LINEAR weights channel at the
//!   key times that blends consecutive keys: positions are exact (piecewise linear as in
//!   AFF). Normals are normalised per key and blended the same way, then renormalised by
//!   the renderer — AFF blends the raw normals, so in-between directions can differ a
//!   little where the raw normals differ in length.
//! * Spheres and cones are tessellated ([`shapes`]); polygons are fanned.
//! * The camera (`v`, animated by `k camera`) becomes a perspective camera node with the
//!   `v` line's vertical field of view and `w/h` aspect; `hither` is `znear` (values below
//!   1e-4 become 1, as BART does); yon is infinite.
//! * Lights: `l` / `la` become point lights (`KHR_lights_punctual` in the converted file)
//!   of the AFF colour (white when absent) without falloff ([`Falloff::None`](crate::scene::Falloff::None): NFF and AFF
//!   lights are as bright at any distance) and intensity π W/m² (so a white diffuse
//!   surface facing a white light has radiance 1, NFF's `diffuse · colour · N·L`); the
//!   converted file writes it in the spec's units, 683·π. It keeps the falloff in the
//!   light's `extras` (`"falloff": "none"`), which subfield reads back; other glTF
//!   readers see an inverse-square light of 683·π candela. `la` lights named by a
//!   `k` block follow its translation track (the light's position).
//! * Textures: each AFF image becomes an opaque RGBA8 image with the default sampler
//!   (linear, repeat); the converted file embeds it as PNG.
//! * Ambient `am` (default 1 1 1) is the scene's ambient light ([`Scene::ambient`],
//!   `scenes[0].extras.ambient` in the converted file), reflected with each material's
//!   ambient colour ([`Material::ambient`](crate::scene::Material::ambient),
//!   `materials[i].extras.ambient`; `f`: colour·Kd, `fm`: its first three numbers) as
//!   NFF and BART shade: the renderer's ambient term, in place of its default.
//! * Background `b` (not used by the renderer) and ambient `am` have no glTF
//!   equivalent: they are kept as read in [`Scene::extras`] (`scene.aff`: `background`,
//!   `ambient`, `t0`, `frames`), which the converted file carries as
//!   `scenes[0].extras.aff`.
//! * Materials (`f`, `fm`) map to metallic-roughness (see [`material`]); the exact AFF
//!   numbers are kept in the material's extras (`extras.aff` in the converted file, see
//!   [`material_extras`]).

mod model;
mod parse;
pub mod shapes;
pub mod spline;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3, Mat4, Vec2, Vec3};

use super::ImportError;
pub use model::{material, material_extras};

use crate::scene::Scene;
use spline::{RotKey, VecKey};

/// Largest `n` accepted in `a t0 t1 n` (every animated node is sampled at every frame).
pub const MAX_FRAMES: u32 = 100_000;

/// The `v` statement.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    pub from: Vec3,
    pub at: Vec3,
    pub up: Vec3,
    /// Vertical field of view, degrees.
    pub angle: f32,
    pub hither: f32,
    pub resolution: (u32, u32),
}

/// The `a t0 t1 n` statement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeRange {
    pub start: f64,
    pub end: f64,
    pub frames: u32,
}

impl TimeRange {
    /// AFF time of frame `i`: `t0 + i·(t1−t0)/(n−1)` (`t0` with a single frame).
    pub fn frame_time(&self, i: u32) -> f64 {
        if self.frames < 2 {
            return self.start;
        }
        self.start + f64::from(i) * (self.end - self.start) / f64::from(self.frames - 1)
    }

    /// Frames per second of the converted glTF: `(n−1)/(t1−t0)`; `None` without motion.
    pub fn fps(&self) -> Option<f64> {
        let fps = f64::from(self.frames.saturating_sub(1)) / (self.end - self.start);
        (self.frames >= 2 && fps.is_finite() && fps > 0.0).then_some(fps)
    }
}

/// A point light (`l`, or `la` when named).
#[derive(Clone, Debug, PartialEq)]
pub struct AffLight {
    pub name: Option<String>,
    pub position: Vec3,
    pub color: Vec3,
}

/// A material as AFF gives it (`f` is turned into this form: ambient = diffuse =
/// colour·Kd, specular = Ks grey).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AffMaterial {
    pub ambient: Vec3,
    pub diffuse: Vec3,
    pub specular: Vec3,
    /// Phong exponent.
    pub shine: f32,
    /// Transmittance `T`.
    pub transmittance: f32,
    pub ior: f32,
}

impl Default for AffMaterial {
    /// White diffuse, used by primitives before any `f` / `fm`.
    fn default() -> Self {
        AffMaterial {
            ambient: Vec3::ONE,
            diffuse: Vec3::ONE,
            specular: Vec3::ZERO,
            shine: 0.0,
            transmittance: 0.0,
            ior: 1.0,
        }
    }
}

/// A decoded texture image: RGB, 8 bits, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct AffTexture {
    /// The name used in the file.
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub rgb8: Vec<u8>,
}

/// How a block places its contents.
#[derive(Clone, Debug, PartialEq)]
pub enum AffTransform {
    /// The top level.
    Root,
    /// `xs sx sy sz  rx ry rz angle_deg  tx ty tz`: `T·R·S`.
    Static {
        scale: Vec3,
        axis: Vec3,
        /// Degrees.
        angle: f32,
        translation: Vec3,
    },
    /// `x name`: driven by the `k name` block (identity where it has no track).
    Animated(String),
}

/// Static triangles of one block sharing a material, a texture and the presence of
/// normals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// Index into [`AffScene::materials`].
    pub material: u32,
    /// Index into [`AffScene::textures`]; `uvs` is present exactly when this is.
    pub texture: Option<u32>,
    pub positions: Vec<Vec3>,
    /// Unit normals.
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<u32>,
}

impl Batch {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// Animated triangles (`tpa`) of one block sharing a material and key times; vertices
/// `3i..3i+3` are triangle `i`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MorphBatch {
    pub material: u32,
    /// Strictly increasing AFF times.
    pub times: Vec<f64>,
    /// Per key, every vertex.
    pub positions: Vec<Vec<Vec3>>,
    /// Per key, every vertex (unit length).
    pub normals: Vec<Vec<Vec3>>,
}

impl MorphBatch {
    pub fn triangle_count(&self) -> usize {
        self.positions.first().map_or(0, |p| p.len() / 3)
    }

    /// Bracketing keys and blend factor at time `t` (clamped outside the keys).
    pub fn bracket(&self, t: f64) -> (usize, usize, f64) {
        let n = self.times.len();
        if n < 2 || t <= self.times[0] {
            return (0, 0, 0.0);
        }
        if t >= self.times[n - 1] {
            return (n - 1, n - 1, 0.0);
        }
        let j = self.times.partition_point(|&k| k <= t).saturating_sub(1);
        let j = j.min(n - 2);
        let f = (t - self.times[j]) / (self.times[j + 1] - self.times[j]);
        (j, j + 1, f)
    }

    /// Vertex positions at AFF time `t`: linear between the bracketing keys.
    pub fn positions_at(&self, t: f64) -> Vec<Vec3> {
        let (a, b, f) = self.bracket(t);
        let f = f as f32;
        self.positions[a]
            .iter()
            .zip(&self.positions[b])
            .map(|(p, q)| *p + (*q - *p) * f)
            .collect()
    }
}

/// A block (`x`, `xs`, or the top level) and what it holds.
#[derive(Clone, Debug, PartialEq)]
pub struct AffNode {
    pub parent: Option<usize>,
    pub children: Vec<usize>,
    pub transform: AffTransform,
    pub batches: Vec<Batch>,
    pub morphs: Vec<MorphBatch>,
}

/// The tracks of one `k name { ... }` block.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tracks {
    pub translation: Vec<VecKey>,
    pub rotation: Vec<RotKey>,
    pub scale: Vec<VecKey>,
    /// `(time, visible)`.
    pub visibility: Vec<(f64, bool)>,
}

impl Tracks {
    pub fn translation_at(&self, t: f64) -> Option<DVec3> {
        spline::eval_vec(&self.translation, t)
    }
    pub fn rotation_at(&self, t: f64) -> Option<DQuat> {
        spline::eval_rot(&self.rotation, t)
    }
    pub fn scale_at(&self, t: f64) -> Option<DVec3> {
        spline::eval_vec(&self.scale, t)
    }
    /// Visible before the first key; from each key's time on, that key's flag.
    pub fn visible_at(&self, t: f64) -> bool {
        self.visibility
            .iter()
            .take_while(|(k, _)| *k <= t)
            .last()
            .is_none_or(|(_, v)| *v)
    }
    /// `T·R·S` at `t` (identity for missing tracks).
    pub fn matrix_at(&self, t: f64) -> DMat4 {
        DMat4::from_scale_rotation_translation(
            self.scale_at(t).unwrap_or(DVec3::ONE),
            self.rotation_at(t).unwrap_or(DQuat::IDENTITY),
            self.translation_at(t).unwrap_or(DVec3::ZERO),
        )
    }
}

/// A posed camera: position, orientation (looks down local `-Z`, `+Y` up), projection.
#[derive(Clone, Debug, PartialEq)]
pub struct AffCamera {
    pub position: DVec3,
    pub rotation: DQuat,
    /// Radians.
    pub yfov: f32,
    pub aspect: Option<f32>,
    pub znear: f32,
}

/// A parsed AFF / NFF scene.
#[derive(Clone, Debug)]
pub struct AffScene {
    pub source: PathBuf,
    pub view: Option<View>,
    pub background: Vec3,
    pub ambient: Vec3,
    pub time: Option<TimeRange>,
    pub lights: Vec<AffLight>,
    pub materials: Vec<AffMaterial>,
    pub textures: Vec<AffTexture>,
    /// `nodes[0]` is the top level; parents come before their children.
    pub nodes: Vec<AffNode>,
    /// `k` blocks by name.
    pub tracks: BTreeMap<String, Tracks>,
    /// Non-fatal problems (keyframes nothing uses, transforms without keyframes).
    pub warnings: Vec<String>,
}

/// Field of view used when a file animates a camera but has no `v` statement.
const DEFAULT_YFOV_DEG: f32 = 45.0;

impl AffScene {
    /// Parses `path` and everything it includes (relative to its folder).
    pub fn load(path: &Path) -> Result<AffScene, ImportError> {
        parse::parse_file(path)
    }

    /// Parses AFF text; includes and textures resolve against `folder`, `path` names the
    /// input in errors.
    pub fn parse_str(text: &str, path: &Path, folder: &Path) -> Result<AffScene, ImportError> {
        parse::parse_text(text.as_bytes(), path, folder)
    }

    /// Static plus animated triangles.
    pub fn triangle_count(&self) -> usize {
        self.nodes
            .iter()
            .map(|n| {
                n.batches.iter().map(Batch::triangle_count).sum::<usize>()
                    + n.morphs
                        .iter()
                        .map(MorphBatch::triangle_count)
                        .sum::<usize>()
            })
            .sum()
    }

    /// Animated (`tpa`) triangles.
    pub fn animated_triangle_count(&self) -> usize {
        self.nodes
            .iter()
            .flat_map(|n| &n.morphs)
            .map(MorphBatch::triangle_count)
            .sum()
    }

    /// The time the scene is posed at when it has no animation: `t0`, or 0 without `a`.
    pub fn rest_time(&self) -> f64 {
        self.time.map_or(0.0, |r| r.start)
    }

    /// AFF times of every frame (just the rest time without a multi-frame `a` line).
    pub fn frame_times(&self) -> Vec<f64> {
        match self.time {
            Some(r) if r.fps().is_some() => (0..r.frames).map(|i| r.frame_time(i)).collect(),
            _ => vec![self.rest_time()],
        }
    }

    /// A block's own transform at time `t`, visibility included (a hidden block scales to
    /// zero).
    pub fn local_matrix(&self, node: usize, t: f64) -> DMat4 {
        match &self.nodes[node].transform {
            AffTransform::Root => DMat4::IDENTITY,
            AffTransform::Static {
                scale,
                axis,
                angle,
                translation,
            } => DMat4::from_scale_rotation_translation(
                scale.as_dvec3(),
                spline::key_quat(axis.as_dvec3(), f64::from(*angle).to_radians()),
                translation.as_dvec3(),
            ),
            AffTransform::Animated(name) => match self.tracks.get(name) {
                None => DMat4::IDENTITY,
                Some(tr) => {
                    let m = tr.matrix_at(t);
                    if tr.visible_at(t) {
                        m
                    } else {
                        m * DMat4::from_scale(DVec3::ZERO)
                    }
                }
            },
        }
    }

    /// World matrix of every block at time `t`.
    pub fn world_matrices(&self, t: f64) -> Vec<DMat4> {
        let mut out: Vec<DMat4> = Vec::with_capacity(self.nodes.len());
        for (i, n) in self.nodes.iter().enumerate() {
            let local = self.local_matrix(i, t);
            out.push(match n.parent {
                Some(p) => out[p] * local,
                None => local,
            });
        }
        out
    }

    /// Every triangle in world space at AFF time `t`, evaluated directly from the AFF
    /// model (splines, visibility, `tpa` keys). Order: depth first over the blocks; in a
    /// block its static batches, then its animated batches, then its sub-blocks — the
    /// order of the converted glTF's scene walk.
    pub fn triangles_at(&self, t: f64) -> Vec<[Vec3; 3]> {
        let world = self.world_matrices(t);
        let mut out = Vec::new();
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i];
            let m: Mat4 = world[i].as_mat4();
            for b in &node.batches {
                for tri in b.indices.chunks_exact(3) {
                    let p = |k: usize| m.transform_point3(b.positions[tri[k] as usize]);
                    out.push([p(0), p(1), p(2)]);
                }
            }
            for mb in &node.morphs {
                let pos = mb.positions_at(t);
                for tri in pos.chunks_exact(3) {
                    out.push([
                        m.transform_point3(tri[0]),
                        m.transform_point3(tri[1]),
                        m.transform_point3(tri[2]),
                    ]);
                }
            }
            stack.extend(node.children.iter().rev().copied());
        }
        out
    }

    /// The camera at AFF time `t`: the `v` statement, moved by `k camera` where it has
    /// tracks. `None` when the file has neither.
    pub fn camera_at(&self, t: f64) -> Option<AffCamera> {
        let tracks = self.tracks.get("camera");
        if self.view.is_none() && tracks.is_none() {
            return None;
        }
        let (mut position, mut rotation) = match &self.view {
            Some(v) => (v.from.as_dvec3(), look_rotation(v)),
            None => (DVec3::ZERO, DQuat::IDENTITY),
        };
        if let Some(tr) = tracks {
            if let Some(p) = tr.translation_at(t) {
                position = p;
            }
            if let Some(r) = tr.rotation_at(t) {
                rotation = r;
            }
        }
        let (yfov, aspect, znear) = match &self.view {
            Some(v) => (
                v.angle.to_radians(),
                (v.resolution.1 > 0).then(|| v.resolution.0 as f32 / v.resolution.1 as f32),
                if v.hither < 1e-4 { 1.0 } else { v.hither },
            ),
            None => (DEFAULT_YFOV_DEG.to_radians(), None, 0.1),
        };
        Some(AffCamera {
            position,
            rotation,
            yfov,
            aspect,
            znear,
        })
    }

    /// The scene as the one [`Scene`] model (see the module docs for the mapping), checked
    /// by `import::validate`; the parser's warnings come with it.
    pub fn to_scene(&self) -> Result<Scene, ImportError> {
        model::to_scene(self)
    }
}

/// Orientation of a camera at `from` looking at `at` with `up` (local `-Z` forward,
/// `+Y` up).
pub fn look_rotation(v: &View) -> DQuat {
    let fwd = (v.at - v.from).as_dvec3().normalize_or_zero();
    if fwd == DVec3::ZERO {
        return DQuat::IDENTITY;
    }
    let mut right = fwd.cross(v.up.as_dvec3()).normalize_or_zero();
    if right == DVec3::ZERO {
        right = fwd.any_orthonormal_vector();
    }
    let up = right.cross(fwd);
    DQuat::from_mat3(&glam::DMat3::from_cols(right, up, -fwd)).normalize()
}

/// Parses an AFF / NFF file and maps it onto a [`Scene`].
pub fn load_scene(path: &Path) -> Result<Scene, ImportError> {
    AffScene::load(path)?.to_scene()
}
