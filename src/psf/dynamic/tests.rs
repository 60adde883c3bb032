use super::tiles::DynSubfield;
use super::*;
use crate::gen::synth::{soup, Rng};
use crate::psf::bsp::LANES;

/// The ranks of triangles already in the order their entries name them.
fn identity(n: usize) -> Vec<u32> {
    (0..n as u32).collect()
}

/// A tile's list as (triangle, zmin bits, zmax bits), in list order.
type List = Vec<(u32, u32, u32)>;

/// Each current tile with its list.
fn lists(s: &DynSubfield, gv: u32) -> Vec<(usize, List)> {
    let mut out = Vec::new();
    for (tile, slot) in s.slots.iter().enumerate() {
        if slot.version != gv {
            continue;
        }
        let list = (slot.start..slot.start + slot.count)
            .map(|i| {
                let b = &s.entries.blocks[i as usize / LANES];
                let j = i as usize % LANES;
                (b.tri[j], b.zmin[j].to_bits(), b.zmax[j].to_bits())
            })
            .collect();
        out.push((tile, list));
    }
    out
}

#[test]
fn checked_bounds_are_the_bounds_and_name_any_non_finite_coordinate() {
    let mut rng = Rng::new(11);
    let tris = soup(
        &mut rng,
        333,
        Vec3::splat(-7.0),
        Vec3::new(3.0, 9.0, 1.0),
        2.0,
    );
    let b = checked_bounds(&tris).expect("finite");
    let want = Aabb::from_triangles(&tris);
    assert_eq!((b.min, b.max), (want.min, want.max));
    let e = checked_bounds(&[]).expect("empty");
    assert_eq!((e.min, e.max), (Aabb::EMPTY.min, Aabb::EMPTY.max));
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for vertex in 0..3 {
            for axis in 0..3 {
                let mut t = tris.clone();
                t[200][vertex][axis] = bad;
                t[250][0][0] = bad;
                match checked_bounds(&t) {
                    Err(PsfError::NonFinite {
                        triangle: 200,
                        vertex: v,
                        ..
                    }) => assert_eq!(v, vertex),
                    other => panic!("{bad} at {vertex}/{axis}: {other:?}"),
                }
            }
        }
    }
}

/// The entry buffer is reused from frame to frame: after a frame of many triangles,
/// a frame of fewer leaves every run's last block padded beyond its entries (a stale
/// entry there would be tested, against a triangle that may no longer exist).
#[test]
fn runs_end_in_padding_after_a_larger_frame() {
    let mut rng = Rng::new(5);
    let (lo, hi) = (Vec3::new(-4.0, -2.0, -3.0), Vec3::new(4.0, 2.0, 3.0));
    let many = soup(&mut rng, 3000, lo, hi, 0.4);
    let few = soup(&mut rng, 200, lo, hi, 0.3);
    for dense in [true, false] {
        let layer = DynamicLayer::with_params(PsfParams {
            level: 0,
            tiles: 32,
        });
        let mut s = layer.expect("params").subfields.remove(0);
        for (gv, tris) in [(1, &many), (2, &few)] {
            let bounds = Aabb::from_triangles(tris);
            let margin = margin_for(&bounds);
            let clip = bounds.padded(2.0 * margin);
            s.count(tris, gv, margin, &clip, 32, Some(dense));
            s.write(&identity(tris.len()), gv);
        }
        let mut runs = 0;
        for slot in s.slots.iter().filter(|x| x.version == 2) {
            let (start, end) = (slot.start as usize, (slot.start + slot.count) as usize);
            for i in end..end.next_multiple_of(LANES) {
                let b = &s.entries.blocks[i / LANES];
                let j = i % LANES;
                assert_eq!(
                    (b.zmin[j], b.zmax[j]),
                    (f32::INFINITY, f32::NEG_INFINITY),
                    "dense {dense}: run {start}..{end}, lane {i}"
                );
            }
            runs += 1;
        }
        assert!(runs > 10, "dense {dense}: {runs} runs");
    }
}

#[test]
fn dense_and_tile_by_tile_counting_give_the_same_lists() {
    let mut rng = Rng::new(7);
    // Small triangles (coarse) and large ones (clipped tile by tile).
    let (lo, hi) = (Vec3::new(-4.0, -2.0, -3.0), Vec3::new(4.0, 2.0, 3.0));
    let mut tris = soup(&mut rng, 600, lo, hi, 0.2);
    tris.extend(soup(&mut rng, 20, lo, hi, 5.0));
    let bounds = Aabb::from_triangles(&tris);
    let margin = margin_for(&bounds);
    let clip = bounds.padded(2.0 * margin);
    for level in 0..2 {
        for tiles in [1, 7, 32, 64] {
            let layer = || DynamicLayer::with_params(PsfParams { level, tiles });
            let (da, db) = (layer().expect("params"), layer().expect("params"));
            for (mut a, mut b) in da.subfields.into_iter().zip(db.subfields) {
                a.count(&tris, 3, margin, &clip, tiles, Some(true));
                b.count(&tris, 3, margin, &clip, tiles, Some(false));
                a.write(&identity(tris.len()), 3);
                b.write(&identity(tris.len()), 3);
                let (la, lb) = (lists(&a, 3), lists(&b, 3));
                assert!(!la.is_empty());
                assert_eq!(la, lb, "level {level}, {tiles} tiles, direction {}", a.dir);
            }
        }
    }
}

#[test]
fn grids_are_the_first_directions_of_the_level_and_refused_outside_it() {
    let p = |level| PsfParams { level, tiles: 8 };
    for (level, all) in [(0, 4), (1, 7)] {
        assert_eq!(
            DynamicLayer::with_params(p(level)).expect("params").grids(),
            all
        );
        let dirs = crate::psf::subfield_directions(level);
        for g in 1..=all {
            let layer = DynamicLayer::with_grids(p(level), g).expect("grids");
            let got: Vec<Vec3> = layer.subfields.iter().map(|s| s.dir).collect();
            assert_eq!(got, dirs[..g], "level {level}, {g} grids");
        }
        for g in [0, all + 1] {
            let e = DynamicLayer::with_grids(p(level), g).expect_err("out of range");
            assert!(
                e.to_string()
                    .contains(&format!("grids {g} is outside 1..={all}")),
                "{e}"
            );
        }
    }
    assert_eq!(DynamicLayer::for_triangles(16_384).grids(), 2);
    assert_eq!(DynamicLayer::for_triangles(32_767).grids(), 2);
    assert_eq!(DynamicLayer::for_triangles(32_768).grids(), 4);
    assert_eq!(DynamicLayer::for_triangles(100_000).params().level, 0);
}

/// An update lists in each tile the triangles an insertion of the Morton-sorted copy
/// lists there, each with the same depths and named by its place in that copy; in
/// the input order, where the insertion lists them in the sorted one.
#[test]
fn update_lists_what_an_insertion_of_the_sorted_copy_lists() {
    let mut rng = Rng::new(23);
    let (lo, hi) = (Vec3::new(-4.0, -2.0, -3.0), Vec3::new(4.0, 2.0, 3.0));
    // Below and above `PARALLEL_FROM`: the update on one thread, then on the pool's.
    let small = DynamicLayer::PARALLEL_FROM - 100;
    let sizes = [
        (small, 0, 32, 2),
        (small, 1, 64, 7),
        (900, 0, 7, 4),
        (900, 0, 1, 1),
    ];
    let large = DynamicLayer::PARALLEL_FROM + 400;
    let sizes = sizes
        .into_iter()
        .chain([(large, 0, 32, 2), (large, 1, 16, 7)]);
    for (n, level, tiles, grids) in sizes {
        let mut tris = soup(&mut rng, n, lo, hi, 0.3);
        tris.extend(soup(&mut rng, 15, lo, hi, 5.0));
        let params = PsfParams { level, tiles };
        let mut layer = DynamicLayer::with_grids(params, grids).expect("params");
        // A larger frame first: the buffers it leaves must not show through.
        layer
            .update(&soup(&mut rng, 1500, lo, hi, 0.5))
            .expect("update");
        layer.update(&tris).expect("update");
        let sorted: Vec<[Vec3; 3]> = layer.order.iter().map(|&i| tris[i as usize]).collect();
        let local: Vec<[Vec3; 3]> = layer.local.iter().map(TriPre::vertices).collect();
        assert_eq!(local, sorted);
        for k in 0..tris.len() {
            assert_eq!(layer.rank[layer.order[k] as usize] as usize, k);
        }
        let gv = layer.generation;
        let mut fresh = DynamicLayer::with_grids(params, grids).expect("params");
        for (s, f) in layer.subfields.iter().zip(&mut fresh.subfields) {
            f.count(&sorted, gv, layer.margin, &layer.clip.aabb(), tiles, None);
            f.write(&identity(sorted.len()), gv);
            let (got, want) = (lists(s, gv), lists(f, gv));
            assert_eq!(got.len(), want.len(), "level {level}, {tiles} tiles");
            assert!(want.iter().any(|(_, l)| l.len() > 1));
            for ((tg, lg), (tw, lw)) in got.iter().zip(&want) {
                assert_eq!(tg, tw);
                let input: Vec<u32> = lg.iter().map(|e| layer.order[e.0 as usize]).collect();
                assert!(input.is_sorted(), "tile {tg}: {input:?}");
                let mut sg = lg.clone();
                sg.sort_unstable();
                assert_eq!(sg, *lw, "tile {tg}, level {level}, {tiles} tiles");
            }
        }
    }
}
