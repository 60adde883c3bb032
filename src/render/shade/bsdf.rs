//! The material's lobes at a surface (Fresnel, the reflected, transmitted and diffuse
//! weights, the capped Blinn-Phong glint for lights) and the rays they send on: mirror
//! and GGX reflection, refraction, the diffuse bounce, the pass-through of alpha.

use glam::{BVec4A, Vec3, Vec3A, Vec4};

use super::block::{BlockOut, Item};
use super::frame::split_one;
use super::surface::Surface;
use super::{
    Cone, LightPath, ShadeContext, Split, GLOSSY_LIMIT, MAX_SHININESS, MIN_WEIGHT, MIRROR_ALPHA,
};
use crate::geometry::Ray;
use crate::render::sampling::{sample_cosine, sample_ggx_vndf, smith_g1, Purpose, Seed};
use crate::scene::Material;

/// `x` (at least 0) to the whole power `n` by binary exponentiation (the same products
/// in the same order as compiler-rt's `__powisf2`, which `f32::powi` calls, but inlined),
/// with results under `f32::MIN_POSITIVE` flushed to 0: a squaring that would leave the
/// normal range stops the chain, because a product of subnormal floats takes a microcode
/// assist (about a hundred cycles) on x86, and most points are far enough from a light's
/// highlight that `nh^256` underflows (benches/PERF.md, issue 38, round 3).
#[inline(always)]
pub(super) fn powi(mut x: f32, mut n: u32) -> f32 {
    // The square root of `f32::MIN_POSITIVE`, 2^-63: a smaller `x` squares to a subnormal.
    const SQRT_MIN_POSITIVE: f32 = 1.084_202_2e-19;
    let mut r = 1.0;
    loop {
        if n & 1 == 1 {
            r *= x;
        }
        n >>= 1;
        if n == 0 {
            return if r < f32::MIN_POSITIVE { 0.0 } else { r };
        }
        if x < SQRT_MIN_POSITIVE {
            // `x² < MIN_POSITIVE` and `r ≤ 1` (`x < 1` from the start): the result is
            // under the normal range.
            return 0.0;
        }
        x *= x;
    }
}

/// [`powi`] in four lanes with one exponent: each lane's result to the bit. A lane takes
/// the scalar chain's products in its order; where the scalar chain would stop early (its
/// `x` below the square root of `f32::MIN_POSITIVE`) the lane is marked and gives 0, its
/// `x` set to 0 so that no later product is subnormal. The loop stops when every lane
/// is marked. Four hits of one material took four scalar chains, each stopping at its
/// own squaring (`benches/PERF.md`, issue 38, round 20: 7.5 % of the shading's
/// instructions fewer).
#[inline(always)]
pub(super) fn powi4(mut x: Vec4, mut n: u32) -> Vec4 {
    const SQRT_MIN_POSITIVE: f32 = 1.084_202_2e-19;
    let tiny = Vec4::splat(SQRT_MIN_POSITIVE);
    let mut r = Vec4::ONE;
    let mut stopped = BVec4A::splat(false);
    loop {
        if n & 1 == 1 {
            r *= x;
        }
        n >>= 1;
        if n == 0 {
            let under = r.cmplt(Vec4::splat(f32::MIN_POSITIVE)) | stopped;
            return Vec4::select(under, Vec4::ZERO, r);
        }
        stopped |= x.cmplt(tiny);
        if stopped.all() {
            return Vec4::ZERO;
        }
        x = Vec4::select(stopped, Vec4::ZERO, x);
        x *= x;
    }
}

/// Whether a surface of material `m` may reflect through the GGX lobe (a random
/// direction), as [`ShadeContext::lobes`] decides: a roughness texture can only lower the
/// factor's roughness, so with one any factor may.
pub(super) fn may_be_glossy(m: &Material) -> bool {
    if m.metallic_roughness_texture.is_some() {
        return true;
    }
    glossy_alpha(m.roughness.clamp(0.0, 1.0)).is_some()
}

/// The GGX lobe's width `roughness²` where a surface of this (clamped) roughness draws
/// its reflection from the lobe: it reflects (under [`GLOSSY_LIMIT`]) and is no mirror
/// (`roughness²` of at least [`MIRROR_ALPHA`]). The lobes, the four lanes and
/// [`may_be_glossy`] all ask here.
#[inline]
pub(super) fn glossy_alpha(roughness: f32) -> Option<f32> {
    let alpha = roughness * roughness;
    (roughness < GLOSSY_LIMIT && alpha >= MIRROR_ALPHA).then_some(alpha)
}

/// A material's factors as the lobes read them, once any texture has scaled metallic
/// and roughness: both clamped to [0, 1], the transmission (none on a metal), the
/// gloss and the reflectance at normal incidence. The four-lane path
/// (`lanes::PlainMaterial`) works out its constants with it too, so the two agree to
/// the bit.
pub(super) struct Factors {
    pub(super) metallic: f32,
    pub(super) roughness: f32,
    pub(super) transmission: f32,
    pub(super) gloss: f32,
    pub(super) f0: Vec3A,
}

impl Factors {
    #[inline]
    pub(super) fn of(metallic: f32, roughness: f32, transmission: f32, albedo: Vec3A) -> Factors {
        let metallic = metallic.clamp(0.0, 1.0);
        let roughness = roughness.clamp(0.0, 1.0);
        Factors {
            metallic,
            roughness,
            transmission: (transmission.clamp(0.0, 1.0)) * (1.0 - metallic),
            gloss: (1.0 - roughness) * (1.0 - roughness),
            f0: Vec3A::splat(0.04).lerp(albedo, metallic),
        }
    }
}

/// What a surface's material makes of light, as [`ShadeContext::lobes`] finds it.
#[derive(Clone, Copy)]
pub(super) struct Lobes {
    pub(super) roughness: f32,
    pub(super) gloss: f32,
    /// GGX width of the reflection lobe; `None` for a mirror or no reflection ray.
    pub(super) glossy_alpha: Option<f32>,
    /// Whether a reflection ray is traced (roughness under [`GLOSSY_LIMIT`]).
    pub(super) reflects: bool,
    /// Towards the viewer.
    pub(super) v: Vec3A,
    pub(super) f0: Vec3A,
    /// The ratio of the indices of refraction across the surface, as the ray crosses it.
    pub(super) eta: f32,
    /// Reflected, transmitted and diffuse weights.
    pub(super) kr: Vec3A,
    pub(super) kt: Vec3A,
    pub(super) kd: Vec3A,
}

/// On through a surface of coverage `alpha`, same direction, same depth.
pub(super) fn pass_through(
    s: &Surface,
    item: &Item,
    alpha: f32,
    eps: f32,
    cone: Cone,
    out: &mut BlockOut,
) {
    let w = item.weight * (1.0 - alpha);
    if w.max_element() > MIN_WEIGHT || item.coverage > 0.0 {
        out.next(
            Ray::new((s.point - s.ng * eps).into(), s.dir.into()),
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

/// The refracted ray (or, on total internal reflection, more weight for the reflected
/// one) and the reflected ray (mirror, or drawn from the GGX lobe), one level deeper.
#[allow(clippy::too_many_arguments)]
pub(super) fn secondary(
    s: &Surface,
    lobes: &Lobes,
    item: &Item,
    weight: Vec3A,
    eps: f32,
    origin: Vec3A,
    cone: Cone,
    random: bool,
    out: &mut BlockOut,
) {
    let (eta, kt, mut kr) = (lobes.eta, lobes.kt, lobes.kr);
    let next = |w: Vec3A, kind: u64, spread: f32| Item {
        sample: item.sample,
        weight: w.into(),
        coverage: 0.0,
        depth: item.depth + 1,
        passes: item.passes,
        bounces: item.bounces,
        diffuse: false,
        // Derived only when a ray can read it (`ShadeContext::random`).
        seed: if random {
            item.seed.child(kind)
        } else {
            item.seed
        },
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
                    Ray::new((s.point - s.ng * eps).into(), t.into()),
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
            out.next(
                Ray::new(origin.into(), r.into()),
                next(kr_w, 0, cone.spread),
            );
        }
        Some(alpha) => {
            let drawn = glossy_reflection(s.dir, s.ns, s.ng, alpha, item.seed, kr_w);
            if let Some((r, w)) = drawn {
                // The lobe's width widens the cone (for the texture level of detail).
                out.next(
                    Ray::new(origin.into(), r.into()),
                    next(w, 0, cone.spread + alpha),
                );
            }
        }
    }
}

/// A reflection drawn from the GGX lobe of width `alpha` (one direction from the visible
/// normals: the estimator's weight is F · G2/G1(v), with Smith's separable G2 that is
/// F · G1(l)): for a ray of unit direction `dir` (the view `v = -dir`) meeting a surface of
/// shading normal `ns` and geometric normal `ng` (both facing the ray), `seed`'s
/// numbers and the reflected weight `kr_w` (F times the ray's weight), the direction
/// and the weight `kr_w · G1(l)`; `None` where it goes into the surface (this sample
/// reflects nothing) or carries no more than [`MIN_WEIGHT`]. `secondary` and the four
/// lanes (`lanes.rs`) both draw it here, so their bits agree.
#[inline]
pub(super) fn glossy_reflection(
    dir: Vec3A,
    ns: Vec3A,
    ng: Vec3A,
    alpha: f32,
    seed: Seed,
    kr_w: Vec3A,
) -> Option<(Vec3A, Vec3A)> {
    let v = -dir;
    let m = sample_ggx_vndf(v.into(), ns.into(), alpha, seed.get(Purpose::Glossy, 0));
    let r = reflect(dir, m.into());
    let cos_l = r.dot(ns);
    if cos_l <= 0.0 || r.dot(ng) <= 0.0 {
        return None;
    }
    let w = kr_w * smith_g1(cos_l, alpha);
    (w.max_element() > MIN_WEIGHT).then_some((r, w))
}

/// One cosine-weighted diffuse bounce (`--diffuse-bounces`): with the Lambertian BRDF
/// `kd / π` and the density `cos / π` the estimator's weight is `kd` itself. The ray
/// carries on to its hit's shadow rays (next-event estimation), so it adds no emission of
/// its own (`Item::diffuse`); where it leaves the scene it sees the background or the
/// environment, which is how they light the scene.
pub(super) fn diffuse_bounce(
    s: &Surface,
    lobes: &Lobes,
    item: &Item,
    weight: Vec3A,
    origin: Vec3A,
    cone: Cone,
    out: &mut BlockOut,
) {
    let w = weight * lobes.kd;
    if w.max_element() <= MIN_WEIGHT {
        return;
    }
    let dir = Vec3A::from(sample_cosine(
        s.ns.into(),
        item.seed.get(Purpose::Diffuse, 0),
    ));
    if dir.dot(s.ng) <= 0.0 {
        return; // below the geometric surface (a bent shading normal): no light there
    }
    out.next(
        Ray::new(origin.into(), dir.into()),
        Item {
            sample: item.sample,
            weight: w.into(),
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

pub(super) fn reflect(d: Vec3A, n: Vec3A) -> Vec3A {
    d - 2.0 * d.dot(n) * n
}

/// Refraction of unit `d` through unit `n` (facing against `d`), `eta = n1 / n2`;
/// `None` on total internal reflection.
pub(super) fn refract(d: Vec3A, n: Vec3A, eta: f32) -> Option<Vec3A> {
    let cos_i = -d.dot(n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return None;
    }
    Some((eta * d + (eta * cos_i - k.sqrt()) * n).normalize_or_zero())
}

/// Unpolarised Fresnel reflectance of a dielectric; `eta = n1 / n2`; 1 on total
/// internal reflection.
pub(super) fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let sin_t2 = eta * eta * (1.0 - cos_i * cos_i);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    (0.5 * (rs * rs + rp * rp)).clamp(0.0, 1.0)
}

impl ShadeContext<'_> {
    /// The material's lobes at `s`: metallic and roughness (textured), Fresnel, and the
    /// reflected, transmitted and diffuse weights.
    pub(super) fn lobes(&self, m: &Material, s: &Surface, albedo: Vec3A) -> Lobes {
        let (mut metallic, mut roughness) = (m.metallic, m.roughness);
        if let Some(t) = self.texture(m.metallic_roughness_texture, s.uv, s.lod, false) {
            metallic *= t.z;
            roughness *= t.y;
        }
        let Factors {
            metallic,
            roughness,
            transmission,
            gloss,
            f0,
        } = Factors::of(metallic, roughness, m.transmission, albedo);
        let v = -s.dir;
        let cos_o = s.ns.dot(v).clamp(0.0, 1.0);
        let ior = if m.ior.is_finite() && m.ior >= 1.0 {
            m.ior
        } else {
            1.5
        };
        let eta = if s.entering { 1.0 / ior } else { ior };
        // Fresnel: exact dielectric for transmissive surfaces, Schlick otherwise.
        let fresnel = if transmission > 0.0 {
            Vec3A::splat(fresnel_dielectric(cos_o, eta))
        } else {
            // `x⁵` as `f32::powi(x, 5)` multiplies, inlined (it was a call).
            let x = 1.0 - cos_o;
            let x2 = x * x;
            f0 + (Vec3A::ONE - f0) * (x * (x2 * x2))
        };
        let reflects = roughness < GLOSSY_LIMIT;
        let kt = (Vec3A::ONE - fresnel) * transmission * albedo;
        let (kr, kd) = if reflects {
            (
                fresnel,
                albedo * ((1.0 - metallic) * (1.0 - transmission) * (1.0 - fresnel.max_element())),
            )
        } else {
            (
                Vec3A::ZERO,
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
            glossy_alpha: glossy_alpha(roughness),
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
    pub(in crate::render) fn shininess(roughness: f32) -> f32 {
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
    pub(super) fn brdf(lobes: &Lobes, s: &Surface, to_light: Vec3A, highlight: bool) -> Vec3A {
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
    pub(super) fn glint(lobes: &Lobes, s: &Surface, to_light: Vec3A) -> Option<Vec3A> {
        let shininess = Self::shininess(lobes.roughness);
        if shininess <= 0.0 {
            return None;
        }
        let h = (to_light + lobes.v).normalize_or_zero();
        let nh = s.ns.dot(h).max(0.0);
        let norm = (shininess + 8.0) / (8.0 * std::f32::consts::PI);
        // A whole exponent (a polished surface's is the cap, 256) by repeated squaring,
        // inlined: libm's `powf` was a tenth of the shading, half of that its slow path
        // for results that underflow, and `f32::powi` a call (benches/PERF.md, issue 38).
        // `shininess` lies in (0, 256]: it is whole exactly when it comes back from
        // `u32` unchanged (`fract` was a call to libm's `trunc` on every glint).
        let whole = shininess as u32;
        let lobe = if whole as f32 == shininess {
            powi(nh, whole)
        } else {
            nh.powf(shininess)
        };
        Some(lobes.f0 * (1.0 - lobes.gloss * 0.5) * (norm * lobe).min(1e3))
    }

    /// What light arriving from `to_light` adds, split over the passes (`e`: the
    /// path's weight × the light's irradiance and geometry factors): at a camera ray's
    /// hit (`path` `None`) the diffuse lobe's part is diffuse and the glint's specular;
    /// deeper, both go to the path's pass.
    pub(super) fn split_light(
        lobes: &Lobes,
        s: &Surface,
        to_light: Vec3A,
        highlight: bool,
        e: Vec3A,
        path: Option<LightPath>,
    ) -> Split {
        let d = e * (lobes.kd * std::f32::consts::FRAC_1_PI);
        let g = match highlight.then(|| Self::glint(lobes, s, to_light)).flatten() {
            Some(g) => e * g,
            None => Vec3A::ZERO,
        };
        match path {
            Some(p) => split_one(p, (d + g).into()),
            None => [d.into(), g.into(), Vec3::ZERO, Vec3::ZERO],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn powi_is_the_library_power_to_the_bit_in_the_normal_range() {
        for n in [0u32, 1, 2, 5, 7, 64, 255, 256] {
            for x in [0.0f32, 0.3, 0.5, 0.71, 0.72, 0.9, 0.999_9, 1.0, 1.5] {
                let n_ = std::hint::black_box(n as i32);
                let lib = x.powi(n_);
                let want = if lib < f32::MIN_POSITIVE { 0.0 } else { lib };
                assert_eq!(powi(x, n).to_bits(), want.to_bits(), "{x}^{n}");
            }
        }
        // Near the edge of the normal range, where a subnormal is flushed to 0.
        for i in 0..2000u32 {
            let x = 0.70 + i as f32 * 1e-5;
            let lib = x.powi(std::hint::black_box(256));
            let want = if lib < f32::MIN_POSITIVE { 0.0 } else { lib };
            assert_eq!(powi(x, 256).to_bits(), want.to_bits(), "{x}^256");
        }
    }

    #[test]
    fn powi4_is_powi_in_each_lane() {
        // Values around 1, in the middle of the range, near the edge of the normal
        // range for each exponent, and 0; every exponent up to the cap and past it.
        let mut xs = vec![
            0.0f32, 1e-30, 1e-19, 1.1e-19, 0.3, 0.5, 0.70, 0.71, 0.72, 0.9,
        ];
        xs.extend([0.95, 0.999, 0.999_9, 1.0, 1.5, 2.0]);
        for i in 0..400u32 {
            xs.push(0.69 + i as f32 * 7.5e-5);
            xs.push(i as f32 / 400.0);
        }
        for n in (0u32..=300).chain([511, 512, 1000, 4096]) {
            for q in xs.chunks(4) {
                let mut v = [0.0f32; 4];
                v[..q.len()].copy_from_slice(q);
                let got = powi4(Vec4::from_array(v), n).to_array();
                for k in 0..4 {
                    let want = powi(v[k], n);
                    assert_eq!(got[k].to_bits(), want.to_bits(), "{}^{n}", v[k]);
                }
            }
        }
    }

    #[test]
    fn refraction_and_fresnel() {
        let n = Vec3A::Y;
        let d = Vec3A::new(1.0, -1.0, 0.0).normalize();
        // Into glass: bends towards the normal (Snell).
        let t = refract(d, n, 1.0 / 1.5).unwrap();
        let sin_t = t.x;
        assert!((sin_t - d.x / 1.5).abs() < 1e-6);
        // Out of glass at 45°: total internal reflection (critical angle 41.8°).
        assert!(refract(d, n, 1.5).is_none());
        assert_eq!(fresnel_dielectric(d.dot(-n).abs(), 1.5), 1.0);
        // Normal incidence: ((n1-n2)/(n1+n2))^2 = 0.04.
        assert!((fresnel_dielectric(1.0, 1.0 / 1.5) - 0.04).abs() < 1e-6);
        assert!(reflect(d, n).abs_diff_eq(Vec3A::new(d.x, -d.y, 0.0), 1e-6));
    }
}
