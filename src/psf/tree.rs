//! A four-wide box tree over the static triangles: what answers a static query on the CPU
//! where no point grid takes the ray (reflections off curved and moving surfaces, every
//! ray of a deeper Whitted level), in place of the parallel subfields' walk. On the
//! demo's scene (Whitted depth 4) the trace is 17–19 % faster and the whole render 7–11
//! %; on the benches' dolly scene (depth 1), where such rays are a quarter of a frame's
//! trace, nothing measurable (benches/PERF.md, issue 38, round 25). The walk stays the
//! method's query: the GPU tracer walks the subfields, counted queries (`tune`, the
//! benches' counts) walk them, and so does a ray the tree cannot take
//! ([`BoxTree::takes`]).
//!
//! # Why every hit is found
//!
//! The tree holds the triangles in leaves of four (padded with [`TriPre::NONE`], which
//! no ray meets); an inner node holds its four children's boxes, each the bounds of its
//! triangles grown by twice the PSF's rounding margin and rounded outwards to `f32`. A
//! leaf's triangles get the same test as the walk's candidates ([`intersect_pre4`], the
//! bits of [`intersect_pre`](crate::geometry::intersect_pre)), and the answer is the
//! least hit by [`Hit::is_closer_than`], a total order, so the order of the tests does
//! not matter: the tree's hit is the walk's and brute force's as long as it tests every
//! triangle that could be the answer. It passes over a child only when its box is
//! certainly not met by the ray between `t_min − s` and `best + s`, where `s` is the
//! walk's early-exit slack (`(margin + 1e-6 |o|) / |d|`, how far in `t` a computed hit
//! may sit from where the line truly meets its triangle, within the margin of it):
//!
//! * a triangle the test reports at `t` (`t_min ≤ t ≤ best`) is met by the line at some
//!   `t*` within `s` of `t`, at a point within the margin of the triangle, so inside
//!   the child's box: the box's slab interval holds `t*`, and `t*` lies in
//!   `[t_min − s, best + s]`;
//! * the slab interval is computed in `f32` lanes as `traverse::surely_outside` computes
//!   its own, and widened the same way (`1e-5 |t| + 1e-30`), which by that function's
//!   proof contains the exact interval for origins and box coordinates under `1e15` and
//!   direction components of at least `1e-20` in size;
//! * a direction component that is zero (either sign) makes that axis's two slab values
//!   `(lo − o) · ±∞`: where `lo < o < hi` they are `−∞` and `+∞`, no bound, as the exact
//!   slab (the line keeps `o` on that axis) has none; where `o` lies outside `[lo, hi]`
//!   both are the same infinity, so the entry is `+∞` or the exit `−∞`, the widened
//!   bound `∞ − ∞` is NaN, every comparison with it is false and the child is passed
//!   over, as the exact slab is empty. Where `o` equals `lo` or `hi` the product `0 · ∞`
//!   is NaN, and what `min` and `max` make of it differs between instruction sets (it
//!   may hide another axis's bound, or reach the comparisons); but the line then lies
//!   in a face of a box grown by twice the margin, at least twice the margin away from
//!   each of the child's triangles along that axis, where no reported hit can lie
//!   (above): passed over or visited, the child gives no answer. A NaN reaches the
//!   comparisons from no other case, and a bound hidden only makes a visit, which is
//!   never wrong. A child is visited only where its entry compared as at most its exit,
//!   so a NaN entry never orders the stack.
//!
//! These are the rays [`BoxTree::takes`]: each direction component zero or at least
//! `1e-20` in size, so an axis-aligned ray (an orthographic camera looking along an axis,
//! a reflection off a wall at normal incidence) is the tree's too.
//!
//! A child skipped so holds no triangle that could be the answer; one kept on the stack
//! is passed over when popped if its entry lies beyond `best + s` by then (the same
//! argument, with the best hit found since). An any-hit query stops at the first hit.

use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;

use super::point::Group;
use crate::geometry::{Hit, Ray, RayPre, TriPre};

/// Coordinates (the boxes', a ray's origin) the `f32` box test takes, and the least
/// direction component in size (`traverse::surely_outside`'s ranges).
const MAX_COORD: f32 = 1e15;
const MIN_DIR: f32 = 1e-20;

/// A child that is a leaf: `LEAF | first << 2` (its four triangles from `first`, a
/// multiple of four); else an inner node's index. `EMPTY` where a node has fewer than
/// four children.
const LEAF: u32 = 1 << 31;
const EMPTY: u32 = u32::MAX;

/// Parts at or below this size are split on one thread.
const SERIAL: usize = 4096;
/// Past this depth (of the binary tree) a part is cut at its middle without looking for
/// the best cut, so the depth (and the traversal's stack) stays bounded whatever the
/// triangles.
const SAH_DEPTH: usize = 20;
/// Stack entries a query may need: a four-wide node is two binary levels, at most
/// `SAH_DEPTH` and the 32 below them that halving can make of 2^32 triangles, and each
/// node popped leaves at most three children behind it.
const STACK: usize = 3 * (SAH_DEPTH + 32).div_ceil(2) + 1;

#[derive(Clone, Copy, Debug)]
struct Node {
    /// The four children's boxes: `lo[axis]` lane `k` is child `k`'s lower bound.
    lo: [Vec4; 3],
    hi: [Vec4; 3],
    child: [u32; 4],
}

/// The static triangles' box tree (see the module's notes).
#[derive(Debug)]
pub(crate) struct BoxTree {
    nodes: Vec<Node>,
    /// The leaves' triangles, four a leaf, and the number each reports.
    pre: Vec<TriPre>,
    number: Vec<u32>,
    margin: f32,
}

/// A triangle while the tree is built: its bounds, centroid and number.
#[derive(Clone, Copy)]
struct Item {
    lo: Vec3A,
    hi: Vec3A,
    c: Vec3A,
    tri: u32,
}

/// A binary tree first (built in parallel), flattened into four-wide nodes after; each
/// part with the bounds of its triangles.
enum Bin {
    Leaf(Vec<u32>, Vec3A, Vec3A),
    Inner(Box<Bin>, Box<Bin>, Vec3A, Vec3A),
}

impl Bin {
    fn bounds(&self) -> (Vec3A, Vec3A) {
        match self {
            Bin::Leaf(_, lo, hi) | Bin::Inner(_, _, lo, hi) => (*lo, *hi),
        }
    }
}

fn bounds(items: &[Item]) -> (Vec3A, Vec3A) {
    items.iter().fold(
        (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)),
        |(l, h), i| (l.min(i.lo), h.max(i.hi)),
    )
}

fn half_area(lo: Vec3A, hi: Vec3A) -> f32 {
    let e = (hi - lo).max(Vec3A::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// Cuts `items` in two, reordering them: at the least surface-area cost over sixteen
/// bins of the centroids on each axis, or at the middle where no cut separates them (or
/// past [`SAH_DEPTH`]). The first part's length and the axis.
fn cut(items: &mut [Item], depth: usize) -> usize {
    const BINS: usize = 16;
    let n = items.len();
    let (clo, chi) = items.iter().fold(
        (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)),
        |(l, h), i| (l.min(i.c), h.max(i.c)),
    );
    let ext = chi - clo;
    let mut best: Option<(f32, usize, f32)> = None;
    if depth <= SAH_DEPTH {
        for axis in 0..3 {
            // A NaN extent (no finite centroid) takes no cut either.
            if ext[axis].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            let k = BINS as f32 / ext[axis];
            let bin = |i: &Item| (((i.c[axis] - clo[axis]) * k) as usize).min(BINS - 1);
            let mut count = [0usize; BINS];
            let mut blo = [Vec3A::splat(f32::INFINITY); BINS];
            let mut bhi = [Vec3A::splat(f32::NEG_INFINITY); BINS];
            for i in items.iter() {
                let b = bin(i);
                count[b] += 1;
                blo[b] = blo[b].min(i.lo);
                bhi[b] = bhi[b].max(i.hi);
            }
            // The cost of the part above each cut, then the part below added to it.
            let mut above = [0.0f32; BINS];
            let (mut l, mut h, mut c) = (blo[BINS - 1], bhi[BINS - 1], count[BINS - 1]);
            for b in (1..BINS).rev() {
                if b < BINS - 1 {
                    l = l.min(blo[b]);
                    h = h.max(bhi[b]);
                    c += count[b];
                }
                above[b] = half_area(l, h) * c as f32;
            }
            let (mut l, mut h, mut c) = (blo[0], bhi[0], 0);
            for b in 0..BINS - 1 {
                l = l.min(blo[b]);
                h = h.max(bhi[b]);
                c += count[b];
                if c == 0 || c == n {
                    continue;
                }
                let cost = half_area(l, h) * c as f32 + above[b + 1];
                if best.is_none_or(|(least, _, _)| cost < least) {
                    best = Some((cost, axis, clo[axis] + (b + 1) as f32 / k));
                }
            }
        }
    }
    if let Some((_, axis, at)) = best {
        let mut i = 0;
        for j in 0..n {
            if items[j].c[axis] < at {
                items.swap(i, j);
                i += 1;
            }
        }
        if i > 0 && i < n {
            return i;
        }
    }
    // No cut separates the centroids (or too deep): the middle of the longest axis.
    let axis = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    items.select_nth_unstable_by(n / 2, |a, b| a.c[axis].total_cmp(&b.c[axis]));
    n / 2
}

/// The binary tree over `items`: leaves of at most four; large parts split side by side
/// on the pool where `parallel`.
fn build_bin(items: &mut [Item], depth: usize, parallel: bool) -> Bin {
    let (lo, hi) = bounds(items);
    if items.len() <= 4 {
        return Bin::Leaf(items.iter().map(|i| i.tri).collect(), lo, hi);
    }
    let m = cut(items, depth);
    let (a, b) = items.split_at_mut(m);
    let (l, r) = if parallel && a.len() + b.len() > SERIAL {
        rayon::join(
            || build_bin(a, depth + 1, true),
            || build_bin(b, depth + 1, true),
        )
    } else {
        (
            build_bin(a, depth + 1, parallel),
            build_bin(b, depth + 1, parallel),
        )
    };
    Bin::Inner(Box::new(l), Box::new(r), lo, hi)
}

/// A four-wide node's parts: an inner part's two children, each cut once more where it
/// is not a leaf (a leaf alone is the one part of a root over four triangles or fewer).
fn parts(bin: Bin) -> Vec<Bin> {
    match bin {
        Bin::Leaf(..) => vec![bin],
        Bin::Inner(l, r, ..) => {
            let mut out = Vec::with_capacity(4);
            for half in [*l, *r] {
                match half {
                    Bin::Inner(a, b, ..) => {
                        out.push(*a);
                        out.push(*b);
                    }
                    leaf => out.push(leaf),
                }
            }
            out
        }
    }
}

impl BoxTree {
    /// The tree over `tris`, boxes grown by twice `margin` (the PSF's); `None` where a
    /// coordinate is beyond what the `f32` box test takes (the walk answers there). On
    /// the pool's threads where `parallel`, else on this one alone. The same tree either
    /// way.
    pub(crate) fn build(tris: &[[Vec3; 3]], margin: f32, parallel: bool) -> Option<BoxTree> {
        let grow = 2.0 * margin;
        let fits = |v: &Vec3| v.abs().max_element() + grow < MAX_COORD;
        if tris.is_empty() || !tris.iter().all(|t| t.iter().all(fits)) || !margin.is_finite() {
            return None;
        }
        let item = |(k, t): (usize, &[Vec3; 3])| {
            let (a, b, c) = (Vec3A::from(t[0]), Vec3A::from(t[1]), Vec3A::from(t[2]));
            let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
            Item {
                lo,
                hi,
                c: (lo + hi) * 0.5,
                tri: k as u32,
            }
        };
        let mut items: Vec<Item> = if parallel {
            tris.par_iter().enumerate().map(item).collect()
        } else {
            tris.iter().enumerate().map(item).collect()
        };
        let bin = build_bin(&mut items, 0, parallel);
        drop(items);
        let mut tree = BoxTree {
            nodes: Vec::new(),
            pre: Vec::with_capacity(tris.len() + tris.len() / 2),
            number: Vec::with_capacity(tris.len() + tris.len() / 2),
            margin,
        };
        tree.node(parts(bin), tris);
        Some(tree)
    }

    /// Writes the node over `parts` (one to four) and what is below it; its index.
    fn node(&mut self, parts_: Vec<Bin>, tris: &[[Vec3; 3]]) -> u32 {
        let at = self.nodes.len();
        let mut node = Node {
            lo: [Vec4::ZERO; 3],
            hi: [Vec4::ZERO; 3],
            child: [EMPTY; 4],
        };
        self.nodes.push(node);
        let grow = Vec3A::splat(2.0 * self.margin);
        for (k, part) in parts_.into_iter().enumerate() {
            let (lo, hi) = part.bounds();
            let (lo, hi) = (lo - grow, hi + grow);
            for ax in 0..3 {
                // Rounded outwards: the box holds every point within the margin.
                node.lo[ax][k] = lo[ax].next_down();
                node.hi[ax][k] = hi[ax].next_up();
            }
            node.child[k] = match part {
                Bin::Leaf(t, ..) => {
                    let first = self.pre.len() as u32;
                    for j in 0..4 {
                        match t.get(j) {
                            Some(&i) => {
                                self.pre.push(TriPre::new(&tris[i as usize]));
                                self.number.push(i);
                            }
                            None => {
                                self.pre.push(TriPre::NONE);
                                self.number.push(u32::MAX);
                            }
                        }
                    }
                    LEAF | first >> 2
                }
                inner => self.node(parts(inner), tris),
            };
        }
        self.nodes[at] = node;
        at as u32
    }

    /// Whether the tree answers `ray` (a valid one): its origin and direction within the
    /// ranges of the `f32` box test, a direction component zero or at least `MIN_DIR` in
    /// size (the module's notes).
    #[inline]
    pub(crate) fn takes(&self, ray: &Ray) -> bool {
        let o = Vec3A::from(ray.origin);
        let d = Vec3A::from(ray.dir).abs();
        o.abs().max_element() < MAX_COORD
            && (d.cmpge(Vec3A::splat(MIN_DIR)) | d.cmpeq(Vec3A::ZERO)).all()
    }

    /// The closest hit among the tree's triangles (any hit for `ANY`) of a ray the tree
    /// [`takes`](Self::takes), with its shear `pre`.
    pub(crate) fn trace<const ANY: bool>(&self, ray: &Ray, pre: &RayPre) -> Option<Hit> {
        const SLACK: f32 = 1e-5;
        const TINY: f32 = 1e-30;
        let o = Vec3A::from(ray.origin);
        let d = Vec3A::from(ray.dir);
        let inv = Vec3A::ONE / d;
        let (ox, oy, oz) = (Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z));
        let (ix, iy, iz) = (Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z));
        // The walk's early-exit slack (`Psf::trace_pre`), in f32 rounded up a little.
        let o64 = ray.origin.as_dvec3();
        let slack = ((self.margin as f64 + 1e-6 * o64.length()) / ray.dir.as_dvec3().length()
            * (1.0 + 1e-6)) as f32;
        let t_min = ray.t_min - slack;
        let mut best: Option<Hit> = None;
        let mut stack = [(0u32, 0.0f32); STACK];
        stack[0] = (0, f32::NEG_INFINITY);
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (c, enter) = stack[sp];
            let t_far = best.map_or(ray.t_max, |b| b.t) + slack;
            if enter > t_far {
                continue;
            }
            if c & LEAF != 0 {
                let first = ((c & !LEAF) << 2) as usize;
                let mut group = Group::default();
                for j in first..first + 4 {
                    group.push(&self.pre[j], self.number[j]);
                }
                if group.test::<ANY>(pre, ray, &mut best).0 {
                    return best;
                }
                continue;
            }
            let node = &self.nodes[c as usize];
            let (ax, bx) = ((node.lo[0] - ox) * ix, (node.hi[0] - ox) * ix);
            let (ay, by) = ((node.lo[1] - oy) * iy, (node.hi[1] - oy) * iy);
            let (az, bz) = ((node.lo[2] - oz) * iz, (node.hi[2] - oz) * iz);
            let t0 = ax.min(bx).max(ay.min(by)).max(az.min(bz));
            let t1 = ax.max(bx).min(ay.max(by)).min(az.max(bz));
            let en = t0 - Vec4::splat(SLACK) * t0.abs() - Vec4::splat(TINY);
            let ex = t1 + Vec4::splat(SLACK) * t1.abs() + Vec4::splat(TINY);
            let met = en.cmple(ex) & en.cmple(Vec4::splat(t_far)) & ex.cmpge(Vec4::splat(t_min));
            let mask = met.bitmask();
            // The children met, pushed far to near by where the ray enters their boxes
            // (an insertion into the stack's top), so the nearest is popped first: 0.6 %
            // of a dolly frame's CPU fewer than an order fixed by the ray's octant
            // (benches/PERF.md, issue 38, round 27).
            let base = sp;
            for k in 0..4 {
                let ch = node.child[k];
                if (mask >> k) & 1 != 0 && ch != EMPTY {
                    let e = en[k];
                    let mut j = sp;
                    while j > base && stack[j - 1].1 < e {
                        stack[j] = stack[j - 1];
                        j -= 1;
                    }
                    stack[j] = (ch, e);
                    sp += 1;
                }
            }
        }
        best
    }

    /// Nodes, for the tests.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.nodes.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gen::synth::{lattice_floor, Rng};
    use crate::geometry::{Aabb, BruteForce, Intersector};
    use crate::psf::margin_for;

    /// The tree's closest hit is brute force's to the bit, and its any-hit query answers
    /// whenever brute force finds a hit; `what` names the ray on a failure.
    fn agrees(tree: &BoxTree, brute: &BruteForce, ray: &Ray, what: &str) {
        let pre = RayPre::new(ray.origin, ray.dir);
        let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits()));
        let (got, want) = (tree.trace::<false>(ray, &pre), brute.intersect(ray));
        assert_eq!(bits(got), bits(want), "{what}: {ray:?}");
        let any = tree.trace::<true>(ray, &pre).is_some();
        assert_eq!(any, brute.occluded(ray), "{what} (any hit): {ray:?}");
    }

    /// Soups of small and large triangles, a tiled plane (shared edges and vertices) and
    /// grazing rays aimed at vertices and edges, at three scales: the tree's hit is brute
    /// force's, to the bit, and an any-hit query answers whenever brute force finds a
    /// hit. The seed is printed on a failure.
    #[test]
    fn the_tree_finds_what_brute_force_finds() {
        for seed in 1..=40u64 {
            let mut r = Rng::new(seed);
            let scale = [1.0f32, 1e-3, 1e4][seed as usize % 3];
            let v = |r: &mut Rng, s: f32| r.in_box(Vec3::splat(-0.5 * s), Vec3::splat(0.5 * s));
            let mut tris = Vec::new();
            for _ in 0..50 + r.below(400) {
                let a = v(&mut r, 10.0 * scale);
                let s = if r.below(4) == 0 { 8.0 } else { 0.4 } * scale;
                tris.push([a, a + v(&mut r, s), a + v(&mut r, s)]);
            }
            let offset = Vec3::new(-3.0, 0.0, -3.0);
            tris.extend(
                lattice_floor(6, 0.25)
                    .into_iter()
                    .map(|t| t.map(|p| (p + offset) * scale)),
            );
            let tree = BoxTree::build(
                &tris,
                margin_for(&Aabb::from_triangles(&tris)),
                seed % 2 == 0,
            )
            .unwrap();
            assert!(tree.len() >= 1);
            let brute = BruteForce::new(&tris);
            for n in 0..600 {
                let o = v(&mut r, 30.0 * scale);
                let t = tris[r.below(tris.len())];
                let aim = match n % 3 {
                    0 => t[r.below(3)],
                    1 => t[0] + (t[1] - t[0]) * r.f32(),
                    _ => v(&mut r, 10.0 * scale),
                };
                let mut ray = Ray::new(o, aim - o);
                if n % 5 == 0 {
                    ray.t_min = r.f32();
                    ray.t_max = 0.5 + r.f32();
                }
                if !ray.is_valid() || !tree.takes(&ray) {
                    continue;
                }
                agrees(&tree, &brute, &ray, &format!("seed {seed}, ray {n}"));
            }
        }
    }

    /// Coordinates beyond the box test's range build no tree; a ray the tree does not
    /// take is the walk's.
    #[test]
    fn out_of_range_is_left_to_the_walk() {
        let far = [[
            Vec3::splat(2e15),
            Vec3::new(2e15, 1.0, 0.0),
            Vec3::new(2e15, 0.0, 1.0),
        ]];
        assert!(BoxTree::build(&far, 1.0, true).is_none());
        assert!(BoxTree::build(&[], 1.0, false).is_none());
        let t = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
        let tree = BoxTree::build(&t, 1e-5, false).unwrap();
        assert!(tree.takes(&Ray::new(
            Vec3::new(0.2, 0.2, 1.0),
            Vec3::new(1e-3, 1e-3, -1.0)
        )));
        assert!(tree.takes(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z)));
        assert!(tree.takes(&Ray::new(Vec3::ZERO, Vec3::new(-0.0, 0.0, 1.0))));
        assert!(!tree.takes(&Ray::new(
            Vec3::new(0.2, 0.2, 1.0),
            Vec3::new(1e-25, 0.0, -1.0)
        )));
        assert!(!tree.takes(&Ray::new(Vec3::splat(2e15), Vec3::ONE)));
    }

    /// Rays with zero direction components (of either sign), most of them starting on
    /// the lattices' vertex and edge coordinates, so that they run in the planes of
    /// triangles, edges and boxes' faces: the tree's hit is brute force's, to the bit,
    /// and an any-hit query answers whenever brute force finds a hit. The seed is
    /// printed on a failure.
    #[test]
    fn axis_aligned_rays_find_what_brute_force_finds() {
        let mut taken = 0;
        for seed in 1..=24u64 {
            let mut r = Rng::new(seed);
            let scale = [1.0f32, 1e-3, 1e4][seed as usize % 3];
            // A floor at y = 0 and a wall at z = 2, both lattices of unit squares, and
            // triangles strewn among them.
            let mut tris: Vec<[Vec3; 3]> = lattice_floor(8, 0.0);
            tris.extend(
                lattice_floor(6, 2.0)
                    .into_iter()
                    .map(|t| t.map(|p| Vec3::new(p.x, p.z, p.y))),
            );
            for _ in 0..40 + r.below(100) {
                let a = r.in_box(Vec3::ZERO, Vec3::splat(8.0));
                let e = |r: &mut Rng| r.in_box(Vec3::splat(-0.5), Vec3::splat(0.5));
                tris.push([a, a + e(&mut r), a + e(&mut r)]);
            }
            for t in &mut tris {
                *t = t.map(|p| p * scale);
            }
            let tree = BoxTree::build(
                &tris,
                margin_for(&Aabb::from_triangles(&tris)),
                seed % 2 == 1,
            )
            .unwrap();
            let brute = BruteForce::new(&tris);
            // A lattice coordinate (a vertex's or an edge's), exactly, or any.
            let at = |r: &mut Rng| {
                if r.below(4) == 0 {
                    r.f32() * 9.0 - 0.5
                } else {
                    r.below(10) as f32 - 1.0
                }
            };
            for n in 0..1000 {
                let o = Vec3::new(at(&mut r), at(&mut r), at(&mut r)) * scale;
                let mut d = r.in_box(Vec3::splat(-1.0), Vec3::ONE);
                for _ in 0..1 + r.below(2) {
                    d[r.below(3)] = if r.below(2) == 0 { 0.0 } else { -0.0 };
                }
                let mut ray = Ray::new(o, d);
                if n % 5 == 0 {
                    ray.t_min = r.f32() * scale;
                    ray.t_max = (1.0 + 8.0 * r.f32()) * scale;
                }
                if !ray.is_valid() {
                    continue;
                }
                assert!(tree.takes(&ray), "seed {seed}, ray {n}: {ray:?}");
                taken += 1;
                agrees(&tree, &brute, &ray, &format!("seed {seed}, ray {n}"));
            }
        }
        assert!(taken > 20_000, "{taken} rays taken");
    }
}
