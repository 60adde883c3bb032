//! Batches of rays through one point (a camera's primary rays, shadow rays towards a
//! point light) are traced through a grid by central projection around that point
//! (`src/psf/point/`). They must agree with brute force exactly, like every other
//! query: same closest hit (triangle, t, barycentrics), same any-hit answer. The scenes
//! put triangles where that grid is delicate: around the point itself (the near list),
//! across the planes between the cube faces, crossing the plane a face clips at, far
//! from the point and behind it; the point lies inside the scene or far outside it; and
//! some rays of a batch miss the point and must take the parallel subfields.
//!
//! proptest prints the failing `Case` (seed included) and shrinks it.

use glam::Vec3;
use proptest::prelude::*;
use subfield::gen::synth::{self, Rng};
use subfield::geometry::{BruteForce, Intersector, Ray};
use subfield::{DynamicLayer, Psf, PsfParams};

#[derive(Clone, Debug)]
struct Case {
    seed: u64,
    params: PsfParams,
    statics: usize,
    moving: usize,
    /// 0: the point inside the scene; 1: just outside; 2: far away.
    where_: usize,
    /// Rays that miss the point, in percent (a batch with many of them takes the
    /// parallel subfields altogether).
    stray: usize,
}

const LO: Vec3 = Vec3::splat(0.0);
const HI: Vec3 = Vec3::splat(8.0);

fn tri_at(rng: &mut Rng, c: Vec3, s: f32) -> [Vec3; 3] {
    [c + rng.unit() * s, c + rng.unit() * s, c + rng.unit() * s]
}

/// Triangles around `c` that exercise the grid: tiny ones within the near cube, ones
/// through `c`, large ones across the faces' boundaries around `c`, and a soup.
fn scene(rng: &mut Rng, n: usize, c: Vec3) -> Vec<[Vec3; 3]> {
    let size = rng.range(0.1, 3.0);
    let mut tris = synth::soup(rng, n, LO, HI, size);
    for _ in 0..rng.below(4) {
        let s = rng.range(1e-4, 0.05);
        tris.push(tri_at(rng, c, s));
    }
    for _ in 0..rng.below(3) {
        let a = c + rng.unit() * rng.range(0.5, 4.0);
        let (f, b) = (rng.f32(), rng.unit() * rng.range(0.5, 4.0));
        tris.push([a, c - (a - c) * f, c + b]);
    }
    for _ in 0..rng.below(6) {
        let m = c + rng.unit() * rng.range(0.05, 3.0);
        let s = rng.range(0.5, 6.0);
        tris.push(tri_at(rng, m, s));
    }
    tris
}

/// A batch through `c`: from it (like primary rays) or towards it (like shadow rays
/// ending short of a light, or at it), with `stray` percent of other rays. A quarter
/// pass through a vertex or an edge of one of `tris`: hits on the boundaries between
/// triangles and on the rims of their projections.
fn rays(
    rng: &mut Rng,
    n: usize,
    c: Vec3,
    stray: usize,
    from: bool,
    tris: &[[Vec3; 3]],
) -> Vec<Ray> {
    (0..n)
        .map(|_| {
            let p = if !tris.is_empty() && rng.below(4) == 0 {
                let t = tris[rng.below(tris.len())];
                let a = rng.below(3);
                if rng.below(2) == 0 {
                    t[a]
                } else {
                    t[a].lerp(t[(a + 1) % 3], rng.f32())
                }
            } else {
                rng.in_box(LO - 1.0, HI + 1.0)
            };
            if rng.below(100) < stray {
                return Ray::new(p, rng.unit());
            }
            // Now and then a ray that is no ray (NaN, a zero direction, an empty
            // interval): no hit, through a grid or not.
            match rng.below(200) {
                0 => return Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), rng.unit()),
                1 => return Ray::new(c, Vec3::ZERO),
                2 => return Ray::segment(c, p - c, 2.0, 1.0),
                _ => {}
            }
            if from {
                let d = if rng.below(4) == 0 { rng.unit() } else { p - c };
                match rng.below(3) {
                    0 => Ray::new(c, d),
                    1 => Ray::segment(c, d, 0.0, rng.range(0.1, 2.0)),
                    _ => Ray::segment(c, d, 1e-3, f32::INFINITY),
                }
            } else {
                let l = c - p;
                let dist = l.length();
                let d = l / dist;
                let end = match rng.below(4) {
                    0 => dist,
                    1 => dist * 0.5,
                    _ => dist * (1.0 - 1e-4),
                };
                Ray::segment(p, d, 0.0, end)
            }
        })
        .collect()
}

fn check(k: &Case) -> Result<(), TestCaseError> {
    let mut rng = Rng::new(k.seed);
    let c = match k.where_ {
        0 => rng.in_box(LO + 1.0, HI - 1.0),
        1 => HI + rng.unit().abs() * rng.range(0.5, 3.0),
        _ => Vec3::splat(4.0) + rng.unit() * rng.range(100.0, 5000.0),
    };
    let stat = scene(&mut rng, k.statics, c);
    let psf = Psf::build(&stat, &k.params).expect("bake");
    let mut layer = DynamicLayer::new(&psf);
    let moving = scene(&mut rng, k.moving, c);
    layer.update(&moving).expect("update");
    let all: Vec<[Vec3; 3]> = stat.iter().chain(&moving).copied().collect();
    let brute = BruteForce::new(&all);
    let both = psf.with_dynamic(&layer);
    let n = (4 * all.len()).max(600);
    let mut batches = Vec::new();
    for from in [true, false] {
        let rs = rays(&mut rng, n, c, k.stray, from, &all);
        batches.push((from, rs.clone()));
        if k.stray == 0 && !all.is_empty() {
            prop_assert!(
                both.point_grid_for(&rs),
                "a batch through one point should take a point grid (seed {})",
                k.seed
            );
        }
        // The static PSF alone takes point grids too.
        let alone = BruteForce::new(&stat);
        for (what, got, want) in [
            (
                "static PSF alone",
                &psf as &dyn Intersector,
                &alone as &dyn Intersector,
            ),
            ("both layers", &both, &brute),
        ] {
            let d = first_difference(got, want, &rs);
            prop_assert!(
                d.is_none(),
                "{}, from the point {}, seed {}: {}",
                what,
                from,
                k.seed,
                d.unwrap_or_default()
            );
        }
    }
    // The next frame: the static part of each grid is kept in the PSF (its point is the
    // same), the moving part built anew over the moved triangles.
    let moved = scene(&mut rng, k.moving, c);
    layer.update(&moved).expect("update");
    let all: Vec<[Vec3; 3]> = stat.iter().chain(&moved).copied().collect();
    let brute = BruteForce::new(&all);
    let both = psf.with_dynamic(&layer);
    for (from, rs) in &batches {
        let d = first_difference(&both, &brute, rs);
        prop_assert!(
            d.is_none(),
            "next frame, from the point {}, seed {}: {}",
            from,
            k.seed,
            d.unwrap_or_default()
        );
    }
    Ok(())
}

fn cases() -> impl Strategy<Value = Case> {
    (
        any::<u64>(),
        0u32..=2,
        1u32..=48,
        0usize..200,
        0usize..200,
        0usize..3,
        prop_oneof![Just(0usize), Just(3), 0usize..100],
    )
        .prop_map(
            |(seed, level, tiles, statics, moving, where_, stray)| Case {
                seed,
                params: PsfParams { level, tiles },
                statics,
                moving,
                where_,
                stray,
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 160, ..ProptestConfig::default() })]

    #[test]
    fn point_grids_agree_with_brute_force(k in cases()) {
        check(&k)?;
    }
}

/// The point grid must be what these batches take: a camera's rays (one origin) and
/// shadow rays ending short of a light (lines through it, found by least squares).
#[test]
fn camera_and_light_batches_take_the_point_grid() {
    let mut rng = Rng::new(7);
    let (_, psf) = room(&mut rng, 0, 0.0);
    let mut layer = DynamicLayer::new(&psf);
    layer
        .update(&synth::soup(&mut rng, 100, LO, HI, 0.5))
        .expect("update");
    let both = psf.with_dynamic(&layer);
    let c = Vec3::new(4.0, 3.0, 5.0);
    assert!(both.point_grid_for(&rays(&mut rng, 1000, c, 0, true, &[])));
    assert!(both.point_grid_for(&rays(&mut rng, 1000, c, 0, false, &[])));
    // Reflections go every way from everywhere: no point, no grid.
    let scattered: Vec<Ray> = (0..1000)
        .map(|_| Ray::new(rng.in_box(LO, HI), rng.unit()))
        .collect();
    assert!(!both.point_grid_for(&scattered));
    // Too small a batch (under 256 rays) to pay for a grid.
    assert!(!both.point_grid_for(&rays(&mut rng, 100, c, 0, true, &[])));
}

/// The box room with `n` random triangles of about `size` inside, and its PSF baked with
/// the parameters the renderer picks.
fn room(rng: &mut Rng, n: usize, size: f32) -> (Vec<[Vec3; 3]>, Psf) {
    let mut stat = synth::box_faces(LO, HI);
    stat.extend(synth::soup(rng, n, LO, HI, size));
    let psf = Psf::build(&stat, &PsfParams::for_triangles(stat.len())).expect("bake");
    (stat, psf)
}

/// Rays from `c` within `spread` of `axis` (a camera's view, wider or narrower).
fn view(rng: &mut Rng, n: usize, c: Vec3, axis: Vec3, spread: f32) -> Vec<Ray> {
    (0..n)
        .map(|_| Ray::new(c, (axis + rng.unit() * spread).normalize()))
        .collect()
}

/// `n` shadow rays towards `light` from points all over the room, stopping short of it.
fn towards(rng: &mut Rng, n: usize, light: Vec3) -> Vec<Ray> {
    (0..n)
        .map(|_| {
            let o = rng.in_box(LO, HI);
            let l = light - o;
            Ray::segment(o, l / l.length(), 1e-3, l.length() * (1.0 - 1e-4))
        })
        .collect()
}

/// The first ray on which `got` and `want` answer differently (closest hit, then any
/// hit), described; `None` when they agree on every ray.
/// `rs` cut into lists of uneven lengths, some empty, as a renderer's blocks hand
/// their rays to `intersect_lists`.
fn lists_of(rs: &[Ray]) -> Vec<&[Ray]> {
    const LENGTHS: [usize; 10] = [0, 1, 37, 1024, 0, 500, 3, 2048, 0, 129];
    let mut lists = Vec::new();
    let mut at = 0;
    for k in 0.. {
        if at == rs.len() {
            break;
        }
        let n = LENGTHS[k % LENGTHS.len()].min(rs.len() - at);
        lists.push(&rs[at..at + n]);
        at += n;
    }
    lists.push(&rs[at..]);
    lists
}

/// The first ray whose answer differs between `got` and `want`, as batches, and with
/// `got` given the rays as lists (`intersect_lists`, `occluded_lists`).
fn first_difference(got: &dyn Intersector, want: &dyn Intersector, rs: &[Ray]) -> Option<String> {
    let n = rs.len();
    let lists = lists_of(rs);
    let (mut a, mut b, mut c) = (vec![None; n], vec![None; n], vec![None; n]);
    got.intersect_batch(rs, &mut a);
    want.intersect_batch(rs, &mut b);
    got.intersect_lists(&lists, &mut c);
    let closest = differs("closest hit", rs, &a, &b)
        .or_else(|| differs("closest hit through lists", rs, &c, &b));
    if closest.is_some() {
        return closest;
    }
    let (mut a, mut b, mut c) = (vec![false; n], vec![false; n], vec![false; n]);
    got.occluded_batch(rs, &mut a);
    want.occluded_batch(rs, &mut b);
    got.occluded_lists(&lists, &mut c);
    differs("any hit", rs, &a, &b).or_else(|| differs("any hit through lists", rs, &c, &b))
}

/// The first ray whose answer in `got` is not `want`'s, described.
fn differs<T: PartialEq + std::fmt::Debug>(
    what: &str,
    rs: &[Ray],
    got: &[T],
    want: &[T],
) -> Option<String> {
    let i = (0..rs.len()).find(|&i| got[i] != want[i])?;
    Some(format!(
        "{what} differs: ray {i} {:?}: {:?} against {:?}",
        rs[i], got[i], want[i]
    ))
}

fn assert_agrees(got: &dyn Intersector, want: &dyn Intersector, rs: &[Ray], what: &str) {
    if let Some(d) = first_difference(got, want, rs) {
        panic!("{d}: {what}");
    }
}

/// A frame without moving triangles after one with many: the point grids of its
/// batches are built over the layer's triangles, and must find none of the last
/// frame's (they once did: the layer's sorted copies outlived an empty update, and a
/// camera batch reported hits on triangles gone). Then a refused update, the same.
#[test]
fn an_empty_frame_leaves_no_moving_triangle_behind() {
    let mut rng = Rng::new(31);
    let (stat, psf) = room(&mut rng, 0, 0.0);
    let brute = BruteForce::new(&stat);
    let mut layer = DynamicLayer::new(&psf);
    let c = Vec3::new(4.0, 3.0, 5.0);
    let crowd = synth::soup(&mut rng, 400, LO + 1.0, HI - 1.0, 0.8);
    let bad = [[Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ONE]];
    for (what, next) in [("empty", &[][..]), ("refused", &bad[..])] {
        layer.update(&crowd).expect("update");
        let _ = layer.update(next);
        assert!(layer.is_empty(), "{what}");
        let both = psf.with_dynamic(&layer);
        let primary = view(&mut rng, 4000, c, Vec3::X, 0.9);
        assert!(both.point_grid_for(&primary), "{what}");
        assert_agrees(&both, &brute, &primary, what);
    }
}

/// A camera that stays put over frames while its view changes: the static grid kept
/// from the first frame serves the views within it and is built again, wider, for one
/// beyond it. Every frame agrees with brute force, and takes a grid.
#[test]
fn kept_grids_serve_later_frames() {
    let mut rng = Rng::new(23);
    let (stat, psf) = room(&mut rng, 3000, 0.3);
    let mut layer = DynamicLayer::new(&psf);
    let c = Vec3::new(4.0, 3.0, 5.0);
    let light = Vec3::new(2.0, 7.0, 2.0);
    // Narrow, wider (beyond the kept rectangles), narrow again, another way.
    let views = [
        (Vec3::X, 0.3),
        (Vec3::X, 0.9),
        (Vec3::X, 0.2),
        (Vec3::NEG_Z, 0.5),
    ];
    for (frame, &(axis, spread)) in views.iter().enumerate() {
        let moving = synth::soup(&mut rng, 100, LO + 1.0, HI - 1.0, 0.6);
        layer.update(&moving).expect("update");
        let all: Vec<[Vec3; 3]> = stat.iter().chain(&moving).copied().collect();
        let brute = BruteForce::new(&all);
        let both = psf.with_dynamic(&layer);
        let primary = view(&mut rng, 4000, c, axis, spread);
        assert!(both.point_grid_for(&primary), "frame {frame}");
        assert_agrees(&both, &brute, &primary, &format!("camera, frame {frame}"));
        let shadow = towards(&mut rng, 4000, light);
        assert_agrees(&both, &brute, &shadow, &format!("light, frame {frame}"));
        assert_agrees(
            &psf,
            &BruteForce::new(&stat),
            &primary,
            &format!("static, frame {frame}"),
        );
    }
}

/// Shadow rays towards one light come in a batch at each depth level of a frame: the
/// grid merged for the first (the static grid kept around the light and the moving
/// triangles' grid on its tiles) serves the later ones, and an update's triangles get
/// their own. Every batch, from points all over the room, agrees with brute force
/// frame after frame as the moving triangles jump about.
#[test]
fn a_frames_shadow_batches_share_their_grid_and_the_next_frame_does_not() {
    let mut rng = Rng::new(29);
    let (stat, psf) = room(&mut rng, 3000, 0.3);
    let mut layer = DynamicLayer::new(&psf);
    let light = Vec3::new(2.0, 7.0, 2.0);
    for frame in 0..4 {
        let moving = synth::soup(&mut rng, 400, LO + 1.0, HI - 1.0, 0.8);
        layer.update(&moving).expect("update");
        let all: Vec<[Vec3; 3]> = stat.iter().chain(&moving).copied().collect();
        let brute = BruteForce::new(&all);
        let both = psf.with_dynamic(&layer);
        for level in 0..3 {
            let shadow = towards(&mut rng, 6000, light);
            assert_agrees(
                &both,
                &brute,
                &shadow,
                &format!("light, frame {frame}, level {level}"),
            );
        }
    }
}

/// A batch too small to pay for a grid over all the static triangles takes none the
/// first time; its point seen again, the static grid is built (and kept), and the hits
/// are brute force's either way.
#[test]
fn a_point_seen_again_gets_a_grid() {
    let mut rng = Rng::new(29);
    let (stat, psf) = room(&mut rng, 20_000, 0.2);
    let brute = BruteForce::new(&stat);
    let light = Vec3::new(4.0, 4.0, 4.0);
    // Shadow rays from all around: all six faces, 1,500 rays for 20,000 triangles
    // (a grid pays for a twelfth as many rays as triangles times faces; one seen again,
    // for an eighth of that).
    let rs: Vec<Ray> = (0..1500)
        .map(|_| {
            let o = rng.in_box(LO, HI);
            let l = light - o;
            Ray::segment(o, l / l.length(), 0.0, l.length() * (1.0 - 1e-4))
        })
        .collect();
    assert!(
        !psf.point_grid_for(&rs),
        "one batch does not pay for the grid"
    );
    assert!(psf.point_grid_for(&rs), "a point seen again gets a grid");
    assert_agrees(&psf, &brute, &rs, "the light's kept grid");
    // Rays that do not pass the light do not take it.
    let other: Vec<Ray> = rs.iter().map(|r| Ray::new(r.origin, rng.unit())).collect();
    assert!(!psf.point_grid_for(&other));
    assert_agrees(&psf, &brute, &other, "rays away from the light");
}

/// A batch mixing rays through several points (a camera's, a light's, and reflections
/// off a plane, which pass the camera's mirror image in it) with scattered ones: each
/// group takes a grid of its own, the rest the parallel subfields, and every answer is
/// brute force's, frame after frame.
#[test]
fn several_points_in_one_batch() {
    for seed in 0..6 {
        let mut rng = Rng::new(100 + seed);
        let (stat, psf) = room(&mut rng, 400, 0.8);
        let mut layer = DynamicLayer::new(&psf);
        let eye = rng.in_box(LO + 1.0, HI - 1.0);
        let light = rng.in_box(LO + 1.0, HI - 1.0);
        // The floor (y = 0) seen from `eye` reflects rays through `mirror`.
        let mirror = Vec3::new(eye.x, -eye.y, eye.z);
        for frame in 0..3 {
            let moving = synth::soup(&mut rng, 150, LO + 1.0, HI - 1.0, 0.7);
            layer.update(&moving).expect("update");
            let all: Vec<[Vec3; 3]> = stat.iter().chain(&moving).copied().collect();
            let brute = BruteForce::new(&all);
            let both = psf.with_dynamic(&layer);
            let mut rs = Vec::new();
            // In runs of neighbours, as a renderer's rays come (pixel after pixel).
            for i in 0..6000 {
                let p = rng.in_box(LO, HI);
                rs.push(match (i / 40) % 5 {
                    0 | 1 => Ray::new(eye, rng.unit()),
                    2 => {
                        let l = light - p;
                        Ray::segment(p, l / l.length(), 0.0, l.length() * (1.0 - 1e-4))
                    }
                    3 => {
                        // From a point of the floor, away from the mirror image.
                        let o = Vec3::new(p.x, 0.0, p.z);
                        Ray::segment(o, (o - mirror).normalize(), 1e-3, f32::INFINITY)
                    }
                    _ => Ray::new(p, rng.unit()),
                });
            }
            assert!(both.point_grid_for(&rs), "seed {seed} frame {frame}");
            let what = format!("seed {seed}, frame {frame}");
            assert_agrees(&both, &brute, &rs, &what);
            assert_agrees(&psf, &BruteForce::new(&stat), &rs, &what);
        }
    }
}

/// A camera that stays put has its static grid built once and kept, one grid however
/// many batches; one that moves leaves at most eight behind.
#[test]
fn kept_grids_are_one_a_point_and_eight_at_most() {
    let mut rng = Rng::new(31);
    let (stat, psf) = room(&mut rng, 2000, 0.3);
    let brute = BruteForce::new(&stat);
    let eye = Vec3::new(4.0, 3.0, 4.0);
    for k in 0..4 {
        let rs = view(&mut rng, 3000, eye, Vec3::Z, 0.4);
        assert_agrees(&psf, &brute, &rs, &format!("fixed camera, batch {k}"));
        assert_eq!(psf.kept_point_grids(), 1, "batch {k}");
    }
    for k in 0..12 {
        let eye = Vec3::new(0.5 + 0.5 * k as f32, 3.0, 4.0);
        let rs = view(&mut rng, 3000, eye, Vec3::Z, 0.4);
        let (mut got, mut want) = (vec![None; rs.len()], vec![None; rs.len()]);
        psf.intersect_batch(&rs, &mut got);
        brute.intersect_batch(&rs, &mut want);
        assert_eq!(got, want, "moving camera, batch {k}");
        assert_eq!(
            psf.kept_point_grids(),
            (k + 2).min(8),
            "moving camera, batch {k}"
        );
    }
}

/// The cache's capacity bounds the grids kept (the least recently used dropped, at
/// once when it shrinks), `clear` drops them all, and neither changes a hit.
#[test]
fn kept_grids_follow_the_capacity_and_clear() {
    let mut rng = Rng::new(37);
    let (stat, psf) = room(&mut rng, 2000, 0.3);
    let brute = BruteForce::new(&stat);
    assert_eq!(psf.point_grid_capacity(), 8, "the default");
    psf.set_point_grid_capacity(3);
    for k in 0..6 {
        let eye = Vec3::new(0.5 + 0.5 * k as f32, 3.0, 4.0);
        let rs = view(&mut rng, 3000, eye, Vec3::Z, 0.4);
        assert_agrees(&psf, &brute, &rs, &format!("capacity 3, batch {k}"));
        assert!(psf.kept_point_grids() <= 3, "batch {k}");
    }
    assert_eq!(psf.kept_point_grids(), 3);
    psf.set_point_grid_capacity(1);
    assert_eq!(psf.kept_point_grids(), 1, "shrunk at once");
    psf.clear_point_grids();
    assert_eq!(psf.kept_point_grids(), 0, "cleared");
    assert_eq!(psf.point_grid_capacity(), 1, "the capacity stays");
    psf.set_point_grid_capacity(0);
    let eye = Vec3::new(4.0, 3.0, 4.0);
    for k in 0..2 {
        let rs = view(&mut rng, 3000, eye, Vec3::Z, 0.4);
        assert_agrees(&psf, &brute, &rs, &format!("capacity 0, batch {k}"));
        assert_eq!(psf.kept_point_grids(), 0, "none kept, batch {k}");
    }
}
