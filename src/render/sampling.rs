//! Deterministic random numbers and the sampling routines of the shading model: every
//! number comes from a hash of where it is used (frame, pixel, sample, bounce, purpose),
//! never from a generator shared between threads, so a frame's bytes do not depend on
//! the thread count or on which shard renders it.

use glam::{Vec2, Vec3};

/// SplitMix64's finaliser: a bijective 64-bit mix.
fn mix(mut h: u64) -> u64 {
    h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^ (h >> 31)
}

/// A stream of random numbers named by a seed: [`Seed::child`] derives the seed of a
/// ray made from this one; [`Seed::get`] gives the `i`-th pair of uniform numbers of
/// this stream for some purpose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Seed(pub u64);

/// What a stream's numbers are for (kept apart so two uses never share numbers).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u64)]
pub enum Purpose {
    /// Choosing a glossy reflection direction.
    Glossy = 1,
    /// Choosing an emissive triangle and a point on it.
    AreaLight = 2,
    /// Choosing a diffuse bounce's direction.
    Diffuse = 3,
}

impl Seed {
    /// The seed of a camera sample (`frame`, pixel `(x, y)`, sample `k`).
    pub fn camera(frame: u32, x: u32, y: u32, k: u32) -> Seed {
        let mut h = 0x5DEE_CE66_D1CE_4E5Bu64;
        for v in [frame, x, y, k] {
            h = mix(h ^ u64::from(v)).wrapping_add(0x9E37_79B9_7F4A_7C15);
        }
        Seed(h)
    }

    /// The seed of the ray this one spawns by `kind` (0 mirror/glossy, 1 refraction,
    /// 2 pass-through).
    pub fn child(self, kind: u64) -> Seed {
        Seed(mix(self.0 ^ (kind + 1).wrapping_mul(0xD6E8_FEB8_6659_FD93)))
    }

    /// Two uniform numbers in `[0, 1)`, number `i` of `purpose`.
    pub fn get(self, purpose: Purpose, i: u32) -> Vec2 {
        let h = mix(self.0 ^ mix(((purpose as u64) << 32) | u64::from(i)));
        let a = (h >> 40) as f32 / (1u64 << 24) as f32;
        let b = ((h >> 16) & 0xFF_FFFF) as f32 / (1u64 << 24) as f32;
        Vec2::new(a, b)
    }
}

/// The `i`-th of `n` stratified pairs in `[0, 1)²` from the uniform pair `r`: cell `i`
/// of an `a × b` grid with `a·b = n` exactly (`a` the largest divisor of `n` up to
/// `√n`), jittered by `r`. The `n` cells tile the square, so `n` samples with one each
/// stay an unbiased estimate.
pub fn stratified(i: u32, n: u32, r: Vec2) -> Vec2 {
    if n <= 1 {
        return r;
    }
    let mut a = (n as f64).sqrt() as u32;
    while a > 1 && !n.is_multiple_of(a) {
        a -= 1;
    }
    let b = n / a.max(1);
    let i = i % n;
    Vec2::new(
        (((i % a) as f32 + r.x) / a as f32).min(0.999_999_9),
        (((i / a) as f32 + r.y) / b as f32).min(0.999_999_9),
    )
}

/// An orthonormal basis `(t, b)` around unit `n` (Duff et al. 2017, branchless).
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// A direction around unit `n` drawn with density `cos θ / π` (Malley's method: a point
/// of the unit disc, uniform by area, lifted onto the hemisphere), from the uniform pair
/// `r`.
pub fn sample_cosine(n: Vec3, r: Vec2) -> Vec3 {
    let (t, b) = basis(n);
    let radius = r.y.sqrt();
    let phi = std::f32::consts::TAU * r.x;
    let (sin, cos) = phi.sin_cos();
    (t * (radius * cos) + b * (radius * sin) + n * (1.0 - r.y).max(0.0).sqrt()).normalize_or_zero()
}

/// GGX (Trowbridge–Reitz) Smith masking `G1` for a direction at cosine `cos` to the
/// normal, width `alpha`.
pub fn smith_g1(cos: f32, alpha: f32) -> f32 {
    let c2 = (cos * cos).max(1e-8);
    let t2 = (1.0 - c2) / c2;
    2.0 / (1.0 + (1.0 + alpha * alpha * t2).sqrt())
}

/// A GGX microfacet normal drawn from the distribution of normals visible from `v`
/// (Heitz 2018, "Sampling the GGX Distribution of Visible Normals"), around unit `n`,
/// width `alpha`, from the uniform pair `r`. `v` must be on `n`'s side.
pub fn sample_ggx_vndf(v: Vec3, n: Vec3, alpha: f32, r: Vec2) -> Vec3 {
    let (t, b) = basis(n);
    // The view direction in the local frame, stretched to the unit-roughness space.
    let vl = Vec3::new(v.dot(t), v.dot(b), v.dot(n).max(1e-6));
    let vh = Vec3::new(alpha * vl.x, alpha * vl.y, vl.z).normalize();
    let len2 = vh.x * vh.x + vh.y * vh.y;
    let t1 = if len2 > 0.0 {
        Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt()
    } else {
        Vec3::X
    };
    let t2 = vh.cross(t1);
    let rad = r.x.sqrt();
    let phi = 2.0 * std::f32::consts::PI * r.y;
    let p1 = rad * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * rad * phi.sin();
    let p3 = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    let nh = t1 * p1 + t2 * p2 + vh * p3;
    let m = Vec3::new(alpha * nh.x, alpha * nh.y, nh.z.max(1e-6)).normalize();
    (t * m.x + b * m.y + n * m.z).normalize_or_zero()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_deterministic_and_apart() {
        let a = Seed::camera(1, 2, 3, 4);
        assert_eq!(a, Seed::camera(1, 2, 3, 4));
        assert_ne!(a, Seed::camera(1, 2, 3, 5));
        assert_ne!(a.child(0), a.child(1));
        assert_ne!(a.get(Purpose::Glossy, 0), a.get(Purpose::AreaLight, 0));
        let r = a.get(Purpose::Glossy, 7);
        assert!((0.0..1.0).contains(&r.x) && (0.0..1.0).contains(&r.y));
    }

    #[test]
    fn strata_tile_the_square_once_each() {
        for n in [2u32, 7, 8, 12, 16, 30] {
            let mut seen = vec![0u32; n as usize];
            for i in 0..n {
                let p = stratified(i, n, Vec2::new(0.5, 0.5));
                let mut a = (n as f64).sqrt() as u32;
                while n % a != 0 {
                    a -= 1;
                }
                let (cx, cy) = ((p.x * a as f32) as u32, (p.y * (n / a) as f32) as u32);
                seen[(cy * a + cx) as usize] += 1;
            }
            assert!(seen.iter().all(|&c| c == 1), "n = {n}: {seen:?}");
        }
    }

    #[test]
    fn basis_is_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let (t, b) = basis(n);
            assert!(t.dot(n).abs() < 1e-6 && b.dot(n).abs() < 1e-6 && t.dot(b).abs() < 1e-6);
            assert!((t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn ggx_normals_narrow_with_roughness_and_face_the_viewer() {
        let n = Vec3::Y;
        let v = Vec3::new(0.5, 0.8, 0.0).normalize();
        let spread = |alpha: f32| {
            let mut s = 0.0;
            for i in 0..256 {
                let r = Seed(i).get(Purpose::Glossy, 0);
                let m = sample_ggx_vndf(v, n, alpha, r);
                assert!(m.dot(n) > 0.0, "microfacet below the surface");
                assert!(m.dot(v) > -1e-4, "microfacet turned away from the viewer");
                s += 1.0 - m.dot(n);
            }
            s / 256.0
        };
        let (a, b, c) = (spread(0.01), spread(0.25), spread(0.8));
        assert!(a < 1e-3 && a < b && b < c, "spreads {a} {b} {c}");
    }
}
