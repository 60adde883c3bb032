//! The PSF tracer must agree with brute force on every ray: the same closest hit (same
//! triangle, same `t`, same barycentrics, ties broken by the smaller triangle index) and
//! the same any-hit answer, over randomised scenes and rays of every awkward kind.
//!
//! proptest prints the failing `Case` (its seed included) and shrinks it; the same case
//! re-runs from that seed alone.

use glam::Vec3;
use proptest::prelude::*;
use subfield::gen::synth::{self, Rng};
use subfield::geometry::{BruteForce, Intersector, Ray};
use subfield::psf::{subfield_directions, GridFrame, RayStats};
use subfield::{Aabb, Psf, PsfParams};

#[derive(Clone, Debug)]
struct Case {
    seed: u64,
    level: u32,
    tiles: u32,
    /// Bit set of scene parts: 1 soup, 2 sphere, 4 walls, 8 slivers, 16 degenerates,
    /// 32 lattice floor (edges on integer coordinates, tile borders with tiles = 8).
    parts: u32,
    /// Uniform scale and offset applied to the scene and the rays.
    scale: f32,
    offset: f32,
    rays: usize,
}

fn build_scene(c: &Case) -> Vec<[Vec3; 3]> {
    let mut rng = Rng::new(c.seed);
    let (lo, hi) = (Vec3::splat(0.0), Vec3::splat(8.0));
    let mut tris = Vec::new();
    if c.parts & 1 != 0 {
        let n = 20 + rng.below(200);
        let size = rng.range(0.05, 4.0);
        tris.extend(synth::soup(&mut rng, n, lo, hi, size));
    }
    if c.parts & 2 != 0 {
        let ctr = rng.in_box(Vec3::splat(2.0), Vec3::splat(6.0));
        tris.extend(synth::sphere(
            ctr,
            rng.range(0.5, 2.0),
            3 + rng.below(8),
            3 + rng.below(12),
        ));
    }
    if c.parts & 4 != 0 {
        tris.extend(synth::box_faces(lo, hi));
        tris.extend(synth::box_faces(
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(3.0, 2.0, 5.0),
        ));
    }
    if c.parts & 8 != 0 {
        let n = 5 + rng.below(40);
        tris.extend(synth::slivers(&mut rng, n, lo, hi, 1e-3));
    }
    if c.parts & 16 != 0 {
        let n = 3 + rng.below(20);
        tris.extend(synth::degenerates(&mut rng, n, lo, hi));
    }
    if c.parts & 32 != 0 {
        tris.extend(synth::lattice_floor(8, 4.0));
    }
    if tris.is_empty() {
        tris.extend(synth::box_faces(lo, hi));
    }
    // Shuffle so that the triangle index (the tie rule) is not correlated with position.
    for i in (1..tris.len()).rev() {
        let j = rng.below(i + 1);
        tris.swap(i, j);
    }
    let off = Vec3::splat(c.offset);
    tris.iter().map(|t| t.map(|v| v * c.scale + off)).collect()
}

/// Rays of every kind the issue names, in scene units (scaled with the scene).
fn build_rays(c: &Case, tris: &[[Vec3; 3]], bounds: &Aabb) -> Vec<Ray> {
    let mut rng = Rng::new(c.seed ^ 0x005e_ed0f_4a75);
    let dirs = subfield_directions(c.level);
    let ctr = bounds.center();
    let radius = (bounds.extent().length() * 0.5).max(1e-30);
    let grid_bounds = bounds.padded(2.0 * subfield::psf::margin_for(bounds));
    let mut rays = Vec::with_capacity(c.rays);
    while rays.len() < c.rays {
        let kind = rng.below(8);
        let inside =
            bounds.min + (bounds.max - bounds.min) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
        let ray = match kind {
            // origin inside, random direction
            0 => Ray::new(inside, rng.unit()),
            // origin outside, aimed at a point inside
            1 => {
                let o = ctr + rng.unit() * radius * rng.range(1.05, 3.0);
                Ray::new(o, (inside - o) * rng.range(0.1, 10.0))
            }
            // exactly along a subfield direction (either sense)
            2 => {
                let d = dirs[rng.below(dirs.len())];
                let o = inside - d * radius * 2.0 * rng.f32();
                Ray::new(o, if rng.below(2) == 0 { d } else { -d })
            }
            // along a tile edge: origin on a tile border line of a subfield, direction in
            // the plane spanned by d and the border's direction
            3 => {
                let k = rng.below(dirs.len());
                let f = GridFrame::new(dirs[k], &grid_bounds, c.tiles);
                let i = rng.below(f.nu as usize + 1) as f32;
                let along_v = rng.range(f.v0, f.v0 + f.nv as f32 * f.tile);
                let depth = ctr.dot(f.d) + rng.range(-radius, radius);
                let o = f.u * (f.u0 + i * f.tile) + f.v * along_v + f.d * depth;
                let dir =
                    f.d * if rng.below(2) == 0 { 1.0 } else { -1.0 } + f.v * rng.range(-0.3, 0.3);
                Ray::new(o, dir)
            }
            // grazing: in the plane of a triangle, through it
            4 => {
                let t = tris[rng.below(tris.len())];
                let n = (t[1] - t[0]).cross(t[2] - t[0]);
                let p = t[0] + (t[1] - t[0]) * rng.f32() * 0.5 + (t[2] - t[0]) * rng.f32() * 0.5;
                let e = (t[1] - t[0]).normalize_or(Vec3::X);
                let eps = if rng.below(2) == 0 {
                    0.0
                } else {
                    rng.range(-1e-4, 1e-4)
                };
                let dir = e + n.normalize_or(Vec3::Y) * eps;
                Ray::new(p - dir * radius, dir)
            }
            // through a vertex or along a shared edge of the mesh
            5 => {
                let t = tris[rng.below(tris.len())];
                let a = rng.below(3);
                let p = if rng.below(2) == 0 {
                    t[a]
                } else {
                    t[a].lerp(t[(a + 1) % 3], rng.f32())
                };
                let o = ctr + rng.unit() * radius * rng.range(0.2, 2.5);
                Ray::new(o, p - o)
            }
            // a segment, as shadow rays are: t in [t_min, t_max]
            6 => {
                let o = inside;
                let p = bounds.min
                    + (bounds.max - bounds.min) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
                Ray::segment(o, p - o, rng.range(0.0, 0.3), rng.range(0.3, 1.0))
            }
            // axis-aligned directions, along walls and lattice lines
            _ => {
                let mut d = Vec3::ZERO;
                d[rng.below(3)] = if rng.below(2) == 0 { 1.0 } else { -1.0 };
                let mut o = inside;
                if rng.below(2) == 0 {
                    // snap a coordinate to a lattice/wall plane
                    let k = rng.below(3);
                    o[k] = (((o[k] - c.offset) / c.scale).round()) * c.scale + c.offset;
                }
                Ray::new(o, d)
            }
        };
        rays.push(ray);
    }
    rays
}

fn check(c: &Case) -> Result<(), TestCaseError> {
    let tris = build_scene(c);
    let bounds = Aabb::from_triangles(&tris);
    let psf = Psf::build(
        &tris,
        &PsfParams {
            level: c.level,
            tiles: c.tiles,
        },
    )
    .expect("bake");
    let brute = BruteForce::new(&tris);
    let rays = build_rays(c, &tris, &bounds);
    let mut got = vec![None; rays.len()];
    let mut want = vec![None; rays.len()];
    psf.intersect_batch(&rays, &mut got);
    brute.intersect_batch(&rays, &mut want);
    let mut occ_got = vec![false; rays.len()];
    let mut occ_want = vec![false; rays.len()];
    psf.occluded_batch(&rays, &mut occ_got);
    brute.occluded_batch(&rays, &mut occ_want);
    // The batches and single rays go through the box tree, counted queries through the
    // walk: both must be brute force's.
    let mut stats = RayStats::default();
    for i in 0..rays.len() {
        prop_assert_eq!(
            got[i],
            want[i],
            "closest hit differs on ray {} {:?} (seed {})",
            i,
            rays[i],
            c.seed
        );
        prop_assert_eq!(
            psf.intersect(&rays[i]),
            want[i],
            "closest hit of one ray differs on ray {} {:?} (seed {})",
            i,
            rays[i],
            c.seed
        );
        prop_assert_eq!(
            psf.intersect_counted(&rays[i], &mut stats),
            want[i],
            "the walk's closest hit differs on ray {} {:?} (seed {})",
            i,
            rays[i],
            c.seed
        );
        prop_assert_eq!(
            psf.occluded_counted(&rays[i], &mut stats),
            occ_want[i],
            "the walk's any hit differs on ray {} {:?} (seed {})",
            i,
            rays[i],
            c.seed
        );
        prop_assert_eq!(
            occ_got[i],
            occ_want[i],
            "any hit differs on ray {} {:?} (seed {})",
            i,
            rays[i],
            c.seed
        );
    }
    Ok(())
}

fn case() -> impl Strategy<Value = Case> {
    (
        any::<u64>(),
        prop_oneof![Just(0u32), Just(1), 2u32..=3, Just(4)],
        prop_oneof![Just(1u32), Just(2), Just(7), Just(8), Just(16), Just(64)],
        1u32..64,
        prop_oneof![Just(1.0f32), Just(1e-4), Just(1e4)],
        prop_oneof![Just(0.0f32), Just(-3.0), Just(100.0)],
    )
        .prop_map(|(seed, level, tiles, parts, scale, offset)| Case {
            seed,
            level,
            tiles,
            parts,
            scale,
            offset: offset * scale,
            rays: 2000,
        })
}

proptest! {
    // 64 cases x 2,000 rays = 128,000 rays a run, each checked for closest and any hit.
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    #[test]
    fn psf_agrees_with_brute_force(c in case()) {
        check(&c)?;
    }
}

/// A closed mesh seen through its shared edges and vertices: the watertight test plus
/// conservative tiles mean no ray slips through, and the PSF agrees with brute force.
#[test]
fn closed_sphere_has_no_holes() {
    let tris = synth::sphere(Vec3::new(4.0, 4.0, 4.0), 2.0, 9, 13);
    let psf = Psf::build(
        &tris,
        &PsfParams {
            level: 2,
            tiles: 16,
        },
    )
    .unwrap();
    let brute = BruteForce::new(&tris);
    let mut rng = Rng::new(99);
    for _ in 0..20_000 {
        let t = tris[rng.below(tris.len())];
        let a = rng.below(3);
        let p = t[a].lerp(
            t[(a + 1) % 3],
            if rng.below(4) == 0 { 0.0 } else { rng.f32() },
        );
        // From outside, within about 30 degrees of the outward normal, so the ray crosses
        // the surface at p rather than grazing the silhouette.
        let out = (p - Vec3::splat(4.0)).normalize();
        let o = p + (out + rng.unit() * 0.5).normalize() * 5.0;
        let ray = Ray::new(o, p - o);
        let h = psf.intersect(&ray);
        assert!(h.is_some(), "slipped through at {p:?} from {o:?}");
        assert_eq!(h, brute.intersect(&ray));
    }
}

/// Hand-picked edge cases, each a seed the random run might not draw: one tile at level
/// 0, level 4, 256 tiles at level 3, a subset of the scene parts, and scenes scaled by
/// 1e4 (offset 3e4) and 1e-4.
#[test]
fn fixed_seeds_at_extreme_levels_tiles_and_scales() {
    let cases = [
        Case {
            seed: 1,
            level: 0,
            tiles: 1,
            parts: 63,
            scale: 1.0,
            offset: 0.0,
            rays: 3000,
        },
        Case {
            seed: 2,
            level: 4,
            tiles: 64,
            parts: 63,
            scale: 1.0,
            offset: 0.0,
            rays: 3000,
        },
        Case {
            seed: 3,
            level: 1,
            tiles: 8,
            parts: 32 | 4,
            scale: 1.0,
            offset: 0.0,
            rays: 3000,
        },
        Case {
            seed: 4,
            level: 2,
            tiles: 16,
            parts: 63,
            scale: 1e4,
            offset: 3e4,
            rays: 3000,
        },
        Case {
            seed: 5,
            level: 2,
            tiles: 16,
            parts: 63,
            scale: 1e-4,
            offset: -3e-4,
            rays: 3000,
        },
        Case {
            seed: 6,
            level: 3,
            tiles: 256,
            parts: 1 | 8 | 16,
            scale: 1.0,
            offset: 0.0,
            rays: 3000,
        },
    ];
    for c in &cases {
        check(c).unwrap_or_else(|e| panic!("{c:?}: {e}"));
    }
}

#[test]
fn empty_scene_and_invalid_rays() {
    let psf = Psf::build(&[], &PsfParams::default()).unwrap();
    assert!(psf.intersect(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
    let tris = synth::box_faces(Vec3::ZERO, Vec3::ONE);
    let psf = Psf::build(&tris, &PsfParams::default()).unwrap();
    for r in [
        Ray::new(Vec3::splat(0.5), Vec3::ZERO),
        Ray::new(Vec3::splat(f32::NAN), Vec3::X),
        Ray::new(Vec3::splat(0.5), Vec3::new(f32::INFINITY, 0.0, 0.0)),
        Ray::segment(Vec3::splat(0.5), Vec3::X, 1.0, 0.5),
    ] {
        assert!(psf.intersect(&r).is_none());
        assert!(!psf.occluded(&r));
    }
}

#[test]
fn bad_input_is_an_error() {
    let bad = vec![[Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ONE]];
    assert!(matches!(
        Psf::build(&bad, &PsfParams::default()),
        Err(subfield::PsfError::NonFinite {
            triangle: 0,
            vertex: 1,
            ..
        })
    ));
    let ok = synth::box_faces(Vec3::ZERO, Vec3::ONE);
    assert!(Psf::build(&ok, &PsfParams { level: 5, tiles: 8 }).is_err());
    assert!(Psf::build(&ok, &PsfParams { level: 1, tiles: 0 }).is_err());
}
