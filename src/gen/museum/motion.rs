//! The dynamic part: the formations (sphere, torus, cube, helix, scatter), one slot per
//! triangle per key, and the morph-target encoding of the motion.

use super::*;

/// A shape the triangles gather into, centred on [`CENTRE`].
#[derive(Clone, Copy, Debug)]
pub(super) enum Shape {
    Sphere,
    Torus,
    Cube,
    Helix,
}

/// Where the triangles are at one key.
#[derive(Clone, Copy, Debug)]
pub(super) enum Formation {
    /// Uniformly in the air of the room, random orientations.
    Scatter,
    /// Flying outwards from the previous key's positions.
    Explode,
    /// Gathered on a shape turned by an angle about Y; a new random assignment of
    /// triangles to places on the shape when `fresh`, else the previous key's (the shape
    /// is held while it turns).
    Gather {
        shape: Shape,
        turn: f32,
        fresh: bool,
    },
}

pub(super) const fn gather(shape: Shape, turn: f32, fresh: bool) -> Formation {
    Formation::Gather { shape, turn, fresh }
}

/// One formation per key, [`MUSEUM_KEYS`] of them. The second key of each shape holds it
/// while it turns.
pub(super) const CHOREOGRAPHY: [Formation; MUSEUM_KEYS] = [
    Formation::Scatter,
    gather(Shape::Sphere, 0.0, true),
    gather(Shape::Sphere, 0.9, false),
    Formation::Explode,
    gather(Shape::Torus, 0.0, true),
    gather(Shape::Torus, 1.2, false),
    Formation::Explode,
    gather(Shape::Cube, 0.0, true),
    gather(Shape::Cube, 0.8, false),
    Formation::Explode,
    gather(Shape::Helix, 0.0, true),
    gather(Shape::Helix, 1.6, false),
    Formation::Scatter,
];

/// The air the triangle centres keep to: walls, floor and ceiling stay clear, and the
/// last 2 m before the front wall, where the camera stands.
pub(super) const AIR_LO: Vec3 = Vec3::new(-9.0, 0.8, -9.0);
pub(super) const AIR_HI: Vec3 = Vec3::new(9.0, 7.2, 7.0);
/// The shapes are sized to about this area, so one triangle size covers them all.
pub(super) const SHAPE_AREA: f32 = 60.0;

/// Fractional part of `0.5 + k a`, in f64 so that a million slots still spread evenly.
pub(super) fn weyl(k: usize, a: f64) -> f32 {
    (0.5 + k as f64 * a).fract() as f32
}
pub(super) const GOLDEN: f64 = 0.618_033_988_749_894_8;

/// The `j`-th of `n` places, evenly over the shape: (position, outward normal).
pub(super) fn slot(shape: Shape, turn: f32, j: usize, n: usize) -> (Vec3, Vec3) {
    use std::f32::consts::TAU;
    let jf = j as f32;
    match shape {
        Shape::Sphere => {
            // Fibonacci lattice, radius 2.2 (area 61).
            let yy = 1.0 - 2.0 * (jf + 0.5) / n as f32;
            let r = (1.0 - yy * yy).max(0.0).sqrt();
            let (s, c) = (TAU * weyl(j, GOLDEN) + turn).sin_cos();
            let d = Vec3::new(r * c, yy, r * s);
            (CENTRE + d * 2.2, d)
        }
        Shape::Torus => {
            // Ring 2.0, tube 0.7 (area 55), tilted towards the camera.
            let (st, ct) = (TAU * (jf + 0.5) / n as f32 + turn).sin_cos();
            let (sp, cp) = (TAU * weyl(j, GOLDEN)).sin_cos();
            let nrm = Vec3::new(cp * ct, sp, cp * st);
            let p = Vec3::new(2.0 * ct, 0.0, 2.0 * st) + nrm * 0.7;
            let tilt = Quat::from_rotation_x(0.9);
            (CENTRE + tilt * p, tilt * nrm)
        }
        Shape::Cube => {
            // Half side 1.6 (area 61), tipped over, turned about Y.
            let (face, k) = (j % 6, j / 6);
            let axes = [Vec3::X, Vec3::Y, Vec3::Z];
            let a = axes[face % 3];
            let sign = if face < 3 { 1.0 } else { -1.0 };
            let (u, v) = (axes[(face + 1) % 3], axes[(face + 2) % 3]);
            // The R2 sequence (Roberts 2018).
            let su = 2.0 * weyl(k, 0.754_877_666_246_692_7) - 1.0;
            let sv = 2.0 * weyl(k, 0.569_840_290_998_053_3) - 1.0;
            let p = (a * sign + u * su + v * sv) * 1.6;
            let rot = Quat::from_rotation_y(turn)
                * Quat::from_rotation_x(0.6)
                * Quat::from_rotation_z(0.5);
            (CENTRE + rot * p, rot * (a * sign))
        }
        Shape::Helix => {
            // Two ribbons 0.6 wide, radius 1.8, two turns over 5.2 (area about 55).
            let strand = (j % 2) as f32;
            let s = ((j / 2) as f32 + 0.5) / n.div_ceil(2) as f32;
            let th = TAU * 2.0 * s + strand * std::f32::consts::PI + turn;
            let (st, ct) = th.sin_cos();
            let radial = Vec3::new(ct, 0.0, st);
            let along = Vec3::new(-st * 1.8 * TAU * 2.0, 5.2, ct * 1.8 * TAU * 2.0).normalize();
            let across = radial.cross(along);
            let w = 0.6 * (weyl(j / 2, GOLDEN) - 0.5);
            let p = CENTRE + Vec3::new(0.0, 5.2 * s - 2.6, 0.0) + radial * 1.8 + across * w;
            (p, radial)
        }
    }
}

/// A right-handed frame in the plane normal to `n`, turned by `spin` about it.
pub(super) fn plane_frame(n: Vec3, spin: f32) -> (Vec3, Vec3) {
    let a = if n.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
    let t0 = n.cross(a).normalize();
    let b0 = n.cross(t0);
    let (s, c) = spin.sin_cos();
    let t = t0 * c + b0 * s;
    (t, n.cross(t))
}

/// Fisher–Yates: `out[i]` is the slot of triangle `i`.
pub(super) fn permutation(rng: &mut Rng, n: usize) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        p.swap(i, rng.below(i + 1));
    }
    p
}

/// Vertex positions of every triangle at every key: `keys[k][3 i + c]`.
pub(super) fn dynamic_keys(p: &MuseumParams) -> Vec<Vec<Vec3>> {
    let n = p.dynamic_tris;
    let mut rng = Rng::new(p.seed);
    let size = (1.4 * (SHAPE_AREA / n as f32).sqrt()).clamp(0.02, 0.6);
    // Each triangle keeps its own shape: three corners around its centre.
    let shapes: Vec<[Vec2; 3]> = (0..n)
        .map(|_| {
            let turn = rng.range(0.0, std::f32::consts::TAU);
            std::array::from_fn(|c| {
                let a = turn + c as f32 * std::f32::consts::TAU / 3.0 + rng.range(-0.35, 0.35);
                Vec2::from_angle(a) * size * rng.range(0.75, 1.25)
            })
        })
        .collect();
    let spins: Vec<f32> = (0..n)
        .map(|_| rng.range(0.0, std::f32::consts::TAU))
        .collect();

    let mut centres = vec![CENTRE; n];
    let mut keys = Vec::with_capacity(MUSEUM_KEYS);
    let mut slots: Vec<usize> = Vec::new();
    for f in CHOREOGRAPHY {
        let mut frames = Vec::with_capacity(n);
        match f {
            Formation::Scatter => {
                for c in centres.iter_mut() {
                    *c = rng.in_box(AIR_LO, AIR_HI);
                    frames.push(plane_frame(
                        rng.unit(),
                        rng.range(0.0, std::f32::consts::TAU),
                    ));
                }
            }
            Formation::Explode => {
                for c in centres.iter_mut() {
                    let out = (*c - CENTRE + rng.unit() * 0.7).normalize_or(Vec3::Y);
                    *c = (*c + out * rng.range(2.5, 6.0)).clamp(AIR_LO, AIR_HI);
                    frames.push(plane_frame(
                        rng.unit(),
                        rng.range(0.0, std::f32::consts::TAU),
                    ));
                }
            }
            Formation::Gather { shape, turn, fresh } => {
                if fresh || slots.len() != n {
                    slots = permutation(&mut rng, n);
                }
                for (i, c) in centres.iter_mut().enumerate() {
                    let (pos, nrm) = slot(shape, turn, slots[i], n);
                    *c = pos;
                    frames.push(plane_frame(nrm, spins[i] + turn));
                }
            }
        }
        let key: Vec<Vec3> = centres
            .iter()
            .zip(&frames)
            .zip(&shapes)
            .flat_map(|((&c, &(t, b)), shape)| shape.map(|l| c + t * l.x + b * l.y))
            .collect();
        keys.push(key);
    }
    keys
}

pub(super) fn build_dynamic(b: &mut Scene, m: &Materials, p: &MuseumParams) {
    let keys = dynamic_keys(p);
    let n = p.dynamic_tris;
    // Four primitives (paint chips of four colours), contiguous runs of triangles.
    let parts = m.chips.len().min(n);
    let mut primitives = Vec::with_capacity(parts);
    for (c, &material) in m.chips.iter().take(parts).enumerate() {
        let (lo, hi) = (3 * (c * n / parts), 3 * ((c + 1) * n / parts));
        let base = &keys[0][lo..hi];
        let morph_targets = keys
            .iter()
            .map(|k| MorphTarget {
                positions: k[lo..hi].iter().zip(base).map(|(a, o)| *a - *o).collect(),
                normals: Vec::new(),
            })
            .collect();
        // Three unshared vertices per triangle.
        let tris = (base.len() / 3) as u32;
        primitives.push(Primitive {
            positions: base.to_vec(),
            triangles: (0..tris).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect(),
            material,
            morph_targets,
            ..Primitive::default()
        });
    }
    let mesh = add_mesh(
        b,
        Mesh {
            name: Some("animart".into()),
            primitives,
            weights: vec![0.0; MUSEUM_KEYS],
        },
    );
    let node = add_root(b, node("animart", mesh, Vec3::ZERO, Quat::IDENTITY));
    // One-hot weights: at key k, target k has weight 1.
    let values = (0..MUSEUM_KEYS * MUSEUM_KEYS)
        .map(|i| {
            if i / MUSEUM_KEYS == i % MUSEUM_KEYS {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    b.animations.push(Animation {
        name: Some("animart".into()),
        channels: vec![Channel {
            node,
            property: Property::Weights,
            interpolation: Interpolation::Linear,
            times: p.key_times(),
            values,
        }],
    });
}
