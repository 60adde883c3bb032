//! The dynamic layer over sequences of frames: after every update, the static PSF and
//! the layer queried together must agree with brute force over the static triangles
//! plus the current moving ones — the same closest hit (triangle, t, barycentrics) and
//! the same any-hit answer. Frames make the triangles jump anywhere, leave the bounds
//! and come back, pile into one tile, shrink to zero area, and change in number, so a
//! stale list from an earlier frame or a missed insertion shows up as a wrong hit.
//!
//! proptest prints the failing `Case` (seed included) and shrinks it.

use glam::Vec3;
use proptest::prelude::*;
use subfield::gen::synth::{self, Rng};
use subfield::geometry::{closest_of, BruteForce, Intersector, Ray};
use subfield::{DynamicLayer, Psf, PsfParams};

#[derive(Clone, Debug)]
struct Case {
    seed: u64,
    static_params: PsfParams,
    /// The dynamic layer's own level and tile count (`None`: those of the static PSF),
    /// and a number that picks how many of the level's directions it lists in.
    dynamic_params: Option<(PsfParams, usize)>,
    moving: usize,
    frames: usize,
    rays: usize,
}

const LO: Vec3 = Vec3::splat(0.0);
const HI: Vec3 = Vec3::splat(8.0);

fn static_scene(rng: &mut Rng) -> Vec<[Vec3; 3]> {
    let mut tris = synth::box_faces(LO, HI);
    let n = rng.below(150);
    let size = rng.range(0.1, 3.0);
    tris.extend(synth::soup(rng, n, LO, HI, size));
    if rng.below(2) == 0 {
        tris.extend(synth::sphere(Vec3::splat(4.0), 1.5, 6, 9));
    }
    tris
}

/// One triangle of size about `s` around `c`.
fn tri_at(rng: &mut Rng, c: Vec3, s: f32) -> [Vec3; 3] {
    [c + rng.unit() * s, c + rng.unit() * s, c + rng.unit() * s]
}

/// This frame's moving triangles. The count changes from frame to frame too.
fn frame_tris(rng: &mut Rng, n: usize) -> (Vec<[Vec3; 3]>, &'static str) {
    let n = if rng.below(3) == 0 {
        rng.below(2 * n + 1)
    } else {
        n
    };
    let far = |rng: &mut Rng| {
        let mut c = rng.in_box(LO, HI);
        c[rng.below(3)] += if rng.below(2) == 0 { 1.0 } else { -1.0 } * rng.range(20.0, 5000.0);
        c
    };
    let mode = rng.below(6);
    let mut out = Vec::with_capacity(n);
    let pile = rng.in_box(LO, HI);
    for _ in 0..n {
        let k = if mode == 5 { rng.below(5) } else { mode };
        let t = match k {
            // jump anywhere inside the static bounds
            0 => {
                let c = rng.in_box(LO - 1.0, HI + 1.0);
                let s = rng.range(0.01, 2.0);
                tri_at(rng, c, s)
            }
            // leave the bounds, far away
            1 => {
                let c = far(rng);
                let s = rng.range(0.1, 20.0);
                tri_at(rng, c, s)
            }
            // pile into one tile
            2 => {
                let c = pile + rng.unit() * 1e-3;
                tri_at(rng, c, 1e-3)
            }
            // vanish to zero area: a point, or a segment
            3 => {
                let a = rng.in_box(LO, HI);
                if rng.below(2) == 0 {
                    [a, a, a]
                } else {
                    let b = rng.in_box(LO, HI);
                    [a, b, a.lerp(b, rng.f32())]
                }
            }
            // straddle the bounds: one vertex far, two inside
            _ => {
                let a = rng.in_box(LO, HI);
                let b = rng.in_box(LO, HI);
                [a, b, far(rng)]
            }
        };
        out.push(t);
    }
    let name = ["jump", "leave", "pile", "vanish", "straddle", "mixed"][mode];
    (out, name)
}

fn rays(rng: &mut Rng, n: usize, moving: &[[Vec3; 3]], before: &[[Vec3; 3]]) -> Vec<Ray> {
    let mut out = Vec::with_capacity(n);
    // A point on a triangle (or its centroid region).
    let on = |rng: &mut Rng, t: &[Vec3; 3]| {
        let (a, b) = (rng.f32(), rng.f32());
        let (a, b) = if a + b > 1.0 {
            (1.0 - a, 1.0 - b)
        } else {
            (a, b)
        };
        t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b
    };
    while out.len() < n {
        let inside = rng.in_box(LO, HI);
        let ray = match rng.below(7) {
            // through a vertex or along an edge of a moving triangle: hits on the
            // boundaries between triangles, and in the corners of tiles
            5 if !moving.is_empty() => {
                let t = moving[rng.below(moving.len())];
                let a = rng.below(3);
                let p = if rng.below(2) == 0 {
                    t[a]
                } else {
                    t[a].lerp(t[(a + 1) % 3], rng.f32())
                };
                Ray::new(inside, p - inside)
            }
            0 => Ray::new(inside, rng.unit()),
            // at a moving triangle, from near or far
            1 | 2 if !moving.is_empty() => {
                let k = rng.below(moving.len());
                let p = on(rng, &moving[k]);
                let o = if rng.below(2) == 0 {
                    inside
                } else {
                    p + rng.unit() * rng.range(0.01, 100.0)
                };
                Ray::new(o, p - o)
            }
            // at where a triangle was last frame: a stale entry would answer
            3 if !before.is_empty() => {
                let k = rng.below(before.len());
                let p = on(rng, &before[k]);
                Ray::new(inside, p - inside)
            }
            // a shadow-ray segment
            4 => {
                let p = rng.in_box(LO, HI);
                Ray::segment(inside, p - inside, 0.0, 1.0)
            }
            // from far outside everything, inwards
            _ => {
                let o = Vec3::splat(4.0) + rng.unit() * rng.range(20.0, 10_000.0);
                Ray::new(o, inside - o)
            }
        };
        out.push(ray);
    }
    out
}

/// This frame's moving triangles gathered tightly (issue 23): every triangle in a ball a
/// few of its widths across (the shared generator's clusters), on a thin spherical
/// shell, stacked on one another (each spanning the whole grid, ties between equal
/// copies decided by the triangle number), a ball with a few far outliers (the bounds
/// wide, the triangles small), or a ball of large triangles beside tiny ones.
fn clustered_tris(rng: &mut Rng, n: usize) -> (Vec<[Vec3; 3]>, &'static str) {
    let n = if rng.below(4) == 0 {
        1 + rng.below(2 * n + 1)
    } else {
        n
    };
    let mode = rng.below(5);
    let c = rng.in_box(LO + 1.0, HI - 1.0);
    let s = rng.range(0.02, 1.0);
    let mut out = Vec::with_capacity(n);
    let base = tri_at(rng, c, s);
    for k in 0..n {
        let t = match mode {
            // a ball 2-5 triangle widths across
            0 => {
                let r = s * rng.range(1.0, 2.5);
                let p = c + rng.unit() * r * rng.f32().cbrt();
                tri_at(rng, p, s)
            }
            // a thin shell: triangles tangent-ish to a sphere of a few widths
            1 => {
                let r = s * rng.range(1.5, 3.0);
                let u = rng.unit();
                let p = c + u * r;
                let (a, b) = u.any_orthonormal_pair();
                let w = s * rng.range(0.5, 1.0);
                [
                    p + a * w,
                    p - a * w * 0.5 + b * w,
                    p - a * w * 0.5 - b * w + u * 1e-4,
                ]
            }
            // stacked: copies of one triangle, some exact, some a hair apart
            2 => {
                if rng.below(2) == 0 {
                    base
                } else {
                    base.map(|v| v + rng.unit() * 1e-5)
                }
            }
            // a ball with a few far outliers
            3 => {
                if k % 97 == 1 {
                    let mut p = c;
                    p[rng.below(3)] += rng.range(20.0, 2000.0);
                    tri_at(rng, p, s)
                } else {
                    let p = c + rng.unit() * s * 2.0 * rng.f32();
                    tri_at(rng, p, s)
                }
            }
            // a ball of mixed sizes: large triangles among tiny ones
            _ => {
                let p = c + rng.unit() * s * 2.0 * rng.f32();
                let size = if rng.below(3) == 0 { s * 3.0 } else { s * 0.02 };
                tri_at(rng, p, size)
            }
        };
        out.push(t);
    }
    let name = ["ball", "shell", "stacked", "ball+outliers", "mixed sizes"][mode];
    (out, name)
}

fn check(c: &Case) -> Result<(), TestCaseError> {
    check_with(c, frame_tris)
}

type FrameGen = fn(&mut Rng, usize) -> (Vec<[Vec3; 3]>, &'static str);

fn check_with(c: &Case, frame_tris: FrameGen) -> Result<(), TestCaseError> {
    let mut rng = Rng::new(c.seed);
    let stat = static_scene(&mut rng);
    let psf = Psf::build(&stat, &c.static_params).expect("bake");
    let mut layer = match c.dynamic_params {
        Some((p, g)) => {
            let all = DynamicLayer::with_params(p).expect("params").grids();
            DynamicLayer::with_grids(p, 1 + g % all).expect("grids")
        }
        None => DynamicLayer::new(&psf),
    };
    let mut before: Vec<[Vec3; 3]> = Vec::new();
    for frame in 0..c.frames {
        let (moving, mode) = frame_tris(&mut rng, c.moving);
        layer.update(&moving).expect("update");
        let all: Vec<[Vec3; 3]> = stat.iter().chain(&moving).copied().collect();
        let brute = BruteForce::new(&all);
        let both = psf.with_dynamic(&layer);
        let rs = rays(&mut rng, c.rays, &moving, &before);
        let (mut got, mut want) = (vec![None; rs.len()], vec![None; rs.len()]);
        both.intersect_batch(&rs, &mut got);
        brute.intersect_batch(&rs, &mut want);
        let (mut og, mut ow) = (vec![false; rs.len()], vec![false; rs.len()]);
        both.occluded_batch(&rs, &mut og);
        brute.occluded_batch(&rs, &mut ow);
        for i in 0..rs.len() {
            prop_assert_eq!(
                got[i],
                want[i],
                "closest hit differs: frame {} ({}), ray {} {:?}, seed {}",
                frame,
                mode,
                i,
                rs[i],
                c.seed
            );
            prop_assert_eq!(
                og[i],
                ow[i],
                "any hit differs: frame {} ({}), ray {} {:?}, seed {}",
                frame,
                mode,
                i,
                rs[i],
                c.seed
            );
        }
        check_layers(&both, &brute, &stat, &rs, frame, mode, c.seed)?;
        // A camera's rays and a light's shadow rays, enough of them through one point
        // that the split's point grids over the moving triangles alone are built.
        let eye = rng.in_box(LO, HI);
        let light = rng.in_box(LO, HI);
        let mut pointed: Vec<Ray> = (0..600)
            .map(|_| Ray::new(eye, rng.in_box(LO - 1.0, HI + 1.0) - eye))
            .collect();
        pointed.extend((0..600).map(|_| {
            let o = rng.in_box(LO, HI);
            Ray::segment(o, light - o, 0.0, 1.0 - 1e-4)
        }));
        check_layers(&both, &brute, &stat, &pointed[..600], frame, mode, c.seed)?;
        check_layers(&both, &brute, &stat, &pointed[600..], frame, mode, c.seed)?;
        before = moving;
    }
    Ok(())
}

/// The static and moving parts traced apart ([`Layers`], as the renderer's memo of
/// static hits does) give brute force's hits: the closer of the static hit and the
/// moving one up to it, and blocked when either part blocks.
fn check_layers(
    both: &impl Intersector,
    brute: &BruteForce,
    stat: &[[Vec3; 3]],
    rs: &[Ray],
    frame: usize,
    mode: &str,
    seed: u64,
) -> Result<(), TestCaseError> {
    let layers = both.layers().expect("a layered query has layers");
    prop_assert_eq!(layers.static_count(), stat.len());
    let n = rs.len();
    let (mut want, mut wany) = (vec![None; n], vec![false; n]);
    brute.intersect_batch(rs, &mut want);
    brute.occluded_batch(rs, &mut wany);
    let (mut s, mut sany) = (vec![None; n], vec![false; n]);
    layers.static_batch(rs, &mut s);
    layers.static_occluded_batch(rs, &mut sany);
    let clipped: Vec<Ray> = rs
        .iter()
        .zip(&s)
        .map(|(r, h)| {
            let mut r = *r;
            if let Some(h) = h {
                r.t_max = h.t;
            }
            r
        })
        .collect();
    let (mut m, mut many) = (vec![None; n], vec![false; n]);
    layers.moving_batch(&clipped, &mut m);
    layers.moving_occluded_batch(rs, &mut many);
    let static_brute = BruteForce::new(stat);
    for i in 0..n {
        prop_assert_eq!(
            s[i],
            static_brute.intersect(&rs[i]),
            "static part's hit differs: frame {} ({}), ray {} {:?}, seed {}",
            frame,
            mode,
            i,
            rs[i],
            seed
        );
        prop_assert_eq!(
            closest_of(s[i], m[i]),
            want[i],
            "split closest hit differs: frame {} ({}), ray {} {:?}, seed {}",
            frame,
            mode,
            i,
            rs[i],
            seed
        );
        prop_assert_eq!(
            sany[i] || many[i],
            wany[i],
            "split any hit differs: frame {} ({}), ray {} {:?}, seed {}",
            frame,
            mode,
            i,
            rs[i],
            seed
        );
    }
    Ok(())
}

fn params() -> impl Strategy<Value = PsfParams> {
    (
        prop_oneof![Just(0u32), Just(1), Just(2)],
        prop_oneof![Just(1u32), Just(4), Just(16), Just(64)],
    )
        .prop_map(|(level, tiles)| PsfParams { level, tiles })
}

fn case() -> impl Strategy<Value = Case> {
    (
        any::<u64>(),
        params(),
        prop_oneof![Just(None), (params(), 0usize..7).prop_map(Some)],
        // The last range crosses `DynamicLayer::PARALLEL_FROM` (2,048), where an update
        // goes from one thread to the pool's.
        prop_oneof![Just(1usize), 2usize..50, 50usize..400, 1900usize..2400],
    )
        .prop_map(|(seed, static_params, dynamic_params, moving)| Case {
            seed,
            static_params,
            dynamic_params,
            moving,
            frames: 6,
            rays: 400,
        })
}

proptest! {
    // 160 cases x 6 frames x 400 rays = 384,000 rays a run, closest and any hit (about
    // 4 s): at 48 cases an empty frame's stale point grids had gone unseen.
    #![proptest_config(ProptestConfig { cases: 160, ..ProptestConfig::default() })]
    #[test]
    fn layered_agrees_with_brute_force_over_frames(c in case()) {
        check(&c)?;
    }
}

proptest! {
    // 64 cases x 6 frames x 400 rays of clustered motion, where the layer lists the
    // triangles in grids coarser than its parameters' (`resolution` in the layer).
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    #[test]
    fn clustered_motion_agrees_with_brute_force(c in case()) {
        check_with(&c, clustered_tris)?;
    }
}

/// A fully dynamic scene (no static triangles at all) works, and an empty update
/// leaves nothing to hit.
#[test]
fn only_moving_triangles_and_empty_frames() {
    let psf = Psf::build(&[], &PsfParams::default()).unwrap();
    let mut layer = DynamicLayer::new(&psf);
    let tri = [
        Vec3::new(-1.0, -1.0, 5.0),
        Vec3::new(1.0, -1.0, 5.0),
        Vec3::new(0.0, 1.0, 5.0),
    ];
    let ray = Ray::new(Vec3::ZERO, Vec3::Z);
    assert_eq!(psf.with_dynamic(&layer).intersect(&ray), None);
    layer.update(&[tri]).unwrap();
    let hit = psf.with_dynamic(&layer).intersect(&ray).expect("hit");
    assert_eq!((hit.tri, hit.t), (0, 5.0));
    layer.update(&[]).unwrap();
    assert_eq!(psf.with_dynamic(&layer).intersect(&ray), None);
    assert!(!psf.with_dynamic(&layer).occluded(&ray));
}

/// Non-finite moving vertices are refused with the triangle named, and leave the layer
/// empty rather than half-updated.
#[test]
fn non_finite_update_is_refused() {
    let psf = Psf::build(&synth::box_faces(LO, HI), &PsfParams::default()).unwrap();
    let mut layer = DynamicLayer::new(&psf);
    let good = [
        Vec3::ONE,
        Vec3::new(2.0, 1.0, 1.0),
        Vec3::new(1.0, 2.0, 1.0),
    ];
    layer.update(&[good]).unwrap();
    let mut bad = good;
    bad[1].y = f32::NAN;
    let err = layer.update(&[good, bad]).unwrap_err().to_string();
    assert!(err.contains("triangle 1"), "{err}");
    assert!(layer.is_empty());
}

/// After the motion has been seen, updates allocate nothing more: the layer's memory is
/// the same after 200 further frames of the same kind of motion.
#[test]
fn memory_is_flat_over_frames() {
    let psf = Psf::build(&synth::box_faces(LO, HI), &PsfParams::default()).unwrap();
    let mut layer = DynamicLayer::new(&psf);
    let mut rng = Rng::new(7);
    let frame = |rng: &mut Rng, layer: &mut DynamicLayer| {
        let tris: Vec<[Vec3; 3]> = (0..2000)
            .map(|_| {
                let c = rng.in_box(LO, HI);
                tri_at(rng, c, 0.2)
            })
            .collect();
        layer.update(&tris).unwrap();
    };
    for _ in 0..50 {
        frame(&mut rng, &mut layer);
    }
    let warm = layer.stats().bytes;
    for _ in 0..200 {
        frame(&mut rng, &mut layer);
    }
    let st = layer.stats();
    assert_eq!(st.triangles, 2000);
    assert!(st.entries >= 2000 * 7, "{st:?}");
    // Lists may still find a rare new maximum; allow 2% growth, not growth per frame.
    assert!(
        st.bytes as f64 <= warm as f64 * 1.02,
        "memory grew from {warm} to {} bytes",
        st.bytes
    );
}

/// A ray aimed exactly at a point of a triangle collapsed onto a segment (the "vanish"
/// frames): the edge functions are rounding noise and could give any `t`, so neither
/// brute force nor the layers report it (this case once made them disagree).
#[test]
fn collinear_triangle_gives_no_rounding_noise_hit() {
    let (a, b) = (
        Vec3::new(0.675_544_7, 1.502_061_8, 3.599_168_8),
        Vec3::new(7.292_999, 7.956_143, 3.074_461),
    );
    let t = [a, b, a.lerp(b, 0.191_837)];
    let o = Vec3::new(3.583_107, 6.536_582, 3.939_263_8);
    let psf = Psf::build(&synth::box_faces(LO, HI), &PsfParams::default()).unwrap();
    let mut layer = DynamicLayer::new(&psf);
    layer.update(&[t]).unwrap();
    for k in 0..=10 {
        let p = t[0].lerp(t[2], k as f32 / 10.0);
        let r = Ray::new(o, p - o);
        assert_eq!(BruteForce::new(&[t]).intersect(&r), None);
        assert_eq!(layer.intersect(&r), None);
    }
}
