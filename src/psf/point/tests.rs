use glam::{DVec3, Vec3};

use super::build::{by_depth, RAYS_PER_TILE};
use super::center::center;
use super::plan::SAMPLE;
use super::project::{aim, down, face_coords, passes, up, EPS_P};
use super::types::{Around, Item, PointGrid, NO_RECT};
use crate::gen::synth::Rng;
use crate::geometry::Ray;

/// `passes` answers `None` for every ray `Ray::is_valid` refuses (a non-finite origin
/// or direction, a zero direction, NaN bounds) without asking it, and for inverted
/// bounds; a ray with bounds in order and finite numbers is judged on its line.
#[test]
fn passes_refuses_what_is_not_a_ray() {
    let special = [
        0.0,
        -0.0,
        1.0,
        -2.5,
        1e-30,
        -3e38,
        f32::MIN_POSITIVE / 8.0,
        f32::MAX,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
    ];
    let mut some = 0;
    for seed in 0..20_000u64 {
        let mut rng = Rng::new(seed);
        // A ray aimed at `c` (so that it qualifies when its numbers allow), then one of
        // its twelve numbers made special.
        let c = DVec3::new(rng.range(-1.0, 1.0) as f64, 0.25, 0.0);
        let origin = Vec3::new(
            rng.range(-4.0, 4.0),
            rng.range(-4.0, 4.0),
            rng.range(-4.0, 4.0),
        );
        let dir = (c.as_vec3() - origin) * rng.range(0.1, 3.0);
        let t = [rng.range(-1.0, 0.5), rng.range(0.5, 2.0)];
        let mut f = [
            origin.x, origin.y, origin.z, dir.x, dir.y, dir.z, t[0], t[1],
        ];
        if rng.below(4) != 0 {
            let k = rng.below(f.len());
            f[k] = special[rng.below(special.len())];
        }
        if rng.below(8) == 0 {
            f[3..6].fill(if rng.below(2) == 0 { 0.0 } else { -0.0 });
        }
        let ray = Ray {
            origin: Vec3::new(f[0], f[1], f[2]),
            dir: Vec3::new(f[3], f[4], f[5]),
            t_min: f[6],
            t_max: f[7],
        };
        let got = passes(c, 0.01, 1e-5, &ray);
        if !ray.is_valid() || ray.t_min > ray.t_max {
            assert_eq!(got, None, "seed {seed}: {ray:?}");
        } else {
            some += usize::from(got.is_some());
        }
    }
    assert!(
        some > 1_000,
        "only {some} rays aimed at the point qualified"
    );
}

/// Each face's coordinates are the axes after the face's own (`u`, `v`), and its own
/// axis, negated for the odd faces (`z`): the rule the grids were built by.
#[test]
fn face_coordinates_follow_the_axes() {
    let (x, y, z) = (1.5, -2.25, 3.125);
    let want = [
        (y, z, x),
        (y, z, -x),
        (z, x, y),
        (z, x, -y),
        (x, y, z),
        (x, y, -z),
    ];
    for (f, w) in want.into_iter().enumerate() {
        assert_eq!(face_coords(f, DVec3::new(x, y, z)), w, "face {f}");
    }
}

#[test]
fn rounding_goes_outwards() {
    let mut rng = Rng::new(3);
    for _ in 0..10_000 {
        let x = (rng.f32() as f64 - 0.5) * 10f64.powi(rng.below(20) as i32 - 10);
        assert!((down(x) as f64) <= x && (up(x) as f64) >= x, "{x}");
        // No further than two units in the last place.
        assert!(((x - down(x) as f64).abs()) <= 2.0 * (x.abs() * 1.2e-7).max(1e-38));
    }
    assert_eq!(down(1e300), f32::MAX);
    assert_eq!(up(-1e300), f32::MIN);
    // Values an f32 holds stay as they are; NaN and the infinities pass through.
    for x in [
        0.0,
        1.0,
        -2.5,
        1e-3f32 as f64,
        f32::MAX as f64,
        f32::MIN_POSITIVE as f64,
    ] {
        assert_eq!((down(x) as f64, up(x) as f64), (x, x), "{x}");
    }
    assert!(down(f64::NAN).is_nan() && up(f64::NAN).is_nan());
    assert_eq!(up(1e300), f32::INFINITY);
    assert_eq!(down(-1e300), f32::NEG_INFINITY);
    assert_eq!(down(f64::INFINITY), f32::INFINITY);
    assert_eq!(up(f64::NEG_INFINITY), f32::NEG_INFINITY);
    // Under f32's normal range: still outwards, within the smallest normal.
    for _ in 0..1_000 {
        let x = (rng.f32() as f64 - 0.5) * 1e-37 * 10f64.powi(-(rng.below(8) as i32));
        assert!((down(x) as f64) <= x && (up(x) as f64) >= x, "{x:e}");
        assert!(
            (x - down(x) as f64).abs() <= 2.0 * f32::MIN_POSITIVE as f64,
            "{x:e}"
        );
    }
}

#[test]
fn rays_qualify_only_on_one_side_of_the_centre() {
    let c = DVec3::new(1.0, 2.0, 3.0);
    let cf = c.as_vec3();
    let (r, rho) = (0.1, 1e-4);
    // From the centre: forwards.
    let from = Ray::new(cf, Vec3::new(0.3, -1.0, 0.2));
    assert_eq!(passes(c, r, rho, &from), Some(true));
    // Towards it, ending short of it: backwards, its face the one it comes from.
    let o = Vec3::new(5.0, 2.0, 3.0);
    let to = Ray::segment(o, (cf - o).normalize(), 0.0, 3.999);
    assert_eq!(passes(c, r, rho, &to), Some(false));
    assert_eq!(aim(c, r, rho, &to).map(|a| a.0), Some(0));
    // Through it, both sides: no.
    let through = Ray::segment(o, (cf - o).normalize(), 0.0, 8.0);
    assert_eq!(passes(c, r, rho, &through), None);
    // Missing it by more than `rho`: no.
    let off = Ray::new(cf + Vec3::new(0.0, 0.0, 1e-3), Vec3::X);
    assert_eq!(passes(c, r, rho, &off), None);
    // Not a ray at all.
    assert_eq!(passes(c, r, rho, &Ray::new(cf, Vec3::ZERO)), None);
}

#[test]
fn items_sort_by_depth_ties_in_order() {
    let mut rng = Rng::new(5);
    for n in [0, 1, 2, 100, 5000] {
        let items: Vec<Item> = (0..n)
            .map(|k| Item {
                // Few distinct depths (ties), spread over many binades.
                zmin: (1 + rng.below(40)) as f32 * 10f32.powi(rng.below(12) as i32 - 6),
                tri: k,
                ..Item::default()
            })
            .collect();
        let mut want = items.clone();
        want.sort_by_key(|it| it.zmin.to_bits());
        let got = by_depth(items);
        let key = |v: &[Item]| v.iter().map(|it| (it.zmin, it.tri)).collect::<Vec<_>>();
        assert_eq!(key(&got), key(&want), "{n} items");
    }
}

/// A kept static grid merged with a moving one lists exactly what one grid built
/// over both sets at once lists, entry for entry and in the same order.
#[test]
fn merged_grids_are_the_grid_over_both() {
    let mut rng = Rng::new(17);
    let at = Around {
        c: DVec3::new(0.5, 1.0, -0.5),
        r: 0.05,
        rho_max: 1e-4,
        reach2: 4.0,
        margin: 1e-4,
    };
    let mut tri = || {
        let a = rng.in_box(Vec3::splat(-6.0), Vec3::splat(6.0));
        let size = 0.05 + 2.0 * rng.f32();
        [a, a + size * rng.unit(), a + size * rng.unit()]
    };
    // One of each set in the near cube, listed apart.
    let c = at.c.as_vec3();
    let near = [c - Vec3::X, c + Vec3::Y, c + Vec3::Z];
    let mut statics: Vec<[Vec3; 3]> = (0..700).map(|_| tri()).collect();
    statics.push(near);
    // Some moving triangles repeat static ones, so that depths tie.
    let mut moving: Vec<[Vec3; 3]> = (0..500).map(|_| tri()).collect();
    moving.extend_from_slice(&statics[..40]);
    moving.push(near);
    // A view over three faces, rays enough for a few hundred tiles.
    let mut rects = [NO_RECT; 6];
    rects[0] = (-0.9, -0.7, 0.8, 0.9, 4000);
    rects[2] = (-1.0, -1.0, 1.0, 1.0, 2000);
    rects[5] = (-0.3, -0.2, 0.4, 0.5, 600);
    let (faces, total) = PointGrid::faces_for(&rects, 0);
    let ns = statics.len();
    let a = PointGrid::build_on(&at, faces, total, 6600, ns, |g| statics[g]).unwrap();
    let b = PointGrid::build_on(&at, faces, total, 6600, moving.len(), |g| moving[g]).unwrap();
    let all = PointGrid::build_on(&at, faces, total, 6600, ns + moving.len(), |g| {
        if g < ns {
            statics[g]
        } else {
            moving[g - ns]
        }
    })
    .unwrap();
    let m = PointGrid::merged(&a, &b, ns as u32);
    let key = |g: &PointGrid| {
        let e: Vec<(u32, u32, u32)> = g
            .entries
            .iter()
            .map(|e| (e.zmin.to_bits(), e.zmax.to_bits(), e.tri))
            .collect();
        (g.starts.clone(), e, g.near.clone())
    };
    assert!(
        all.entries.len() > 1000 && all.near.len() >= 2,
        "a grid worth merging"
    );
    assert_eq!(key(&m), key(&all));
}

/// A triangle whose projection lies beyond a face's grid by less than its `eps`
/// can still be hit by a ray landing in the edge tile: the build's early cull of
/// triangles beyond the grid must leave it listed, and drop one further out.
#[test]
fn triangles_just_beyond_a_grid_stay_listed() {
    let at = Around {
        c: DVec3::ZERO,
        r: 0.05,
        rho_max: 1e-4,
        reach2: 1.0,
        margin: 1e-4,
    };
    // Face 0 looks along +x: `(u, v, z) = (y, z, x)`.
    let mut rects = [NO_RECT; 6];
    rects[0] = (-0.5, -0.5, 0.5, 0.5, 64 * RAYS_PER_TILE);
    let depth = 10.0f64;
    let eps = 4.0 * at.allowance() / depth + EPS_P;
    let probe = |gap: f64| {
        let grid = PointGrid::build(
            &at,
            &rects,
            1,
            |_| {
                // Its projection starts `gap` beyond the rectangle's right side.
                let u = 0.5 + gap;
                [
                    Vec3::new(depth as f32, (u * depth) as f32, 0.0),
                    Vec3::new(depth as f32, ((u + 0.01) * depth) as f32, 0.0),
                    Vec3::new(depth as f32, ((u + 0.01) * depth) as f32, 0.1),
                ]
            },
            0,
        )
        .expect("a small grid");
        let face = grid.faces[0];
        let right = face.u0 + face.nu as f64 / face.inv;
        let edge = face.tile([(right - 1e-6) as f32, 0.0]).expect("inside");
        (right, grid.run(edge).iter().any(|e| e.tri == 0))
    };
    // Whole tiles put the grid's edge at or beyond the rectangle's: measure from it.
    let (right, _) = probe(1.0);
    let beyond = right - 0.5;
    assert!(
        probe(beyond + 0.25 * eps).1,
        "within eps of the edge: listed"
    );
    assert!(!probe(beyond + 0.01).1, "well beyond: not listed");
}

#[test]
fn the_centre_of_shadow_rays_is_found_among_strays() {
    let mut rng = Rng::new(11);
    let light = Vec3::new(2.0, 7.5, -1.0);
    let rays: Vec<Ray> = (0..4000)
        .map(|_| {
            let o = rng.in_box(Vec3::splat(-5.0), Vec3::splat(5.0));
            if rng.below(5) == 0 {
                Ray::new(o, rng.unit())
            } else {
                let l = light - o;
                Ray::segment(o, l / l.length(), 0.0, l.length() * (1.0 - 1e-4))
            }
        })
        .collect();
    let step = rays.len() / SAMPLE;
    let sample: Vec<(&Ray, Option<&Ray>)> = (0..rays.len())
        .step_by(step)
        .map(|i| (&rays[i], rays.get(i + 1)))
        .collect();
    let (c, v) = center(&sample, |c, ray| aim(c, 0.05, 1e-4, ray).is_some()).unwrap();
    assert!((c - light.as_dvec3()).length() < 1e-4, "{c:?}");
    assert!(v * 10 >= sample.len() * 7, "{v} of {}", sample.len());
}

/// The rays `taken` leaves are exactly those `trace_batch` hands to its fallback (the
/// parallel subfields), for a batch from one point mixed with rays through no point,
/// once the batch's point has been seen (as the tuner's sample is classified).
#[test]
fn taken_leaves_what_trace_batch_falls_back_on() {
    use crate::psf::{Psf, PsfParams};
    let mut rng = Rng::new(23);
    let tris = crate::gen::synth::soup(&mut rng, 3000, Vec3::splat(-2.0), Vec3::splat(2.0), 0.2);
    let psf = Psf::build(&tris, &PsfParams::for_static(tris.len())).unwrap();
    let eye = Vec3::new(0.3, 0.4, 6.0);
    let rays: Vec<Ray> = (0..8192)
        .map(|k| {
            if k % 5 == 0 {
                Ray::new(rng.in_box(Vec3::splat(-3.0), Vec3::splat(3.0)), rng.unit())
            } else {
                Ray::new(eye, rng.in_box(Vec3::splat(-2.0), Vec3::splat(2.0)) - eye)
            }
        })
        .collect();
    let src = psf.point_sources();
    psf.point_grids_take(&rays, false);
    let taken = psf.point_grids_take(&rays, false);
    let n = taken.iter().filter(|&&t| t).count();
    assert!(n >= rays.len() / 2 && n < rays.len(), "{n} taken");
    let fell = std::sync::Mutex::new(Vec::new());
    let mut out = vec![None; rays.len()];
    super::trace_batch::<false, _>(
        &rays,
        &mut out,
        &src,
        |h| h,
        |r, o: &mut [Option<crate::geometry::Hit>]| {
            fell.lock().unwrap().extend_from_slice(r);
            o.fill(None);
        },
    );
    let left: Vec<Ray> = rays
        .iter()
        .zip(&taken)
        .filter(|(_, &t)| !t)
        .map(|(r, _)| *r)
        .collect();
    let fell = fell.into_inner().unwrap();
    assert_eq!(left, fell);
    // Any-hit planning likewise takes the eye's rays.
    psf.point_grids_take(&rays, true);
    assert!(
        psf.point_grids_take(&rays, true)
            .iter()
            .filter(|&&t| t)
            .count()
            >= n / 2
    );
}
