//! Triangle sets made in code, for tests, benchmarks and examples: random soups, closed
//! meshes, walls, slivers, degenerate triangles. Deterministic from a seed, with no
//! dependency on a random-number crate (SplitMix64), so every machine builds the same.

use glam::Vec3;

/// SplitMix64 (Steele, Lea, Flood 2014): tiny, fast, and good enough to scatter
/// triangles and rays.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }

    pub fn in_box(&mut self, lo: Vec3, hi: Vec3) -> Vec3 {
        Vec3::new(
            self.range(lo.x, hi.x),
            self.range(lo.y, hi.y),
            self.range(lo.z, hi.z),
        )
    }

    /// Uniform on the unit sphere.
    pub fn unit(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let a = self.range(0.0, std::f32::consts::TAU);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * a.cos(), r * a.sin(), z)
    }
}

/// `n` random triangles in `[lo, hi]`, each with vertices within `size` of its first.
pub fn soup(rng: &mut Rng, n: usize, lo: Vec3, hi: Vec3, size: f32) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|_| {
            let a = rng.in_box(lo, hi);
            [
                a,
                a + rng.unit() * rng.range(0.0, size),
                a + rng.unit() * rng.range(0.0, size),
            ]
        })
        .collect()
}

/// A closed UV sphere: `rings` bands of `segments` quads, fans at the poles. Every edge
/// is shared by exactly two triangles.
pub fn sphere(center: Vec3, radius: f32, rings: usize, segments: usize) -> Vec<[Vec3; 3]> {
    let rings = rings.max(2);
    let segments = segments.max(3);
    let p = |i: usize, j: usize| {
        // Poles exactly, so the fans close (sin(pi) is not 0 in f32).
        if i == 0 || i == rings {
            return center + Vec3::new(0.0, if i == 0 { radius } else { -radius }, 0.0);
        }
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        let ph = std::f32::consts::TAU * (j % segments) as f32 / segments as f32;
        center + radius * Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin())
    };
    let mut out = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (p(i, j), p(i, j + 1), p(i + 1, j), p(i + 1, j + 1));
            if i > 0 {
                out.push([a, b, d]);
            }
            if i + 1 < rings {
                out.push([a, d, c]);
            }
        }
    }
    out
}

/// The six faces of a box as 12 triangles, axis-aligned.
pub fn box_faces(lo: Vec3, hi: Vec3) -> Vec<[Vec3; 3]> {
    let c =
        |x: usize, y: usize, z: usize| Vec3::new([lo.x, hi.x][x], [lo.y, hi.y][y], [lo.z, hi.z][z]);
    let quads = [
        [c(0, 0, 0), c(1, 0, 0), c(1, 1, 0), c(0, 1, 0)],
        [c(0, 0, 1), c(0, 1, 1), c(1, 1, 1), c(1, 0, 1)],
        [c(0, 0, 0), c(0, 0, 1), c(1, 0, 1), c(1, 0, 0)],
        [c(0, 1, 0), c(1, 1, 0), c(1, 1, 1), c(0, 1, 1)],
        [c(0, 0, 0), c(0, 1, 0), c(0, 1, 1), c(0, 0, 1)],
        [c(1, 0, 0), c(1, 0, 1), c(1, 1, 1), c(1, 1, 0)],
    ];
    quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect()
}

/// A flat axis-aligned floor of `n × n` unit-lattice quads at height `y`, split in
/// triangles: every vertex and edge sits on integer coordinates.
pub fn lattice_floor(n: usize, y: f32) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (x0, x1, z0, z1) = (i as f32, i as f32 + 1.0, j as f32, j as f32 + 1.0);
            out.push([
                Vec3::new(x0, y, z0),
                Vec3::new(x1, y, z0),
                Vec3::new(x1, y, z1),
            ]);
            out.push([
                Vec3::new(x0, y, z0),
                Vec3::new(x1, y, z1),
                Vec3::new(x0, y, z1),
            ]);
        }
    }
    out
}

/// Long thin triangles: two vertices far apart, the third within `width` of their line.
pub fn slivers(rng: &mut Rng, n: usize, lo: Vec3, hi: Vec3, width: f32) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|_| {
            let a = rng.in_box(lo, hi);
            let b = rng.in_box(lo, hi);
            let m = a.lerp(b, rng.f32()) + rng.unit() * width;
            [a, b, m]
        })
        .collect()
}

/// Zero-area triangles: collinear vertices, repeated vertices, single points.
pub fn degenerates(rng: &mut Rng, n: usize, lo: Vec3, hi: Vec3) -> Vec<[Vec3; 3]> {
    (0..n)
        .map(|k| {
            let a = rng.in_box(lo, hi);
            let b = rng.in_box(lo, hi);
            match k % 3 {
                0 => [a, b, a.lerp(b, rng.f32())],
                1 => [a, a, b],
                _ => [a, a, a],
            }
        })
        .collect()
}

/// A museum-like static room for benchmarks: walls, floor and ceiling finely tessellated,
/// pillars (closed cylinders) and spheres, about `target` triangles.
pub fn room(rng: &mut Rng, target: usize) -> Vec<[Vec3; 3]> {
    let mut out = box_faces(Vec3::new(-10.0, 0.0, -10.0), Vec3::new(10.0, 6.0, 10.0));
    // eight pillars on a ring, tessellated to carry a third of the triangles
    let stacks = (target / 3 / (8 * 2 * 24)).max(1);
    for k in 0..8 {
        let a = k as f32 / 8.0 * std::f32::consts::TAU;
        out.extend(cylinder(
            Vec3::new(7.0 * a.cos(), 0.0, 7.0 * a.sin()),
            0.4,
            6.0,
            24,
            stacks,
        ));
    }
    // spheres fill the rest
    while out.len() < target {
        let c = rng.in_box(Vec3::new(-8.0, 0.5, -8.0), Vec3::new(8.0, 5.5, 8.0));
        out.extend(sphere(c, rng.range(0.2, 0.8), 12, 24));
    }
    out.truncate(target);
    out
}

/// An open cylinder along +y, `segments` around, `stacks` high.
pub fn cylinder(
    base: Vec3,
    radius: f32,
    height: f32,
    segments: usize,
    stacks: usize,
) -> Vec<[Vec3; 3]> {
    let p = |i: usize, j: usize| {
        let a = std::f32::consts::TAU * (j % segments) as f32 / segments as f32;
        base + Vec3::new(
            radius * a.cos(),
            height * i as f32 / stacks as f32,
            radius * a.sin(),
        )
    };
    let mut out = Vec::new();
    for i in 0..stacks {
        for j in 0..segments {
            out.push([p(i, j), p(i, j + 1), p(i + 1, j + 1)]);
            out.push([p(i, j), p(i + 1, j + 1), p(i + 1, j)]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_is_closed() {
        let s = sphere(Vec3::ZERO, 1.0, 6, 9);
        // every undirected edge appears exactly twice
        let key = |a: Vec3, b: Vec3| {
            let (a, b) = (
                a.to_array().map(f32::to_bits),
                b.to_array().map(f32::to_bits),
            );
            if a < b {
                (a, b)
            } else {
                (b, a)
            }
        };
        let mut edges = std::collections::BTreeMap::new();
        for t in &s {
            for k in 0..3 {
                *edges.entry(key(t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        assert!(
            edges.values().all(|&c| c == 2),
            "open edges: {:?}",
            edges.values().filter(|&&c| c != 2).count()
        );
    }

    #[test]
    fn rng_is_deterministic() {
        let a: Vec<u64> = (0..4)
            .map({
                let mut r = Rng::new(7);
                move |_| r.next_u64()
            })
            .collect();
        let b: Vec<u64> = (0..4)
            .map({
                let mut r = Rng::new(7);
                move |_| r.next_u64()
            })
            .collect();
        assert_eq!(a, b);
    }
}
