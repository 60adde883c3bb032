//! Tessellation of AFF's curved primitives into triangles with smooth normals.
//!
//! Spheres: a latitude–longitude grid of [`SPHERE_SLICES`] × [`SPHERE_STACKS`] with shared
//! pole and seam vertices (a closed surface: every edge has two triangles). Cones and
//! cylinders: [`CONE_SLICES`] segments around the axis, open at both ends as in AFF.
//! Every vertex lies on the exact surface; a negative radius (AFF: the inside is visible)
//! turns the triangles and normals inwards.

use glam::Vec3;

pub const SPHERE_SLICES: usize = 48;
pub const SPHERE_STACKS: usize = 24;
pub const CONE_SLICES: usize = 48;

/// An indexed triangle mesh with per-vertex unit normals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tessellation {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub indices: Vec<u32>,
}

impl Tessellation {
    /// Orients every triangle so its geometric normal agrees with `outward(centroid)`.
    fn orient(&mut self, outward: impl Fn(Vec3) -> Vec3) {
        for tri in self.indices.chunks_exact_mut(3) {
            let [a, b, c] = [
                self.positions[tri[0] as usize],
                self.positions[tri[1] as usize],
                self.positions[tri[2] as usize],
            ];
            let n = (b - a).cross(c - a);
            if n.dot(outward((a + b + c) / 3.0)) < 0.0 {
                tri.swap(1, 2);
            }
        }
    }
}

/// A sphere of radius `|radius|` about `centre`; facing inwards when `radius < 0`.
pub fn sphere(centre: Vec3, radius: f32) -> Tessellation {
    let r = radius.abs();
    let sign = if radius < 0.0 { -1.0 } else { 1.0 };
    let mut t = Tessellation::default();
    let push = |dir: Vec3, t: &mut Tessellation| {
        t.positions.push(centre + dir * r);
        t.normals.push(dir * sign);
    };
    push(Vec3::Y, &mut t);
    for i in 1..SPHERE_STACKS {
        let theta = std::f32::consts::PI * i as f32 / SPHERE_STACKS as f32;
        for j in 0..SPHERE_SLICES {
            let phi = std::f32::consts::TAU * j as f32 / SPHERE_SLICES as f32;
            let dir = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            push(dir, &mut t);
        }
    }
    push(Vec3::NEG_Y, &mut t);
    let ring = |i: usize, j: usize| (1 + (i - 1) * SPHERE_SLICES + j % SPHERE_SLICES) as u32;
    let south = (1 + (SPHERE_STACKS - 1) * SPHERE_SLICES) as u32;
    for j in 0..SPHERE_SLICES {
        t.indices.extend([0, ring(1, j), ring(1, j + 1)]);
        for i in 1..SPHERE_STACKS - 1 {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            t.indices.extend([a, c, b, b, c, d]);
        }
        t.indices.extend([
            south,
            ring(SPHERE_STACKS - 1, j + 1),
            ring(SPHERE_STACKS - 1, j),
        ]);
    }
    t.orient(|p| (p - centre) * sign);
    t
}

/// A cone or cylinder from `base` (radius `|r0|`) to `apex` (radius `|r1|`), without end
/// caps; facing inwards when both radii are negative. Empty when the axis has no length
/// or both radii are zero.
pub fn cone(base: Vec3, r0: f32, apex: Vec3, r1: f32) -> Tessellation {
    let mut t = Tessellation::default();
    let axis = apex - base;
    let h = axis.length();
    let (a0, a1) = (r0.abs(), r1.abs());
    if h.is_nan() || h <= 0.0 || !h.is_finite() || (a0 == 0.0 && a1 == 0.0) {
        return t;
    }
    let d = axis / h;
    let sign = if r0 < 0.0 && r1 < 0.0 { -1.0 } else { 1.0 };
    let u = d.any_orthonormal_vector();
    let v = d.cross(u);
    for j in 0..CONE_SLICES {
        let phi = std::f32::consts::TAU * j as f32 / CONE_SLICES as f32;
        let radial = u * phi.cos() + v * phi.sin();
        let n = (radial * h + d * (a0 - a1)).normalize() * sign;
        t.positions.push(base + radial * a0);
        t.normals.push(n);
        t.positions.push(apex + radial * a1);
        t.normals.push(n);
    }
    let b = |j: usize| (2 * (j % CONE_SLICES)) as u32;
    let a = |j: usize| (2 * (j % CONE_SLICES) + 1) as u32;
    for j in 0..CONE_SLICES {
        if a0 > 0.0 {
            t.indices.extend([b(j), b(j + 1), a(j)]);
        }
        if a1 > 0.0 {
            t.indices.extend([a(j), b(j + 1), a(j + 1)]);
        }
    }
    t.orient(|p| {
        let along = (p - base).dot(d);
        (p - (base + d * along)) * sign
    });
    t
}
