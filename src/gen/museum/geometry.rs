//! Parts made in code: grids, cuboids, bands, spheres, pillars, a torus, framed
//! paintings; and node helpers.

use super::*;

/// Indexed triangles under construction; `normals` is empty (flat shading) or one per
/// position (smooth).
#[derive(Default)]
pub(super) struct Part {
    pub(super) positions: Vec<Vec3>,
    pub(super) normals: Vec<Vec3>,
    pub(super) indices: Vec<u32>,
}

impl Part {
    pub(super) fn base(&self) -> u32 {
        self.positions.len() as u32
    }

    /// `nu × nv` cells spanning `du`, `dv` from `origin`; front side (counter-clockwise)
    /// towards `du × dv`.
    pub(super) fn grid(&mut self, origin: Vec3, du: Vec3, dv: Vec3, nu: usize, nv: usize) {
        let base = self.base();
        for i in 0..=nu {
            for j in 0..=nv {
                let p = origin + du * (i as f32 / nu as f32) + dv * (j as f32 / nv as f32);
                self.positions.push(p);
            }
        }
        let at = |i: usize, j: usize| base + (i * (nv + 1) + j) as u32;
        for i in 0..nu {
            for j in 0..nv {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                self.indices.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
    }

    /// An axis-aligned box, faces outwards, 12 triangles.
    pub(super) fn cuboid(&mut self, lo: Vec3, hi: Vec3) {
        let e = hi - lo;
        let (x, y, z) = (Vec3::X * e.x, Vec3::Y * e.y, Vec3::Z * e.z);
        self.grid(lo, z, y, 1, 1); // -X
        self.grid(lo + x, y, z, 1, 1); // +X
        self.grid(lo, x, z, 1, 1); // -Y
        self.grid(lo + y, z, x, 1, 1); // +Y
        self.grid(lo, y, x, 1, 1); // -Z
        self.grid(lo + z, x, y, 1, 1); // +Z
    }

    /// A vertical band of `quads` cells from `origin` along `du`, `dv` up; with `odd`, the
    /// last cell is three triangles (a vertex in the middle of its top edge, which is a
    /// border, so no crack).
    pub(super) fn band(&mut self, origin: Vec3, du: Vec3, dv: Vec3, quads: usize, odd: bool) {
        let base = self.base();
        for i in 0..=quads {
            let p = origin + du * (i as f32 / quads as f32);
            self.positions.push(p);
            self.positions.push(p + dv);
        }
        for i in 0..quads as u32 {
            let (b0, t0, b1, t1) = (
                base + 2 * i,
                base + 2 * i + 1,
                base + 2 * i + 2,
                base + 2 * i + 3,
            );
            if odd && i + 1 == quads as u32 {
                let m = self.base();
                let mid = (self.positions[t0 as usize] + self.positions[t1 as usize]) * 0.5;
                self.positions.push(mid);
                self.indices
                    .extend_from_slice(&[b0, b1, t1, b0, t1, m, b0, m, t0]);
            } else {
                self.indices.extend_from_slice(&[b0, b1, t1, b0, t1, t0]);
            }
        }
    }

    #[cfg(test)]
    pub(super) fn tris(&self) -> usize {
        self.indices.len() / 3
    }

    pub(super) fn primitive(self, material: u32) -> Primitive {
        Primitive {
            normals: (!self.normals.is_empty()).then_some(self.normals),
            positions: self.positions,
            triangles: self
                .indices
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect(),
            material,
            ..Primitive::default()
        }
    }
}

/// Smooth surface `f(u, v) -> (position, normal)` over a `nu × nv` lattice; `wrap_u`
/// closes the lattice in `u` (no seam vertices: shading needs none without UVs).
/// Front side (counter-clockwise) towards `∂f/∂u × ∂f/∂v`.
pub(super) fn smooth_lattice(
    part: &mut Part,
    nu: usize,
    nv: usize,
    wrap_v: bool,
    f: impl Fn(f32, f32) -> (Vec3, Vec3),
) {
    let base = part.base();
    let cols = if wrap_v { nv } else { nv + 1 };
    for i in 0..=nu {
        for j in 0..cols {
            let (p, n) = f(i as f32 / nu as f32, j as f32 / nv as f32);
            part.positions.push(p);
            part.normals.push(n);
        }
    }
    let at = |i: usize, j: usize| base + (i * cols + j % cols) as u32;
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            part.indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
}

/// UV sphere around the origin: `rings` bands, `2 * rings` segments, fans at the poles.
pub(super) fn sphere(radius: f32, rings: usize) -> Part {
    let segs = 2 * rings;
    let mut part = Part::default();
    let dir = |i: usize, j: usize| {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        let ph = std::f32::consts::TAU * j as f32 / segs as f32;
        Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin())
    };
    part.positions.push(Vec3::Y * radius);
    part.normals.push(Vec3::Y);
    for i in 1..rings {
        for j in 0..segs {
            let d = dir(i, j);
            part.positions.push(d * radius);
            part.normals.push(d);
        }
    }
    let bottom = part.base();
    part.positions.push(Vec3::NEG_Y * radius);
    part.normals.push(Vec3::NEG_Y);
    let at = |i: usize, j: usize| 1 + ((i - 1) * segs + j % segs) as u32;
    for j in 0..segs {
        part.indices.extend_from_slice(&[0, at(1, j + 1), at(1, j)]);
        part.indices
            .extend_from_slice(&[bottom, at(rings - 1, j), at(rings - 1, j + 1)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
            let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
            part.indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    part
}

/// One pillar: an open cylinder of radius 0.4 from the base to the capital (smooth),
/// and the base and capital blocks (flat). Local origin on the floor.
pub(super) fn pillar(segments: usize) -> (Part, Part) {
    let rings = (segments / 2).max(1);
    let mut column = Part::default();
    smooth_lattice(&mut column, rings, segments, true, |u, v| {
        let (s, c) = (std::f32::consts::TAU * v).sin_cos();
        let n = Vec3::new(c, 0.0, s);
        (n * 0.4 + Vec3::Y * (0.3 + 7.3 * u), n)
    });
    let mut blocks = Part::default();
    blocks.cuboid(Vec3::new(-0.55, 0.0, -0.55), Vec3::new(0.55, 0.3, 0.55));
    blocks.cuboid(
        Vec3::new(-0.55, 7.6, -0.55),
        Vec3::new(0.55, ROOM_HEIGHT, 0.55),
    );
    (column, blocks)
}

/// Torus around the local Y axis: major radius 0.55, tube 0.2.
pub(super) fn torus(segments: usize) -> Part {
    let tube = torus_tube(segments);
    let mut part = Part::default();
    // u around the tube, v around the ring: ∂f/∂u × ∂f/∂v points outwards.
    smooth_lattice(&mut part, tube, segments, true, |u, v| {
        let (sp, cp) = (std::f32::consts::TAU * u).sin_cos();
        let (st, ct) = (std::f32::consts::TAU * v).sin_cos();
        let n = Vec3::new(cp * ct, sp, cp * st);
        (Vec3::new(0.55 * ct, 0.0, 0.55 * st) + n * 0.2, n)
    });
    // The tube wraps too: its first and last rows coincide, so merge them.
    let cols = segments as u32;
    let last_row = tube as u32 * cols;
    for i in &mut part.indices {
        if *i >= last_row {
            *i -= last_row;
        }
    }
    part.positions.truncate(last_row as usize);
    part.normals.truncate(last_row as usize);
    part
}

/// A framed picture in its local frame: canvas `w × h` centred on the origin facing +Z,
/// a gold frame 0.12 wide and 0.08 deep behind it against the wall (z = 0).
pub(super) fn framed(w: f32, h: f32, canvas_material: u32, gold: u32) -> Mesh {
    let (hw, hh, bar, depth) = (w / 2.0, h / 2.0, 0.12, 0.08);
    let mut frame = Part::default();
    frame.cuboid(
        Vec3::new(-hw - bar, hh, 0.0),
        Vec3::new(hw + bar, hh + bar, depth),
    );
    frame.cuboid(
        Vec3::new(-hw - bar, -hh - bar, 0.0),
        Vec3::new(hw + bar, -hh, depth),
    );
    frame.cuboid(Vec3::new(-hw - bar, -hh, 0.0), Vec3::new(-hw, hh, depth));
    frame.cuboid(Vec3::new(hw, -hh, 0.0), Vec3::new(hw + bar, hh, depth));
    let mut canvas = Part::default();
    canvas.grid(Vec3::new(-hw, -hh, 0.03), Vec3::X * w, Vec3::Y * h, 1, 1);
    Mesh {
        name: None,
        primitives: vec![frame.primitive(gold), canvas.primitive(canvas_material)],
        weights: Vec::new(),
    }
}

/// A rest transform: `translation` and `rotation`, unit scale.
pub(super) fn placed(translation: Vec3, rotation: Quat) -> NodeTransform {
    NodeTransform::Trs(Trs {
        translation,
        rotation,
        scale: Vec3::ONE,
    })
}

pub(super) fn node(name: &str, mesh: usize, translation: Vec3, rotation: Quat) -> Node {
    Node {
        name: Some(name.to_string()),
        mesh: Some(mesh),
        transform: placed(translation, rotation),
        ..Node::default()
    }
}

/// Adds `n` to the scene's nodes and roots; returns its index.
pub(super) fn add_root(b: &mut Scene, n: Node) -> usize {
    b.nodes.push(n);
    let i = b.nodes.len() - 1;
    b.roots.push(i);
    i
}

/// Adds `m` to the scene's meshes; returns its index.
pub(super) fn add_mesh(b: &mut Scene, m: Mesh) -> usize {
    b.meshes.push(m);
    b.meshes.len() - 1
}
