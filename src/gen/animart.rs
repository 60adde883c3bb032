//! A generator of BART-museum-style "animart": triangles in unstructured motion, written
//! as AFF `tpa` entries with five keys at times 0..4 (as `museum/animart5.aff`):
//!
//! 0. huddled, small, at the top of the museum's pillar;
//! 1. scattered at random over the space above the pillar, randomly turned;
//! 2. gathered into a shape: the tiles of a cube's surface;
//! 3. the same tiles pushed onto a sphere (smooth normals);
//! 4. exploded outwards from the shape's centre, randomly turned.
//!
//! Everything stays inside the box the museum's own animart uses (x, z in ±1.25, y in
//! 1.45..4.4), so the file pairs with the museum's static part (`room`, `pillar`,
//! `block`, `paintings`). The file also carries the animart material and an
//! `a -1 5 F` line (museum5's range; a museum file that includes it and states its own
//! `a` afterwards overrides it). Same parameters, same bytes.

use std::fmt::Write;

use glam::{DQuat, DVec3};

/// Parameters of [`generate_animart`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AnimartParams {
    /// Number of triangles (at least 1).
    pub triangles: usize,
    pub seed: u64,
    /// Frames of the `a -1 5 F` line (at least 2).
    pub frames: u32,
}

impl Default for AnimartParams {
    fn default() -> Self {
        AnimartParams {
            triangles: 1024,
            seed: 1,
            frames: 300,
        }
    }
}

/// SplitMix64: small, fast, and the same on every platform.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// A uniformly distributed rotation (Shoemake).
    fn rotation(&mut self) -> DQuat {
        let (u1, u2, u3) = (self.unit(), self.unit(), self.unit());
        let tau = std::f64::consts::TAU;
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        DQuat::from_xyzw(
            a * (tau * u2).sin(),
            a * (tau * u2).cos(),
            b * (tau * u3).sin(),
            b * (tau * u3).cos(),
        )
        .normalize()
    }
}

const CENTRE: DVec3 = DVec3::new(0.0, 2.6, 0.0);
const CUBE_HALF: f64 = 0.5;
const SPHERE_RADIUS: f64 = 0.6;
const LO: DVec3 = DVec3::new(-1.25, 1.45, -1.25);
const HI: DVec3 = DVec3::new(1.25, 4.4, 1.25);
const PILLAR_TOP: DVec3 = DVec3::new(0.0, 1.6, 0.0);

/// Cube faces: outward normal `n` and tangents `a × b = n`.
const FACES: [[DVec3; 3]; 6] = [
    [DVec3::X, DVec3::Y, DVec3::Z],
    [DVec3::NEG_X, DVec3::Z, DVec3::Y],
    [DVec3::Y, DVec3::Z, DVec3::X],
    [DVec3::NEG_Y, DVec3::X, DVec3::Z],
    [DVec3::Z, DVec3::X, DVec3::Y],
    [DVec3::NEG_Z, DVec3::Y, DVec3::X],
];

fn face_normal(t: &[DVec3; 3]) -> DVec3 {
    let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
    if n == DVec3::ZERO {
        DVec3::Y
    } else {
        n
    }
}

/// `t` turned by `q` about its centroid and moved to `to`, scaled by `s`.
fn place(t: &[DVec3; 3], q: DQuat, s: f64, to: DVec3) -> [DVec3; 3] {
    let c = (t[0] + t[1] + t[2]) / 3.0;
    t.map(|p| to + q * ((p - c) * s))
}

/// The AFF text of `p.triangles` animated triangles (`p.triangles` 0 gives a file with
/// none).
pub fn generate_animart(p: &AnimartParams) -> String {
    let n = p.triangles;
    let mut rng = Rng(p.seed ^ 0x5eed_a417_0000_0000);
    // Tiles per cube face edge: 12·m² triangle slots for n triangles.
    let m = ((n as f64 / 12.0).sqrt().ceil() as usize).max(1);
    let slots = 12 * m * m;
    let cell = 2.0 / m as f64;

    let mut out = String::with_capacity(n * 420 + 512);
    let _ = writeln!(
        out,
        "% subfield generate animart: {n} animated triangles, seed {}, {} frames",
        p.seed, p.frames
    );
    let _ = writeln!(
        out,
        "% keys 0..4: huddled on the pillar, scattered, a cube of tiles, a sphere, exploded"
    );
    let _ = writeln!(
        out,
        "fm 0.25 0.15 0.15\n   0.4 0.25 0.1\n   0.6 0.6 0.40\n   20 0 0"
    );
    let _ = writeln!(out, "a -1.0 5.0 {}", p.frames.max(2));

    for i in 0..n {
        let slot = i * slots / n.max(1);
        let face = &FACES[slot / (2 * m * m)];
        let cellno = (slot % (2 * m * m)) / 2;
        let (cu, cv) = ((cellno % m) as f64, (cellno / m) as f64);
        let (u0, v0) = (-1.0 + cu * cell, -1.0 + cv * cell);
        let (u1, v1) = (u0 + cell, v0 + cell);
        let uv = if slot.is_multiple_of(2) {
            [(u0, v0), (u1, v0), (u1, v1)]
        } else {
            [(u0, v0), (u1, v1), (u0, v1)]
        };
        let dir = uv.map(|(u, v)| face[0] + face[1] * u + face[2] * v);
        let cube = dir.map(|d| CENTRE + d * CUBE_HALF);
        let sphere = dir.map(|d| CENTRE + d.normalize() * SPHERE_RADIUS);
        let sphere_n = dir.map(|d| d.normalize());

        let huddle_at = PILLAR_TOP
            + DVec3::new(
                rng.range(-0.12, 0.12),
                rng.range(0.0, 0.1),
                rng.range(-0.12, 0.12),
            );
        let huddle = place(&cube, rng.rotation(), 0.3, huddle_at);
        let scatter_at = DVec3::new(
            rng.range(-1.1, 1.1),
            rng.range(1.7, 4.1),
            rng.range(-1.1, 1.1),
        );
        let scatter = place(&cube, rng.rotation(), 1.0, scatter_at);
        let c = (cube[0] + cube[1] + cube[2]) / 3.0;
        let out_dir = ((c - CENTRE).normalize_or_zero()
            + DVec3::new(
                rng.range(-0.3, 0.3),
                rng.range(-0.3, 0.3),
                rng.range(-0.3, 0.3),
            ))
        .normalize_or_zero();
        let margin = DVec3::splat(cell * CUBE_HALF);
        let burst_at = (CENTRE + out_dir * rng.range(0.9, 1.5)).clamp(LO + margin, HI - margin);
        let burst = place(&cube, rng.rotation(), 1.0, burst_at);

        let keys: [([DVec3; 3], [DVec3; 3]); 5] = [
            (huddle, [face_normal(&huddle); 3]),
            (scatter, [face_normal(&scatter); 3]),
            (cube, [face_normal(&cube); 3]),
            (sphere, sphere_n),
            (burst, [face_normal(&burst); 3]),
        ];
        out.push_str("tpa 5\n");
        for (k, (pos, nor)) in keys.iter().enumerate() {
            let _ = writeln!(out, "  {k}");
            for j in 0..3 {
                let (q, d) = (pos[j], nor[j]);
                let _ = writeln!(
                    out,
                    "   {:.6} {:.6} {:.6}  {:.6} {:.6} {:.6}",
                    q.x, q.y, q.z, d.x, d.y, d.z
                );
            }
        }
    }
    out
}
