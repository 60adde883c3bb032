//! Whitted shading, traced as a wavefront: every ray of a depth level is traced as one
//! batch through the [`Intersector`] (closest hits), then shaded in parallel, which
//! yields shadow rays (one per light that faces the point, any-hit batch) and the
//! next level's rays (mirror reflection, refraction, and the continuation through
//! alpha-cut or blended surfaces). Tracing and shading are timed apart.
//!
//! The rooms (the shading model, shared by every ray of the CPU path; a GPU twin would
//! port the same functions):
//!
//! | room | what is there |
//! |---|---|
//! | `mod.rs` (here) | [`ShadeContext`]: what shading reads in a frame; `shade`, one ray's contribution; the model's constants |
//! | `surface` | the surface a ray meets: point, normals, normal maps, uvs, texture level of detail, textured factors |
//! | `bsdf` | the lobes (Fresnel, reflected / transmitted / diffuse weights, the glint) and the rays they send on |
//! | `direct` | direct light: shadow rays to the punctual lights and to samples of the emitters |
//! | `lanes` | the same model on four hits at once in SSE lanes, for plain materials and punctual lights (`shade4`, the same bits as `shade`) |
//! | `block` | a wavefront's bookkeeping: [`Item`], [`BlockOut`] |
//! | `frame` | what a frame's shading fills and reports: [`FrameBuffers`], light-path passes, Cryptomatte, counts |
//!
//! Beside them in `render`: `lights` (the emitters as area lights), `sampling` (seeds,
//! GGX and cosine sampling), `mips` (textures), `environment`.
//!
//! Determinism: rays sit in arrays in a fixed order; each block of rays is shaded by one
//! task into its own lists, blocks are merged in order, and contributions are added to
//! their sample one after the other in array order. Jitter comes from a hash of (frame,
//! pixel, sample). Nothing depends on the thread count.
//!
//! Model (linear RGB radiance, W·sr⁻¹·m⁻², lights radiometric: see `scene::LightDef`):
//! base colour = factor × texture
//! (sRGB texels linearised before filtering; textures are mip-mapped and looked up
//! trilinearly at the level of detail of the ray's cone, see `mips`); the shading normal
//! bent by the normal map, if any (tangents from the triangle's uvs);
//! `F0 = mix(0.04, base, metallic)`; Fresnel `F` by Schlick (exact dielectric Fresnel
//! with the material's IOR for transmissive surfaces).
//!
//! * Reflection: below roughness [`GLOSSY_LIMIT`] one reflection ray a sample, weight
//!   `F`: the mirror direction for a polished surface (GGX width `α = roughness²`
//!   under 1e-3), else a direction drawn from the GGX distribution of visible normals
//!   (weight `F·G1(l)`), so a rough surface reflects a blur that converges with `--spp`.
//!   From the limit on, no reflection ray; a rough metal's lobe then stands in as diffuse
//!   (`metallic·(1 − g)·base`, `g = (1 − roughness)²`).
//! * Refraction weight `(1 − F)·transmission·(1 − metallic)·base` (total internal
//!   reflection goes to the reflection ray).
//! * Diffuse colour `kd = base·(1 − metallic)(1 − transmission)(1 − F)` with a reflection
//!   ray, `base·((1 − metallic)(1 − transmission)(1 − F·g) + metallic·(1 − g))` without.
//!   Lit by every punctual light through a shadow ray as `kd/π·E·cos`, plus a normalised
//!   Blinn–Phong highlight (exponent `2/r⁴ − 2`, at most 256); by the emissive triangles
//!   (area lights, `lights`) through `ceil(8 / spp)` shadow rays at a camera ray's hit and
//!   one deeper, each to a point drawn by power and area, as
//!   `kd/π·Le·cos·cos'/d²/pdf` (their highlight only without a reflection ray: with one,
//!   the reflection ray finds the emitter itself, so nothing is counted twice); an
//!   ambient term `kd·ambient` (the scene's ambient light, AFF `am`, where it has one,
//!   else the options'; a material's own ambient colour, AFF's, times its base colour
//!   texture in place of `kd` where it has one) and the emission `emissive·strength·texture` (from the
//!   front face, both faces when double-sided).
//!
//! Irradiance: directional `E = intensity` (W/m²: a glTF file's lux / 683), point and
//! spot `E = intensity/d²` (W/sr: candela / 683; `E = intensity` for a light without
//! falloff, `Falloff::None`: AFF/NFF lights) with the spec's range window and spot cone
//! falloff. So a Lambertian floor of albedo ρ at distance `d` from a point light of `I`
//! candela, at incidence θ, has radiance `ρ/π · I/683 · cosθ/d²`. Without punctual lights
//! and emitters, the options' default light.

mod block;
mod bsdf;
mod direct;
mod frame;
mod lanes;
mod surface;

use glam::{Vec3, Vec3A};

use super::camera::CameraModel;
use super::lights::AreaLights;
use super::mips::TextureMips;
use super::options::ShadingOptions;
use crate::geometry::{Hit, Ray};
use crate::psf::Prim;
use crate::scene::{Falloff, Light, LightKind, Material, Scene, TriangleSoup};

pub(in crate::render) use block::{BlockOut, Item, REPLAY_LIGHTS};
use bsdf::{diffuse_bounce, pass_through, secondary};
use direct::PreLight;
use frame::split_one;
pub(in crate::render) use frame::{CentreAov, Split};
pub use frame::{CryptoBuffers, FrameBuffers, FrameWork, LightPath, LightPathBuffers, RayCounts};
use surface::alpha_of;

/// Everything shading reads during one frame.
pub struct ShadeContext<'a> {
    pub scene: &'a Scene,
    pub static_soup: &'a TriangleSoup,
    pub dynamic_soup: &'a TriangleSoup,
    pub options: ShadingOptions,
    /// Size of the scene (bounding box diagonal), for ray offsets.
    pub extent: f32,
    pub(in crate::render) lights: Vec<PreLight>,
    pub(in crate::render) area: AreaLights,
    mips: &'a TextureMips,
    /// glTF's default material, for triangles without one (made once, not a hit).
    default_material: Material,
    /// Whether any ray of the frame can draw random numbers (area lights, diffuse
    /// bounces, a glossy lobe). Without, no ray's seed is ever read, so none is made:
    /// a camera ray's is four rounds of a hash (benches/PERF.md, issue 38, round 3).
    pub(in crate::render) random: bool,
    /// Each material as the four-lane path reads it (`None`: one it leaves to
    /// [`shade`](Self::shade)), and the default material's.
    plain: Vec<Option<lanes::PlainMaterial>>,
    plain_default: Option<lanes::PlainMaterial>,
    /// Whether the frame's hits may be shaded four at once ([`ShadeContext::shade4`]):
    /// no area lights or bounces (punctual lights only, any number).
    lanes: bool,
}

/// Passes through alpha-cut surfaces a ray may make.
pub(in crate::render) const MAX_PASSES: u16 = 16;
/// Contributions below this (max component of the weight) are dropped.
pub(in crate::render) const MIN_WEIGHT: f32 = 1e-4;
/// Largest Blinn–Phong exponent (roughness below about 0.3 gets this).
const MAX_SHININESS: f32 = 256.0;
/// From this roughness on, a surface traces no reflection ray. Chosen against Cycles on
/// CornellBox (walls of roughness 0.5): Cycles shows no reflection in them, and at 0.6
/// our GGX rays from them that found the small ceiling light (radiance 100) were
/// fireflies, there being no multiple importance sampling.
pub const GLOSSY_LIMIT: f32 = 0.4;
/// GGX widths below this reflect as a perfect mirror.
pub(in crate::render) const MIRROR_ALPHA: f32 = 1e-3;
/// Area-light samples a pixel gets at its camera rays' hits, over all its samples
/// (`ceil(LIGHT_SAMPLES / spp)` a hit; one at deeper hits).
pub(in crate::render) const LIGHT_SAMPLES: u32 = 8;

/// A ray cone (Akenine-Möller et al. 2021): its width where the ray starts and how fast
/// it widens (radians), for texture level of detail.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(in crate::render) struct Cone {
    pub(in crate::render) width: f32,
    pub(in crate::render) spread: f32,
}

impl<'a> ShadeContext<'a> {
    /// `lights` posed for this frame and the emissive triangles of both soups; a scene
    /// with neither gets the default light when the options ask for it (placed
    /// relative to `camera`). `mips`: the scene's texture chains, built once a render.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        scene: &'a Scene,
        static_soup: &'a TriangleSoup,
        dynamic_soup: &'a TriangleSoup,
        lights: &[Light],
        camera: &CameraModel,
        options: ShadingOptions,
        extent: f32,
        mips: &'a TextureMips,
    ) -> ShadeContext<'a> {
        let mut pre: Vec<PreLight> = lights
            .iter()
            .filter(|l| l.intensity.is_finite() && l.intensity > 0.0)
            .map(|l| PreLight {
                kind: l.kind,
                power: l.color * l.intensity,
                position: l.position,
                direction: l.direction,
                range: l.range.filter(|r| *r > 0.0),
                falloff: l.falloff,
            })
            .collect();
        let area = AreaLights::new(scene, static_soup, dynamic_soup);
        if lights.is_empty() && area.is_empty() && options.default_light {
            let towards = (camera.rotation * Vec3::new(-0.4, 0.6, 0.7)).normalize_or_zero();
            pre.push(PreLight {
                kind: LightKind::Directional,
                power: Vec3::splat(std::f32::consts::PI),
                position: camera.origin,
                direction: -towards,
                range: None,
                falloff: Falloff::InverseSquare,
            });
        }
        let mut options = options;
        if let Some(a) = scene.ambient {
            // The scene's own ambient light (AFF `am`) replaces the options' term.
            options.ambient = a;
        }
        if options.diffuse_bounces > 0 {
            // Traced bounce light replaces the stand-in.
            options.ambient = Vec3::ZERO;
        }
        let default_material = Material::default();
        let random = !area.is_empty()
            || options.diffuse_bounces > 0
            || scene
                .materials
                .iter()
                .chain(std::iter::once(&default_material))
                .any(bsdf::may_be_glossy);
        // The lanes draw a glossy lobe's direction lane by lane; area lights and
        // bounces draw numbers at every hit, which only `shade` does.
        let lanes = area.is_empty() && options.diffuse_bounces == 0;
        ShadeContext {
            plain: scene
                .materials
                .iter()
                .map(lanes::PlainMaterial::of)
                .collect(),
            plain_default: lanes::PlainMaterial::of(&default_material),
            lanes,
            scene,
            static_soup,
            dynamic_soup,
            options,
            extent: if extent.is_finite() && extent > 0.0 {
                extent
            } else {
                1.0
            },
            lights: pre,
            area,
            mips,
            default_material,
            random,
        }
    }

    /// The punctual lights' count: their shadow rays are batches `0..count`, the area
    /// lights' the batch after.
    pub(in crate::render) fn punctual_lights(&self) -> usize {
        self.lights.len()
    }

    fn material(&self, i: u32) -> Option<&Material> {
        self.scene.materials.get(i as usize)
    }

    /// Offset for secondary ray origins at `p`: relative to the position's magnitude
    /// (float spacing) and to the scene's size.
    fn eps(&self, p: Vec3A) -> f32 {
        1e-4 * p.abs().max_element().max(1e-3 * self.extent)
    }

    /// The AOV values at a primary hit: (normal, albedo).
    pub(in crate::render) fn aov(&self, ray: &Ray, hit: &Hit) -> CentreAov {
        let Some(s) = self.surface(ray, hit, 0.0) else {
            return CentreAov::default();
        };
        let albedo = self
            .material(s.material)
            .map_or(Vec3::ONE, |m| self.base_color(m, s.uv, s.lod).truncate());
        CentreAov {
            normal: s.ns.to_array(),
            albedo: albedo.to_array(),
            point: s.point.into(),
        }
    }

    /// Which node placed the hit triangle and its material (Cryptomatte).
    pub(in crate::render) fn ids(&self, hit: &Hit) -> Option<(u32, u32)> {
        let (soup, i) = match Prim::from_index(hit.tri, self.static_soup.len()) {
            Prim::Static(i) => (self.static_soup, i as usize),
            Prim::Moving(i) => (self.dynamic_soup, i as usize),
        };
        Some((*soup.node.get(i)?, *soup.material.get(i)?))
    }

    /// One ray's contribution: the background on a miss; else the pass-through ray of a
    /// surface not wholly opaque, emission and ambient, shadow rays to the lights and
    /// the emitters, and the refracted and reflected rays. `spp`: the frame's samples a
    /// pixel (sets the area-light samples a hit).
    pub(in crate::render) fn shade(
        &self,
        ray: &Ray,
        item: &Item,
        hit: Option<Hit>,
        max_depth: u32,
        spp: u32,
        out: &mut BlockOut,
    ) {
        let Some(hit) = hit else {
            let seen = match &self.options.environment {
                Some(env) => env.radiance(ray.dir),
                None => self.options.background,
            };
            let c = item.weight * seen;
            out.add_split(item.sample, c.into(), || {
                split_one(item.path.unwrap_or(LightPath::Emission), c)
            });
            return;
        };
        let distance = hit.t * ray.dir.length();
        let width = item.cone.width + item.cone.spread * distance;
        let Some(s) = self.surface(ray, &hit, width) else {
            return;
        };
        let m = self.material(s.material).unwrap_or(&self.default_material);
        let base = self.base_color(m, s.uv, s.lod);
        let alpha = alpha_of(m, base);
        let eps = self.eps(s.point);
        let cone = Cone {
            width,
            spread: item.cone.spread,
        };
        if alpha < 1.0 && item.passes < MAX_PASSES {
            pass_through(&s, item, alpha, eps, cone, out);
        }
        if alpha <= 0.0 {
            return;
        }
        out.cover(item.sample, item.coverage * alpha);
        let weight = Vec3A::from(item.weight) * alpha;
        let lobes = self.lobes(m, &s, base.truncate().into());

        // Emission (front face; both when double-sided) and ambient.
        let emitted = if (s.entering || m.double_sided) && !item.diffuse {
            self.emission(m, s.uv, s.lod)
        } else {
            Vec3A::ZERO
        };
        // The ambient light is reflected with the diffuse colour, or with the material's
        // own ambient colour (AFF) times its base colour texture.
        let ambient = match m.ambient {
            None => lobes.kd,
            Some(a) => Vec3A::from(
                a * self
                    .texture(m.base_color_texture, s.uv, s.lod, true)
                    .map_or(Vec3::ONE, |t| t.truncate()),
            ),
        };
        let ambient_light = Vec3A::from(self.options.ambient);
        out.add_split(
            item.sample,
            weight * (emitted + ambient * ambient_light),
            || {
                let mut split = split_one(
                    item.path.unwrap_or(LightPath::Emission),
                    (weight * emitted).into(),
                );
                split[item.path.unwrap_or(LightPath::Diffuse) as usize] +=
                    Vec3::from(weight * (ambient * ambient_light));
                split
            },
        );

        // Direct light through shadow rays.
        let origin = s.point + s.ng * eps;
        self.direct_light(&s, &lobes, weight, origin, item, out);
        if !self.area.is_empty() {
            let n = if item.depth == 0 {
                LIGHT_SAMPLES.div_ceil(spp.max(1))
            } else {
                1
            };
            self.area_light(&s, &lobes, weight, origin, item, n, spp, out);
        }

        if u32::from(item.bounces) < self.options.diffuse_bounces {
            diffuse_bounce(&s, &lobes, item, weight, origin, cone, out);
        }
        if item.depth >= max_depth {
            return;
        }
        secondary(
            &s,
            &lobes,
            item,
            weight,
            eps,
            origin,
            cone,
            self.random,
            out,
        );
    }
}
