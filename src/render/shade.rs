//! Whitted shading, traced as a wavefront: every ray of a depth level is traced as one
//! batch through the [`Intersector`] (closest hits), then shaded in parallel, which
//! yields shadow rays (one per light that faces the point, any-hit batch) and the
//! next level's rays (mirror reflection, refraction, and the continuation through
//! alpha-cut or blended surfaces). Tracing and shading are timed apart.
//!
//! Why this file is over 800 lines: the shading of one hit (surface, lobes, direct and
//! area light, the secondary rays) shares `Surface`, `Lobes` and `BlockOut` and reads
//! best as one piece; what stands alone already lives beside it (`lights`, `sampling`,
//! `mips`). The next split, if it grows: the lobes and BRDF into a `bsdf` module.
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

use std::time::Duration;

use glam::{Vec2, Vec3, Vec4};

use super::camera::CameraModel;
use super::lights::AreaLights;
use super::mips::TextureMips;
use super::options::ShadingOptions;
use super::sampling::{sample_cosine, sample_ggx_vndf, smith_g1, stratified, Purpose, Seed};
use crate::geometry::{Hit, Ray};
use crate::psf::Prim;
use crate::scene::{
    AlphaMode, Falloff, Light, LightKind, Material, Scene, TextureRef, TriangleSoup,
};

/// Linear radiance and AOVs of one frame, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameBuffers {
    pub width: u32,
    pub height: u32,
    /// Linear RGB and coverage (alpha).
    pub rgba: Vec<[f32; 4]>,
    pub depth: Option<Vec<f32>>,
    pub normal: Option<Vec<[f32; 3]>>,
    pub albedo: Option<Vec<[f32; 3]>>,
    /// World-space hit point of the centre ray (`P.X/Y/Z`).
    pub position: Option<Vec<[f32; 3]>>,
    /// Screen-space motion to the next frame in pixels (`motion.X/Y`; +x right, +y down).
    pub motion: Option<Vec<[f32; 2]>>,
    pub crypto: Option<CryptoBuffers>,
    /// The light-path passes (`--aov diffuse,specular,transmission,emission`): all four
    /// when any is asked for.
    pub light_paths: Option<LightPathBuffers>,
    /// Pixels traced beyond every edge (`--overscan`): the buffers are
    /// `(width + 2·overscan) × (height + 2·overscan)`, row 0 being `y = −overscan`;
    /// `width` and `height` are the image's (the display window).
    pub overscan: u32,
}

impl FrameBuffers {
    /// Width and height of the buffers: the image and its overscan border.
    pub fn data_size(&self) -> (u32, u32) {
        (
            self.width + 2 * self.overscan,
            self.height + 2 * self.overscan,
        )
    }

    /// `--exposure EV`: the radiance (RGB and the light-path passes) × 2^EV; alpha and
    /// the data AOVs are left alone.
    pub fn apply_exposure(&mut self, ev: f32) {
        super::camera::apply_exposure(&mut self.rgba, ev);
        if ev == 0.0 {
            return;
        }
        let k = ev.exp2();
        if let Some(lp) = &mut self.light_paths {
            for pass in &mut lp.passes {
                for c in pass.iter_mut().flatten() {
                    *c *= k;
                }
            }
        }
    }
}

/// Which pass a contribution to the beauty goes to (`--aov
/// diffuse,specular,transmission,emission`), decided as Cycles decides its passes: by
/// the first scattering event at the camera ray's hit (pass-through of alpha-cut or
/// blended surfaces is no event). At that hit, light from the lights through the
/// diffuse lobe, the ambient term and diffuse bounces are `Diffuse`; the lights' glint
/// (the Blinn–Phong highlight) and everything the mirror or GGX reflection ray brings
/// are `Specular`; everything the refracted ray brings is `Transmission`; the hit's own
/// emission and the background or environment a camera ray sees are `Emission`. Past
/// the first event a path keeps its pass (a mirror seen through glass is transmission).
/// Every contribution goes to exactly one pass, so the passes add up to the beauty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum LightPath {
    Diffuse = 0,
    Specular = 1,
    Transmission = 2,
    Emission = 3,
}

impl LightPath {
    /// The passes in channel-layer order.
    pub const ALL: [LightPath; 4] = [
        LightPath::Diffuse,
        LightPath::Specular,
        LightPath::Transmission,
        LightPath::Emission,
    ];

    /// The EXR layer name (`diffuse.R` …) and the `--aov` name.
    pub fn name(self) -> &'static str {
        match self {
            LightPath::Diffuse => "diffuse",
            LightPath::Specular => "specular",
            LightPath::Transmission => "transmission",
            LightPath::Emission => "emission",
        }
    }
}

/// The four light-path passes of a frame, linear RGB a pixel, indexed by
/// [`LightPath`] (`passes[LightPath::Specular as usize]`).
#[derive(Clone, Debug, PartialEq)]
pub struct LightPathBuffers {
    pub passes: [Vec<[f32; 3]>; 4],
    /// Which of them the EXR gets (the `--aov` names given).
    pub written: [bool; 4],
}

/// A contribution split over the passes (indexed by [`LightPath`]).
pub(super) type Split = [Vec3; 4];

/// `c` in pass `path`, nothing in the others.
#[inline]
fn split_one(path: LightPath, c: Vec3) -> Split {
    let mut s = [Vec3::ZERO; 4];
    s[path as usize] = c;
    s
}

/// Cryptomatte ranks of a frame: `levels` `(id, coverage)` pairs a pixel, pixel by
/// pixel, most coverage first (`(0, 0)` past the ids a pixel has).
#[derive(Clone, Debug, PartialEq)]
pub struct CryptoBuffers {
    pub levels: usize,
    pub object: Vec<(f32, f32)>,
    pub material: Vec<(f32, f32)>,
}

/// The centre ray's surface values (zero on a miss).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct CentreAov {
    pub normal: [f32; 3],
    pub albedo: [f32; 3],
    pub point: Vec3,
}

/// Rays traced for one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    /// Camera rays (every sample, plus the pixel-centre AOV rays when `spp > 1`).
    pub primary: u64,
    /// Any-hit rays towards lights.
    pub shadow: u64,
    /// Reflection, refraction and pass-through rays.
    pub secondary: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.secondary
    }
}

/// Where one frame's time went.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameWork {
    /// Wall time inside batch intersection calls.
    pub trace: Duration,
    /// Wall time making rays and shading (everything else of the frame's pixels).
    pub shade: Duration,
    pub rays: RayCounts,
}

/// A light ready for shading.
#[derive(Clone, Copy, Debug)]
pub(super) struct PreLight {
    pub(super) kind: LightKind,
    /// Colour × intensity.
    pub(super) power: Vec3,
    pub(super) position: Vec3,
    /// Unit direction the light shines along.
    pub(super) direction: Vec3,
    pub(super) range: Option<f32>,
    pub(super) falloff: Falloff,
}

/// Everything shading reads during one frame.
pub struct ShadeContext<'a> {
    pub scene: &'a Scene,
    pub static_soup: &'a TriangleSoup,
    pub dynamic_soup: &'a TriangleSoup,
    pub options: ShadingOptions,
    /// Size of the scene (bounding box diagonal), for ray offsets.
    pub extent: f32,
    pub(super) lights: Vec<PreLight>,
    area: AreaLights,
    mips: &'a TextureMips,
    /// glTF's default material, for triangles without one (made once, not a hit).
    default_material: Material,
}

/// Passes through alpha-cut surfaces a ray may make.
const MAX_PASSES: u16 = 16;
/// Contributions below this (max component of the weight) are dropped.
pub(super) const MIN_WEIGHT: f32 = 1e-4;
/// Largest Blinn–Phong exponent (roughness below about 0.3 gets this).
const MAX_SHININESS: f32 = 256.0;
/// From this roughness on, a surface traces no reflection ray. Chosen against Cycles on
/// CornellBox (walls of roughness 0.5): Cycles shows no reflection in them, and at 0.6
/// our GGX rays from them that found the small ceiling light (radiance 100) were
/// fireflies, there being no multiple importance sampling.
pub const GLOSSY_LIMIT: f32 = 0.4;
/// GGX widths below this reflect as a perfect mirror.
pub(super) const MIRROR_ALPHA: f32 = 1e-3;
/// Area-light samples a pixel gets at its camera rays' hits, over all its samples
/// (`ceil(LIGHT_SAMPLES / spp)` a hit; one at deeper hits).
const LIGHT_SAMPLES: u32 = 8;

/// A ray cone (Akenine-Möller et al. 2021): its width where the ray starts and how fast
/// it widens (radians), for texture level of detail.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Cone {
    pub(super) width: f32,
    pub(super) spread: f32,
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
        ShadeContext {
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
            default_material: Material::default(),
        }
    }

    /// The punctual lights' count: their shadow rays are batches `0..count`, the area
    /// lights' the batch after.
    pub(super) fn punctual_lights(&self) -> usize {
        self.lights.len()
    }

    fn material(&self, i: u32) -> Option<&Material> {
        self.scene.materials.get(i as usize)
    }

    /// Samples a texture (RGBA, linearised RGB when `srgb`) at `uv` (through the slot's
    /// `KHR_texture_transform`, if any), filtered for a footprint of level
    /// `lod + log2(√(width·height))` (see [`Surface::lod`]), or `None` without one.
    #[inline]
    fn texture(&self, slot: Option<TextureRef>, uv: Vec2, lod: f32, srgb: bool) -> Option<Vec4> {
        let slot = slot?;
        let t = slot.texture as usize;
        let tex = self.scene.textures.get(t)?;
        let img = self.scene.images.get(tex.image as usize)?;
        let (w, h) = (img.width, img.height);
        if w == 0 || h == 0 || img.rgba8.len() as u64 != u64::from(w) * u64::from(h) * 4 {
            return None;
        }
        let uv = slot.transform.map_or(uv, |t| t.apply(uv));
        let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
        let lod = lod + 0.5 * ((w as f32) * (h as f32)).log2();
        Some(self.mips.lookup(t, tex, &img.rgba8, w, h, uv, lod, srgb))
    }

    /// Geometry at a hit, `None` for a triangle index out of range. `width`: the ray
    /// cone's width at the hit (0: the finest texture level).
    #[inline(always)]
    fn surface(&self, ray: &Ray, hit: &Hit, width: f32) -> Option<Surface> {
        let (soup, i) = match Prim::from_index(hit.tri, self.static_soup.len()) {
            Prim::Static(i) => (self.static_soup, i as usize),
            Prim::Moving(i) => (self.dynamic_soup, i as usize),
        };
        let p = soup.positions.get(i)?;
        let nrm = soup.normals.get(i);
        let uvs = soup.uvs.get(i);
        let material = soup.material.get(i).copied().unwrap_or(u32::MAX);
        let (u, v) = (hit.u, hit.v);
        let w = 1.0 - u - v;
        let point = p[0] * w + p[1] * u + p[2] * v;
        let cross = (p[1] - p[0]).cross(p[2] - p[0]);
        let mut ng = cross.normalize_or_zero();
        let dir = ray.dir.normalize_or_zero();
        if ng == Vec3::ZERO {
            ng = -dir;
        }
        let front = ng;
        // `entering`: the ray meets the side the winding makes the front.
        let entering = ng.dot(dir) < 0.0;
        if !entering {
            ng = -ng;
        }
        let mut ns = nrm
            .map(|n| (n[0] * w + n[1] * u + n[2] * v).normalize_or_zero())
            .unwrap_or(Vec3::ZERO);
        if ns == Vec3::ZERO || !ns.is_finite() {
            ns = front;
        }
        let uv = uvs.map_or(Vec2::ZERO, |t| t[0] * w + t[1] * u + t[2] * v);
        // Level of detail without the texture's size: log2 of the footprint's width in
        // uv units (Akenine-Möller et al. 2021, eq. 34, for a unit texture).
        // Only a textured material reads it (two logarithms a hit saved elsewhere).
        let textured = self.material(material).is_some_and(|m| {
            m.base_color_texture.is_some()
                || m.metallic_roughness_texture.is_some()
                || m.emissive_texture.is_some()
                || m.normal_texture.is_some()
        });
        let uv_area = uvs.map_or(0.0, |t| (t[1] - t[0]).perp_dot(t[2] - t[0]).abs());
        let world_area = cross.length();
        let cos = ng.dot(dir).abs().max(1e-4);
        let lod = if textured && width > 0.0 && uv_area > 0.0 && world_area > 0.0 {
            (width / cos).log2() + 0.5 * (uv_area / world_area).log2()
        } else {
            f32::NEG_INFINITY
        };
        if let (Some(m), Some(t)) = (self.material(material), uvs) {
            if m.normal_texture.is_some() {
                ns = self.normal_mapped(m, ns, p, t, uv, lod).unwrap_or(ns);
            }
        }
        if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        Some(Surface {
            point,
            ng,
            ns,
            dir,
            entering,
            uv,
            lod,
            material,
            tri: hit.tri,
        })
    }

    /// The front-side normal `n` bent by the material's normal map at `uv`. Tangent
    /// `T = ∂p/∂u` of the triangle (per triangle, from its uvs: the file's `TANGENT`
    /// attribute is not read), made orthogonal to `n`; bitangent `B = ±n × T`, the sign
    /// making it point along `−∂p/∂v` (glTF's normal maps have +Y towards decreasing `v`,
    /// and mirrored uvs flip it). `None` where the uvs are degenerate.
    fn normal_mapped(
        &self,
        m: &Material,
        n: Vec3,
        p: &[Vec3; 3],
        t: &[Vec2; 3],
        uv: Vec2,
        lod: f32,
    ) -> Option<Vec3> {
        let c = self.texture(m.normal_texture, uv, lod, false)?;
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let (d1, d2) = (t[1] - t[0], t[2] - t[0]);
        let det = d1.perp_dot(d2);
        if det.abs() < 1e-12 {
            return None;
        }
        let dpdu = (e1 * d2.y - e2 * d1.y) / det;
        let dpdv = (e2 * d1.x - e1 * d2.x) / det;
        let tangent = (dpdu - n * n.dot(dpdu)).try_normalize()?;
        let mut bitangent = n.cross(tangent);
        if bitangent.dot(dpdv) > 0.0 {
            bitangent = -bitangent;
        }
        let s = if m.normal_scale.is_finite() {
            m.normal_scale
        } else {
            1.0
        };
        let local = Vec3::new(
            (2.0 * c.x - 1.0) * s,
            (2.0 * c.y - 1.0) * s,
            2.0 * c.z - 1.0,
        );
        let bent = (tangent * local.x + bitangent * local.y + n * local.z).try_normalize()?;
        // A map cannot turn the normal to the far side of the surface.
        (bent.dot(n) > 0.0).then_some(bent)
    }

    /// Base colour (factor × texture) at a surface.
    fn base_color(&self, m: &Material, uv: Vec2, lod: f32) -> Vec4 {
        match self.texture(m.base_color_texture, uv, lod, true) {
            Some(t) => m.base_color * t,
            None => m.base_color,
        }
    }

    /// Offset for secondary ray origins at `p`: relative to the position's magnitude
    /// (float spacing) and to the scene's size.
    fn eps(&self, p: Vec3) -> f32 {
        1e-4 * p.abs().max_element().max(1e-3 * self.extent)
    }

    /// The AOV values at a primary hit: (normal, albedo).
    pub(super) fn aov(&self, ray: &Ray, hit: &Hit) -> CentreAov {
        let Some(s) = self.surface(ray, hit, 0.0) else {
            return CentreAov::default();
        };
        let albedo = self
            .material(s.material)
            .map_or(Vec3::ONE, |m| self.base_color(m, s.uv, s.lod).truncate());
        CentreAov {
            normal: s.ns.to_array(),
            albedo: albedo.to_array(),
            point: s.point,
        }
    }

    /// Which node placed the hit triangle and its material (Cryptomatte).
    pub(super) fn ids(&self, hit: &Hit) -> Option<(u32, u32)> {
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
    pub(super) fn shade(
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
            out.add_split(item.sample, c, || {
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
        let weight = item.weight * alpha;
        let lobes = self.lobes(m, &s, base.truncate());

        // Emission (front face; both when double-sided) and ambient.
        let emitted = if (s.entering || m.double_sided) && !item.diffuse {
            self.emission(m, s.uv, s.lod)
        } else {
            Vec3::ZERO
        };
        // The ambient light is reflected with the diffuse colour, or with the material's
        // own ambient colour (AFF) times its base colour texture.
        let ambient = match m.ambient {
            None => lobes.kd,
            Some(a) => {
                a * self
                    .texture(m.base_color_texture, s.uv, s.lod, true)
                    .map_or(Vec3::ONE, |t| t.truncate())
            }
        };
        out.add_split(
            item.sample,
            weight * (emitted + ambient * self.options.ambient),
            || {
                let mut split =
                    split_one(item.path.unwrap_or(LightPath::Emission), weight * emitted);
                split[item.path.unwrap_or(LightPath::Diffuse) as usize] +=
                    weight * (ambient * self.options.ambient);
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
        secondary(&s, &lobes, item, weight, eps, origin, cone, out);
    }

    /// Emitted radiance of `m` at `uv`.
    fn emission(&self, m: &Material, uv: Vec2, lod: f32) -> Vec3 {
        let mut e = m.emissive * m.emissive_strength;
        if e != Vec3::ZERO {
            if let Some(t) = self.texture(m.emissive_texture, uv, lod, true) {
                e *= t.truncate();
            }
        }
        e
    }

    /// The material's lobes at `s`: metallic and roughness (textured), Fresnel, and the
    /// reflected, transmitted and diffuse weights.
    fn lobes(&self, m: &Material, s: &Surface, albedo: Vec3) -> Lobes {
        let (mut metallic, mut roughness) = (m.metallic, m.roughness);
        if let Some(t) = self.texture(m.metallic_roughness_texture, s.uv, s.lod, false) {
            metallic *= t.z;
            roughness *= t.y;
        }
        let metallic = metallic.clamp(0.0, 1.0);
        let roughness = roughness.clamp(0.0, 1.0);
        let transmission = (m.transmission.clamp(0.0, 1.0)) * (1.0 - metallic);
        let gloss = (1.0 - roughness) * (1.0 - roughness);
        let v = -s.dir;
        let cos_o = s.ns.dot(v).clamp(0.0, 1.0);
        let f0 = Vec3::splat(0.04).lerp(albedo, metallic);
        let ior = if m.ior.is_finite() && m.ior >= 1.0 {
            m.ior
        } else {
            1.5
        };
        let eta = if s.entering { 1.0 / ior } else { ior };
        // Fresnel: exact dielectric for transmissive surfaces, Schlick otherwise.
        let fresnel = if transmission > 0.0 {
            Vec3::splat(fresnel_dielectric(cos_o, eta))
        } else {
            f0 + (Vec3::ONE - f0) * (1.0 - cos_o).powi(5)
        };
        let reflects = roughness < GLOSSY_LIMIT;
        let alpha = roughness * roughness;
        let kt = (Vec3::ONE - fresnel) * transmission * albedo;
        let (kr, kd) = if reflects {
            (
                fresnel,
                albedo * ((1.0 - metallic) * (1.0 - transmission) * (1.0 - fresnel.max_element())),
            )
        } else {
            (
                Vec3::ZERO,
                albedo
                    * ((1.0 - metallic)
                        * (1.0 - transmission)
                        * (1.0 - fresnel.max_element() * gloss)
                        + metallic * (1.0 - gloss)),
            )
        };
        Lobes {
            roughness,
            gloss,
            glossy_alpha: (reflects && alpha >= MIRROR_ALPHA).then_some(alpha),
            reflects,
            v,
            f0,
            eta,
            kr,
            kt,
            kd,
        }
    }

    /// The Blinn–Phong exponent of the highlight for lights (0: none).
    pub(super) fn shininess(roughness: f32) -> f32 {
        if roughness < 0.9 {
            // Capped: a point light is a delta, and the glint of one on a polished
            // surface would otherwise be a tiny spot of enormous radiance (one that
            // mirrors then multiply around the scene).
            (2.0 / roughness.powi(4).max(1e-4) - 2.0).min(MAX_SHININESS)
        } else {
            0.0
        }
    }

    /// Diffuse plus (when `highlight`) the capped Blinn–Phong glint, for light arriving
    /// from `to_light`.
    #[inline]
    fn brdf(lobes: &Lobes, s: &Surface, to_light: Vec3, highlight: bool) -> Vec3 {
        let mut brdf = lobes.kd * std::f32::consts::FRAC_1_PI;
        if highlight {
            if let Some(g) = Self::glint(lobes, s, to_light) {
                brdf += g;
            }
        }
        brdf
    }

    /// The capped Blinn–Phong glint for light arriving from `to_light`; `None` for a
    /// surface too rough to have one.
    #[inline]
    fn glint(lobes: &Lobes, s: &Surface, to_light: Vec3) -> Option<Vec3> {
        let shininess = Self::shininess(lobes.roughness);
        if shininess <= 0.0 {
            return None;
        }
        let h = (to_light + lobes.v).normalize_or_zero();
        let nh = s.ns.dot(h).max(0.0);
        let norm = (shininess + 8.0) / (8.0 * std::f32::consts::PI);
        Some(lobes.f0 * (1.0 - lobes.gloss * 0.5) * (norm * nh.powf(shininess)).min(1e3))
    }

    /// What light arriving from `to_light` adds, split over the passes (`e`: the
    /// path's weight × the light's irradiance and geometry factors): at a camera ray's
    /// hit (`path` `None`) the diffuse lobe's part is diffuse and the glint's specular;
    /// deeper, both go to the path's pass.
    fn split_light(
        lobes: &Lobes,
        s: &Surface,
        to_light: Vec3,
        highlight: bool,
        e: Vec3,
        path: Option<LightPath>,
    ) -> Split {
        let d = e * (lobes.kd * std::f32::consts::FRAC_1_PI);
        let g = match highlight.then(|| Self::glint(lobes, s, to_light)).flatten() {
            Some(g) => e * g,
            None => Vec3::ZERO,
        };
        match path {
            Some(p) => split_one(p, d + g),
            None => [d, g, Vec3::ZERO, Vec3::ZERO],
        }
    }

    /// A shadow ray towards each light that lights `s` (from `origin`, just off the
    /// surface), carrying what the light would add: diffuse and a capped Blinn-Phong
    /// glint.
    fn direct_light(
        &self,
        s: &Surface,
        lobes: &Lobes,
        weight: Vec3,
        origin: Vec3,
        item: &Item,
        out: &mut BlockOut,
    ) {
        for (li, l) in self.lights.iter().enumerate() {
            let Some((to_light, dist, irradiance)) = light_at(l, origin) else {
                continue;
            };
            let cos_i = s.ns.dot(to_light);
            if cos_i <= 0.0 || s.ng.dot(to_light) <= 0.0 {
                continue;
            }
            let brdf = Self::brdf(lobes, s, to_light, true);
            let c = weight * brdf * irradiance * cos_i;
            if c.max_element() <= MIN_WEIGHT * 1e-2 || !c.is_finite() {
                continue;
            }
            let shadow = if dist.is_finite() {
                Ray::segment(origin, to_light, 0.0, dist * (1.0 - 1e-4))
            } else {
                Ray::new(origin, to_light)
            };
            out.shadow(shadow, li, item.sample, c, || {
                let e = weight * irradiance * cos_i;
                Self::split_light(lobes, s, to_light, true, e, item.path)
            });
        }
    }

    /// `n` shadow rays to points on the emissive triangles (stratified over the
    /// triangle, each triangle drawn by power), each carrying `1/n` of its estimate.
    #[allow(clippy::too_many_arguments)]
    fn area_light(
        &self,
        s: &Surface,
        lobes: &Lobes,
        weight: Vec3,
        origin: Vec3,
        item: &Item,
        n: u32,
        spp: u32,
        out: &mut BlockOut,
    ) {
        // One batch for every area-light shadow ray, after the punctual lights'.
        let batch = self.lights.len();
        // At a camera ray's hit the pixel's `spp · n` samples share one stratification
        // (jittered: cell `j·spp + k` for light sample `j` of pixel sample `k`), and
        // the emitter choice is stratified too, over the cells in a scrambled order, so
        // the pick and the point do not go together.
        let (k, cells) = if item.depth == 0 {
            (item.sample % spp.max(1), n * spp.max(1))
        } else {
            (0, n)
        };
        for j in 0..n {
            let cell = j * (cells / n) + k;
            let rp = item.seed.get(Purpose::AreaLight, 2 * j);
            let scrambled = if cells % 7919 == 0 {
                cell as f32
            } else {
                (u64::from(cell) * 7919 % u64::from(cells)) as f32
            };
            let pick = ((scrambled + rp.x) / cells as f32).min(0.999_999_9);
            let r = stratified(cell, cells, item.seed.get(Purpose::AreaLight, 2 * j + 1));
            let Some(lp) = self.area.sample(pick, r) else {
                continue;
            };
            if lp.tri == s.tri {
                continue;
            }
            let d = lp.point - origin;
            let d2 = d.length_squared();
            if !(d2 > 0.0 && d2.is_finite()) {
                continue;
            }
            let dist = d2.sqrt();
            let to = d / dist;
            let cos_i = s.ns.dot(to);
            if cos_i <= 0.0 || s.ng.dot(to) <= 0.0 {
                continue;
            }
            let mut cos_l = -lp.normal.dot(to);
            if lp.two_sided {
                cos_l = cos_l.abs();
            }
            if cos_l <= 0.0 {
                continue;
            }
            let Some(m) = self.material(lp.material) else {
                continue;
            };
            let le = self.emission(m, self.uv_at(lp.tri, lp.bary), f32::NEG_INFINITY);
            let brdf = Self::brdf(lobes, s, to, !lobes.reflects);
            let c = weight * brdf * le * (cos_i * cos_l / (d2 * lp.pdf_area * n as f32));
            if c.max_element() <= MIN_WEIGHT * 1e-2 || !c.is_finite() {
                continue;
            }
            out.shadow(
                Ray::segment(origin, to, 0.0, dist * (1.0 - 1e-3)),
                batch,
                item.sample,
                c,
                || {
                    let e = weight * le * (cos_i * cos_l / (d2 * lp.pdf_area * n as f32));
                    Self::split_light(lobes, s, to, !lobes.reflects, e, item.path)
                },
            );
        }
    }

    /// Texture coordinates at barycentrics `b` of hit number `tri`.
    fn uv_at(&self, tri: u32, b: Vec2) -> Vec2 {
        let uvs = match Prim::from_index(tri, self.static_soup.len()) {
            Prim::Static(i) => self.static_soup.uvs.get(i as usize),
            Prim::Moving(i) => self.dynamic_soup.uvs.get(i as usize),
        };
        uvs.map_or(Vec2::ZERO, |t| {
            t[0] * (1.0 - b.x - b.y) + t[1] * b.x + t[2] * b.y
        })
    }
}

/// What a surface's material makes of light, as [`ShadeContext::lobes`] finds it.
#[derive(Clone, Copy)]
struct Lobes {
    roughness: f32,
    gloss: f32,
    /// GGX width of the reflection lobe; `None` for a mirror or no reflection ray.
    glossy_alpha: Option<f32>,
    /// Whether a reflection ray is traced (roughness under [`GLOSSY_LIMIT`]).
    reflects: bool,
    /// Towards the viewer.
    v: Vec3,
    f0: Vec3,
    /// The ratio of the indices of refraction across the surface, as the ray crosses it.
    eta: f32,
    /// Reflected, transmitted and diffuse weights.
    kr: Vec3,
    kt: Vec3,
    kd: Vec3,
}

/// The material's coverage at a point of base colour `base`.
fn alpha_of(m: &Material, base: Vec4) -> f32 {
    match m.alpha_mode {
        AlphaMode::Opaque => 1.0,
        AlphaMode::Mask { cutoff } => {
            if base.w >= cutoff {
                1.0
            } else {
                0.0
            }
        }
        AlphaMode::Blend => base.w.clamp(0.0, 1.0),
    }
}

/// On through a surface of coverage `alpha`, same direction, same depth.
fn pass_through(s: &Surface, item: &Item, alpha: f32, eps: f32, cone: Cone, out: &mut BlockOut) {
    let w = item.weight * (1.0 - alpha);
    if w.max_element() > MIN_WEIGHT || item.coverage > 0.0 {
        out.next(
            Ray::new(s.point - s.ng * eps, s.dir),
            Item {
                sample: item.sample,
                weight: w,
                coverage: item.coverage * (1.0 - alpha),
                depth: item.depth,
                passes: item.passes + 1,
                bounces: item.bounces,
                diffuse: item.diffuse,
                seed: item.seed.child(2),
                cone,
                path: item.path,
            },
        );
    }
}

/// The direction towards light `l` from `origin`, its distance (infinite for a
/// directional light) and the irradiance it brings there (range and cone applied);
/// `None` at the light itself or where the numbers overflow.
fn light_at(l: &PreLight, origin: Vec3) -> Option<(Vec3, f32, Vec3)> {
    Some(match l.kind {
        LightKind::Directional => (-l.direction, f32::INFINITY, l.power),
        LightKind::Point | LightKind::Spot { .. } => {
            let d = l.position - origin;
            let d2 = d.length_squared();
            if d2 <= 0.0 || !d2.is_finite() {
                return None;
            }
            let dist = d2.sqrt();
            let mut att = match l.falloff {
                Falloff::None => 1.0,
                Falloff::InverseSquare => 1.0 / d2,
            };
            if let Some(r) = l.range {
                att *= (1.0 - (dist / r).powi(4)).clamp(0.0, 1.0).powi(2);
            }
            let to = d / dist;
            if let LightKind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } = l.kind
            {
                let (ci, co) = (inner_cone_angle.cos(), outer_cone_angle.cos());
                let scale = 1.0 / (ci - co).max(1e-3);
                let cd = l.direction.dot(-to);
                att *= ((cd - co) * scale).clamp(0.0, 1.0).powi(2);
            }
            (to, dist, l.power * att)
        }
    })
}

/// The refracted ray (or, on total internal reflection, more weight for the reflected
/// one) and the reflected ray (mirror, or drawn from the GGX lobe), one level deeper.
#[allow(clippy::too_many_arguments)]
fn secondary(
    s: &Surface,
    lobes: &Lobes,
    item: &Item,
    weight: Vec3,
    eps: f32,
    origin: Vec3,
    cone: Cone,
    out: &mut BlockOut,
) {
    let (eta, kt, mut kr) = (lobes.eta, lobes.kt, lobes.kr);
    let next = |w: Vec3, kind: u64, spread: f32| Item {
        sample: item.sample,
        weight: w,
        coverage: 0.0,
        depth: item.depth + 1,
        passes: item.passes,
        bounces: item.bounces,
        diffuse: false,
        seed: item.seed.child(kind),
        cone: Cone {
            width: cone.width,
            spread,
        },
        // At the camera ray's hit the event names the pass (kind 1: refraction).
        path: item.path.or(Some(if kind == 1 {
            LightPath::Transmission
        } else {
            LightPath::Specular
        })),
    };
    // Refraction (or total internal reflection, which adds to the reflected ray).
    let kt_w = weight * kt;
    if kt_w.max_element() > MIN_WEIGHT {
        match refract(s.dir, s.ns, eta).or_else(|| refract(s.dir, s.ng, eta)) {
            Some(t) if t.dot(s.ng) < 0.0 => {
                out.next(
                    Ray::new(s.point - s.ng * eps, t),
                    next(kt_w, 1, cone.spread),
                );
            }
            _ => kr += kt,
        }
    }
    let kr_w = weight * kr;
    if kr_w.max_element() <= MIN_WEIGHT {
        return;
    }
    match lobes.glossy_alpha {
        None => {
            let mut r = reflect(s.dir, s.ns);
            if r.dot(s.ng) <= 0.0 {
                r = reflect(s.dir, s.ng);
            }
            out.next(Ray::new(origin, r), next(kr_w, 0, cone.spread));
        }
        Some(alpha) => {
            // One direction from the visible normals: the estimator's weight is
            // F · G2/G1(v), with Smith's separable G2 that is F · G1(l).
            let m = sample_ggx_vndf(lobes.v, s.ns, alpha, item.seed.get(Purpose::Glossy, 0));
            let r = reflect(s.dir, m);
            let cos_l = r.dot(s.ns);
            if cos_l <= 0.0 || r.dot(s.ng) <= 0.0 {
                return; // into the surface: this sample reflects nothing
            }
            let w = kr_w * smith_g1(cos_l, alpha);
            if w.max_element() > MIN_WEIGHT {
                // The lobe's width widens the cone (for the texture level of detail).
                out.next(Ray::new(origin, r), next(w, 0, cone.spread + alpha));
            }
        }
    }
}

/// One cosine-weighted diffuse bounce (`--diffuse-bounces`): with the Lambertian BRDF
/// `kd / π` and the density `cos / π` the estimator's weight is `kd` itself. The ray
/// carries on to its hit's shadow rays (next-event estimation), so it adds no emission of
/// its own (`Item::diffuse`); where it leaves the scene it sees the background or the
/// environment, which is how they light the scene.
fn diffuse_bounce(
    s: &Surface,
    lobes: &Lobes,
    item: &Item,
    weight: Vec3,
    origin: Vec3,
    cone: Cone,
    out: &mut BlockOut,
) {
    let w = weight * lobes.kd;
    if w.max_element() <= MIN_WEIGHT {
        return;
    }
    let dir = sample_cosine(s.ns, item.seed.get(Purpose::Diffuse, 0));
    if dir.dot(s.ng) <= 0.0 {
        return; // below the geometric surface (a bent shading normal): no light there
    }
    out.next(
        Ray::new(origin, dir),
        Item {
            sample: item.sample,
            weight: w,
            coverage: 0.0,
            depth: item.depth + 1,
            passes: item.passes,
            bounces: item.bounces + 1,
            diffuse: true,
            seed: item.seed.child(3),
            // A diffuse lobe spreads over the hemisphere: the coarsest texture level.
            cone: Cone {
                width: cone.width,
                spread: 1.0,
            },
            path: item.path.or(Some(LightPath::Diffuse)),
        },
    );
}

fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Refraction of unit `d` through unit `n` (facing against `d`), `eta = n1 / n2`;
/// `None` on total internal reflection.
fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -d.dot(n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return None;
    }
    Some((eta * d + (eta * cos_i - k.sqrt()) * n).normalize_or_zero())
}

/// Unpolarised Fresnel reflectance of a dielectric; `eta = n1 / n2`; 1 on total
/// internal reflection.
fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let sin_t2 = eta * eta * (1.0 - cos_i * cos_i);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    (0.5 * (rs * rs + rp * rp)).clamp(0.0, 1.0)
}

struct Surface {
    point: Vec3,
    /// Geometric normal, facing the incoming ray.
    ng: Vec3,
    /// Shading normal, on the side of `ng`.
    ns: Vec3,
    /// Unit ray direction.
    dir: Vec3,
    entering: bool,
    uv: Vec2,
    /// Texture level of detail for a unit texture: a `w × h` texture adds
    /// `log2(√(w·h))`; `-∞` for the finest level.
    lod: f32,
    material: u32,
    /// Hit number of the triangle.
    tri: u32,
}

/// A ray's bookkeeping: which sample it adds to, with what weight.
#[derive(Clone, Copy, Debug)]
pub(super) struct Item {
    pub(super) sample: u32,
    pub(super) weight: Vec3,
    /// Share of the sample's coverage (alpha) this ray decides (primary rays and their
    /// pass-through continuations; 0 for secondary rays).
    pub(super) coverage: f32,
    pub(super) depth: u32,
    pub(super) passes: u16,
    /// Diffuse bounces taken on the way to this ray (`--diffuse-bounces`).
    pub(super) bounces: u8,
    /// The ray leaves a diffuse bounce: what it meets of the emitters was counted by the
    /// bounce's own shadow rays to them, so it adds no emission (no double counting).
    pub(super) diffuse: bool,
    /// The ray's own random numbers.
    pub(super) seed: Seed,
    pub(super) cone: Cone,
    /// The light-path pass this ray's light goes to; `None` for a camera ray (and its
    /// pass-through continuations) until its hit decides (see [`LightPath`]).
    pub(super) path: Option<LightPath>,
}

/// A block's shadow rays towards one light, each with what it adds to which sample
/// when unblocked.
#[derive(Default)]
pub(super) struct ShadowList {
    pub(super) rays: Vec<Ray>,
    pub(super) add: Vec<(u32, Vec3)>,
    /// `add`'s contributions split over the light-path passes (only when
    /// [`BlockOut::light_paths`]).
    pub(super) split: Vec<Split>,
}

#[derive(Default)]
pub(super) struct BlockOut {
    /// Whether the light-path passes are traced: then every contribution also goes,
    /// split, to `split` (and the shadow lists' `split`).
    pub(super) light_paths: bool,
    pub(super) add: Vec<(u32, Vec3)>,
    pub(super) split: Vec<(u32, Split)>,
    pub(super) cover: Vec<(u32, f32)>,
    /// The shadow rays a light at a time (index: the light's batch, see
    /// [`ShadeContext::shade`]'s lights and the area lights' batch after them).
    pub(super) shadow: Vec<ShadowList>,
    pub(super) next_rays: Vec<Ray>,
    pub(super) next_items: Vec<Item>,
}

impl BlockOut {
    /// Empties every list, keeping their capacity (a frame's blocks are reused).
    pub(super) fn clear(&mut self) {
        self.add.clear();
        self.split.clear();
        self.cover.clear();
        for l in &mut self.shadow {
            l.rays.clear();
            l.add.clear();
            l.split.clear();
        }
        self.next_rays.clear();
        self.next_items.clear();
    }

    /// `c` to the beauty of `sample` and, when the passes are traced, `split()` (`c`
    /// split over them) to the passes; nothing when `c` is 0 or not finite.
    #[inline]
    fn add_split(&mut self, sample: u32, c: Vec3, split: impl FnOnce() -> Split) {
        if c != Vec3::ZERO && c.is_finite() {
            self.add.push((sample, c));
            if self.light_paths {
                self.split.push((sample, split()));
            }
        }
    }
    fn cover(&mut self, sample: u32, c: f32) {
        if c > 0.0 {
            self.cover.push((sample, c));
        }
    }
    /// A shadow ray towards batch `light` that adds `c` (split: `split()`) to `sample`
    /// when unblocked.
    #[inline]
    fn shadow(
        &mut self,
        ray: Ray,
        light: usize,
        sample: u32,
        c: Vec3,
        split: impl FnOnce() -> Split,
    ) {
        if self.shadow.len() <= light {
            self.shadow.resize_with(light + 1, ShadowList::default);
        }
        let l = &mut self.shadow[light];
        l.rays.push(ray);
        l.add.push((sample, c));
        if self.light_paths {
            l.split.push(split());
        }
    }
    fn next(&mut self, ray: Ray, item: Item) {
        self.next_rays.push(ray);
        self.next_items.push(item);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refraction_and_fresnel() {
        let n = Vec3::Y;
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        // Into glass: bends towards the normal (Snell).
        let t = refract(d, n, 1.0 / 1.5).unwrap();
        let sin_t = t.x;
        assert!((sin_t - d.x / 1.5).abs() < 1e-6);
        // Out of glass at 45°: total internal reflection (critical angle 41.8°).
        assert!(refract(d, n, 1.5).is_none());
        assert_eq!(fresnel_dielectric(d.dot(-n).abs(), 1.5), 1.0);
        // Normal incidence: ((n1-n2)/(n1+n2))^2 = 0.04.
        assert!((fresnel_dielectric(1.0, 1.0 / 1.5) - 0.04).abs() < 1e-6);
        assert!(reflect(d, n).abs_diff_eq(Vec3::new(d.x, -d.y, 0.0), 1e-6));
    }
}
