//! Whitted shading, traced as a wavefront: every ray of a depth level is traced as one
//! batch through the [`Intersector`] (closest hits), then shaded in parallel, which
//! yields shadow rays (one per light that faces the point, any-hit batch) and the
//! next level's rays (mirror reflection, refraction, and the continuation through
//! alpha-cut or blended surfaces). Tracing and shading are timed apart.
//!
//! Determinism: rays sit in arrays in a fixed order; each block of rays is shaded by one
//! task into its own lists, blocks are merged in order, and contributions are added to
//! their sample one after the other in array order. Jitter comes from a hash of (frame,
//! pixel, sample). Nothing depends on the thread count.
//!
//! Model (linear RGB; `KHR_lights_punctual` units): base colour = factor × texture
//! (sRGB texels linearised before bilinear filtering); `F0 = mix(0.04, base, metallic)`;
//! gloss `g = (1 − roughness)²`; mirror weight `F·g` (Schlick; exact dielectric Fresnel
//! with the material's IOR for transmissive surfaces); refraction weight
//! `(1 − F)·transmission·(1 − metallic)·base` (total internal reflection goes to the
//! mirror ray); diffuse colour `base·((1 − metallic)(1 − transmission)(1 − F·g) +
//! metallic·(1 − g))` (a rough metal's glossy lobe stands in as diffuse, since Whitted
//! has no glossy rays), lit by every light through a shadow ray as `kd/π·E·cos`, plus a
//! normalised Blinn–Phong highlight for the lights (exponent `2/r⁴ − 2`, at most 256), an ambient term `kd·ambient` and the
//! emission `emissive·strength·texture`. Irradiance: directional `E = intensity`
//! (lux), point and spot `E = intensity/d²` (candela) with the spec's range window and
//! spot cone falloff.

use std::time::Duration;

use glam::{Vec2, Vec3, Vec4};

use super::camera::CameraModel;
use super::options::ShadingOptions;
use crate::geometry::{Hit, Ray};
use crate::psf::Prim;
use crate::scene::{AlphaMode, Light, LightKind, Material, Scene, TextureRef, TriangleSoup, Wrap};

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
struct PreLight {
    kind: LightKind,
    /// Colour × intensity.
    power: Vec3,
    position: Vec3,
    /// Unit direction the light shines along.
    direction: Vec3,
    range: Option<f32>,
}

/// Everything shading reads during one frame.
pub struct ShadeContext<'a> {
    pub scene: &'a Scene,
    pub static_soup: &'a TriangleSoup,
    pub dynamic_soup: &'a TriangleSoup,
    pub options: ShadingOptions,
    /// Size of the scene (bounding box diagonal), for ray offsets.
    pub extent: f32,
    lights: Vec<PreLight>,
    lut: [f32; 256],
}

/// Passes through alpha-cut surfaces a ray may make.
const MAX_PASSES: u16 = 16;
/// Contributions below this (max component of the weight) are dropped.
const MIN_WEIGHT: f32 = 1e-4;
/// Largest Blinn–Phong exponent (roughness below about 0.3 gets this).
const MAX_SHININESS: f32 = 256.0;

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

impl<'a> ShadeContext<'a> {
    /// `lights` posed for this frame; an empty list gets the default light when the
    /// options ask for it (placed relative to `camera`).
    pub fn new(
        scene: &'a Scene,
        static_soup: &'a TriangleSoup,
        dynamic_soup: &'a TriangleSoup,
        lights: &[Light],
        camera: &CameraModel,
        options: ShadingOptions,
        extent: f32,
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
            })
            .collect();
        if lights.is_empty() && options.default_light {
            let towards = (camera.rotation * Vec3::new(-0.4, 0.6, 0.7)).normalize_or_zero();
            pre.push(PreLight {
                kind: LightKind::Directional,
                power: Vec3::splat(std::f32::consts::PI),
                position: camera.origin,
                direction: -towards,
                range: None,
            });
        }
        let mut lut = [0.0; 256];
        for (i, v) in lut.iter_mut().enumerate() {
            *v = srgb_to_linear(i as f32 / 255.0);
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
            lut,
        }
    }

    fn material(&self, i: u32) -> Option<&Material> {
        self.scene.materials.get(i as usize)
    }

    /// Samples a texture (RGBA, linearised RGB when `srgb`), or `None` without one.
    fn texture(&self, slot: Option<TextureRef>, uv: Vec2, srgb: bool) -> Option<Vec4> {
        let slot = slot?;
        let tex = self.scene.textures.get(slot.texture as usize)?;
        let img = self.scene.images.get(tex.image as usize)?;
        let (w, h) = (img.width as i64, img.height as i64);
        if w == 0 || h == 0 || img.rgba8.len() as i64 != w * h * 4 {
            return None;
        }
        let uv = slot.transform.map_or(uv, |t| t.apply(uv));
        let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
        let fetch = |x: i64, y: i64| -> Vec4 {
            let x = wrap(x, w, tex.wrap_s);
            let y = wrap(y, h, tex.wrap_t);
            let at = ((y * w + x) * 4) as usize;
            match img.rgba8.get(at..at + 4) {
                Some(p) => {
                    let c = |b: u8| {
                        if srgb {
                            self.lut[b as usize]
                        } else {
                            b as f32 / 255.0
                        }
                    };
                    Vec4::new(c(p[0]), c(p[1]), c(p[2]), p[3] as f32 / 255.0)
                }
                None => Vec4::ONE,
            }
        };
        let x = uv.x as f64 * w as f64;
        let y = uv.y as f64 * h as f64;
        if tex.nearest {
            return Some(fetch(x.floor() as i64, y.floor() as i64));
        }
        let (x, y) = (x - 0.5, y - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = fetch(x0, y0).lerp(fetch(x0 + 1, y0), fx);
        let bottom = fetch(x0, y0 + 1).lerp(fetch(x0 + 1, y0 + 1), fx);
        Some(top.lerp(bottom, fy))
    }

    /// Geometry at a hit, `None` for a triangle index out of range.
    fn surface(&self, ray: &Ray, hit: &Hit) -> Option<Surface> {
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
        let mut ng = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        let dir = ray.dir.normalize_or_zero();
        if ng == Vec3::ZERO {
            ng = -dir;
        }
        // `entering`: the ray meets the side the winding makes the front.
        let entering = ng.dot(dir) < 0.0;
        if !entering {
            ng = -ng;
        }
        let mut ns = nrm
            .map(|n| (n[0] * w + n[1] * u + n[2] * v).normalize_or_zero())
            .unwrap_or(Vec3::ZERO);
        if ns == Vec3::ZERO || !ns.is_finite() {
            ns = ng;
        } else if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        let uv = uvs.map_or(Vec2::ZERO, |t| t[0] * w + t[1] * u + t[2] * v);
        Some(Surface {
            point,
            ng,
            ns,
            dir,
            entering,
            uv,
            material,
        })
    }

    /// Base colour (factor × texture) at a surface.
    fn base_color(&self, m: &Material, uv: Vec2) -> Vec4 {
        match self.texture(m.base_color_texture, uv, true) {
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
        let Some(s) = self.surface(ray, hit) else {
            return CentreAov::default();
        };
        let albedo = self
            .material(s.material)
            .map_or(Vec3::ONE, |m| self.base_color(m, s.uv).truncate());
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
    /// surface not wholly opaque, emission and ambient, shadow rays to the lights, and
    /// the refracted and mirror rays.
    pub(super) fn shade(
        &self,
        ray: &Ray,
        item: &Item,
        hit: Option<Hit>,
        max_depth: u32,
        out: &mut BlockOut,
    ) {
        let Some(hit) = hit else {
            out.add(item.sample, item.weight * self.options.background);
            return;
        };
        let Some(s) = self.surface(ray, &hit) else {
            return;
        };
        let default = Material::default();
        let m = self.material(s.material).unwrap_or(&default);
        let base = self.base_color(m, s.uv);
        let alpha = alpha_of(m, base);
        let eps = self.eps(s.point);
        if alpha < 1.0 && item.passes < MAX_PASSES {
            pass_through(&s, item, alpha, eps, out);
        }
        if alpha <= 0.0 {
            return;
        }
        out.cover(item.sample, item.coverage * alpha);
        let weight = item.weight * alpha;
        let lobes = self.lobes(m, &s, base.truncate());

        // Emission and ambient.
        let mut emitted = m.emissive * m.emissive_strength;
        if emitted != Vec3::ZERO {
            if let Some(t) = self.texture(m.emissive_texture, s.uv, true) {
                emitted *= t.truncate();
            }
        }
        out.add(
            item.sample,
            weight * (emitted + lobes.kd * self.options.ambient),
        );

        // Direct light through shadow rays.
        let origin = s.point + s.ng * eps;
        self.direct_light(&s, &lobes, weight, origin, item.sample, out);

        if item.depth >= max_depth {
            return;
        }
        secondary(&s, &lobes, item, weight, eps, origin, out);
    }

    /// The material's lobes at `s`: metallic and roughness (textured), Fresnel, and the
    /// mirror, transmitted and diffuse weights.
    fn lobes(&self, m: &Material, s: &Surface, albedo: Vec3) -> Lobes {
        let (mut metallic, mut roughness) = (m.metallic, m.roughness);
        if let Some(t) = self.texture(m.metallic_roughness_texture, s.uv, false) {
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
        let kr = fresnel * gloss;
        let kt = (Vec3::ONE - fresnel) * transmission * albedo;
        let kd = albedo
            * ((1.0 - metallic) * (1.0 - transmission) * (1.0 - fresnel.max_element() * gloss)
                + metallic * (1.0 - gloss));
        Lobes {
            roughness,
            gloss,
            v,
            f0,
            eta,
            kr,
            kt,
            kd,
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
        sample: u32,
        out: &mut BlockOut,
    ) {
        let Lobes {
            roughness,
            gloss,
            v,
            f0,
            kd,
            ..
        } = *lobes;
        let shininess = if roughness < 0.9 {
            // Capped: a point light is a delta, and the glint of one on a polished
            // surface would otherwise be a tiny spot of enormous radiance (one that
            // mirrors then multiply around the scene).
            (2.0 / roughness.powi(4).max(1e-4) - 2.0).min(MAX_SHININESS)
        } else {
            0.0
        };
        for (li, l) in self.lights.iter().enumerate() {
            let Some((to_light, dist, irradiance)) = light_at(l, origin) else {
                continue;
            };
            let cos_i = s.ns.dot(to_light);
            if cos_i <= 0.0 || s.ng.dot(to_light) <= 0.0 {
                continue;
            }
            let mut brdf = kd * std::f32::consts::FRAC_1_PI;
            if shininess > 0.0 {
                let h = (to_light + v).normalize_or_zero();
                let nh = s.ns.dot(h).max(0.0);
                let norm = (shininess + 8.0) / (8.0 * std::f32::consts::PI);
                brdf += f0 * (1.0 - gloss * 0.5) * (norm * nh.powf(shininess)).min(1e3);
            }
            let c = weight * brdf * irradiance * cos_i;
            if c.max_element() <= MIN_WEIGHT * 1e-2 || !c.is_finite() {
                continue;
            }
            let shadow = if dist.is_finite() {
                Ray::segment(origin, to_light, 0.0, dist * (1.0 - 1e-4))
            } else {
                Ray::new(origin, to_light)
            };
            out.shadow(shadow, li, sample, c);
        }
    }
}

/// What a surface's material makes of light, as [`ShadeContext::lobes`] finds it.
#[derive(Clone, Copy)]
struct Lobes {
    roughness: f32,
    gloss: f32,
    /// Towards the viewer.
    v: Vec3,
    f0: Vec3,
    /// The ratio of the indices of refraction across the surface, as the ray crosses it.
    eta: f32,
    /// Mirror, transmitted and diffuse weights.
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
fn pass_through(s: &Surface, item: &Item, alpha: f32, eps: f32, out: &mut BlockOut) {
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
            let mut att = 1.0 / d2;
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

/// The refracted ray (or, on total internal reflection, more weight for the mirror)
/// and the mirror ray, one level deeper.
fn secondary(
    s: &Surface,
    lobes: &Lobes,
    item: &Item,
    weight: Vec3,
    eps: f32,
    origin: Vec3,
    out: &mut BlockOut,
) {
    let (eta, kt, mut kr) = (lobes.eta, lobes.kt, lobes.kr);
    let next = |w: Vec3| Item {
        sample: item.sample,
        weight: w,
        coverage: 0.0,
        depth: item.depth + 1,
        passes: item.passes,
    };
    // Refraction (or total internal reflection, which adds to the mirror ray).
    let kt_w = weight * kt;
    if kt_w.max_element() > MIN_WEIGHT {
        match refract(s.dir, s.ns, eta).or_else(|| refract(s.dir, s.ng, eta)) {
            Some(t) if t.dot(s.ng) < 0.0 => {
                out.next(Ray::new(s.point - s.ng * eps, t), next(kt_w));
            }
            _ => kr += kt,
        }
    }
    let kr_w = weight * kr;
    if kr_w.max_element() > MIN_WEIGHT {
        let mut r = reflect(s.dir, s.ns);
        if r.dot(s.ng) <= 0.0 {
            r = reflect(s.dir, s.ng);
        }
        out.next(Ray::new(origin, r), next(kr_w));
    }
}

fn wrap(i: i64, n: i64, mode: Wrap) -> i64 {
    match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m >= n {
                2 * n - 1 - m
            } else {
                m
            }
        }
    }
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
    material: u32,
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
}

#[derive(Default)]
pub(super) struct BlockOut {
    pub(super) add: Vec<(u32, Vec3)>,
    pub(super) cover: Vec<(u32, f32)>,
    pub(super) shadow_rays: Vec<Ray>,
    pub(super) shadow_add: Vec<(u32, Vec3)>,
    /// The light each shadow ray goes to.
    pub(super) shadow_light: Vec<u16>,
    pub(super) next_rays: Vec<Ray>,
    pub(super) next_items: Vec<Item>,
}

impl BlockOut {
    fn add(&mut self, sample: u32, c: Vec3) {
        if c != Vec3::ZERO && c.is_finite() {
            self.add.push((sample, c));
        }
    }
    fn cover(&mut self, sample: u32, c: f32) {
        if c > 0.0 {
            self.cover.push((sample, c));
        }
    }
    fn shadow(&mut self, ray: Ray, light: usize, sample: u32, c: Vec3) {
        self.shadow_rays.push(ray);
        self.shadow_add.push((sample, c));
        self.shadow_light.push(light.min(u16::MAX as usize) as u16);
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

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap(9, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap(8, 4, Wrap::MirroredRepeat), 0);
    }
}
