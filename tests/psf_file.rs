//! The baked file (`formats/psf-v2.md`): round trip against the PSF built in memory,
//! deterministic bytes, and every kind of damage giving an error that names the section
//! or the cause, never a panic.
//!
//! The fuzz loops below are seeded and bounded; proptest prints the failing case.

mod common;

use common::reseal;

use std::path::PathBuf;
use std::sync::Arc;

use glam::Vec3;
use proptest::prelude::*;
use reseal::reseal;
use subfield::format::{
    self, from_bytes, open_psf, scene_hash, to_bytes, write_psf, Codec, FormatError, OpenOptions,
    WriteOptions,
};
use subfield::gen::synth::{self, Rng};
use subfield::geometry::{Intersector, Ray};
use subfield::{Psf, PsfParams};

// ---------------------------------------------------------------------------------------
// helpers

fn scene(seed: u64, parts: u32) -> Vec<[Vec3; 3]> {
    let mut rng = Rng::new(seed);
    let (lo, hi) = (Vec3::splat(-2.0), Vec3::splat(6.0));
    let mut tris = Vec::new();
    if parts & 1 != 0 {
        let n = 10 + rng.below(150);
        let size = rng.range(0.1, 3.0);
        tris.extend(synth::soup(&mut rng, n, lo, hi, size));
    }
    if parts & 2 != 0 {
        let c = rng.in_box(lo, hi);
        tris.extend(synth::sphere(
            c,
            rng.range(0.3, 2.0),
            4 + rng.below(6),
            5 + rng.below(8),
        ));
    }
    if parts & 4 != 0 {
        tris.extend(synth::box_faces(lo, hi));
    }
    if parts & 8 != 0 {
        let n = 3 + rng.below(10);
        tris.extend(synth::degenerates(&mut rng, n, lo, hi));
    }
    if parts & 16 != 0 {
        let n = 300 + rng.below(700);
        tris.extend(synth::room(&mut rng, n));
    }
    tris
}

fn rays(seed: u64, tris: &[[Vec3; 3]], n: usize) -> Vec<Ray> {
    let mut rng = Rng::new(seed ^ 0x00ff_11ce);
    let b = subfield::Aabb::from_triangles(tris);
    let (ctr, r) = (b.center(), b.extent().length().max(1.0));
    (0..n)
        .map(|k| {
            let target = if !tris.is_empty() && k % 2 == 0 {
                let t = tris[rng.below(tris.len())];
                (t[0] + t[1] + t[2]) / 3.0
            } else {
                ctr + rng.unit() * r * rng.f32()
            };
            let o = ctr + rng.unit() * r * rng.range(0.0, 2.0);
            let mut ray = Ray::new(o, target - o + rng.unit() * 1e-3);
            if k % 7 == 0 {
                ray.t_max = rng.range(0.1, 1.5);
            }
            ray
        })
        .collect()
}

fn open_mem(bytes: &[u8]) -> Result<format::BakedPsf, FormatError> {
    from_bytes(Arc::new(bytes.to_vec()), &OpenOptions::default())
}

fn opts(codec: Codec) -> WriteOptions {
    WriteOptions {
        codec,
        ..Default::default()
    }
}

/// A folder for this test's files, unique per process and name, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        let p = std::env::temp_dir().join(format!("subfield-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The arrays of two PSFs, bit for bit.
fn assert_same_psf(a: &Psf, b: &Psf) {
    assert_eq!(a.params(), b.params());
    assert_eq!(a.margin().to_bits(), b.margin().to_bits());
    assert_eq!(
        bytemuck::cast_slice::<_, u8>(a.triangles()),
        bytemuck::cast_slice::<_, u8>(b.triangles())
    );
    assert_eq!(a.subfields().len(), b.subfields().len());
    for (x, y) in a.subfields().iter().zip(b.subfields()) {
        assert_eq!(bytemuck::bytes_of(&x.frame), bytemuck::bytes_of(&y.frame));
        assert_eq!(
            bytemuck::cast_slice::<_, u8>(&x.tiles),
            bytemuck::cast_slice::<_, u8>(&y.tiles)
        );
        assert_eq!(*x.slab_starts, *y.slab_starts);
        assert_eq!(
            bytemuck::cast_slice::<_, u8>(&x.entries),
            bytemuck::cast_slice::<_, u8>(&y.entries)
        );
    }
}

fn assert_same_hits(a: &Psf, b: &Psf, rays: &[Ray]) {
    for (i, r) in rays.iter().enumerate() {
        assert_eq!(a.intersect(r), b.intersect(r), "ray {i}: {r:?}");
        assert_eq!(a.occluded(r), b.occluded(r), "ray {i}: {r:?}");
    }
}

fn small_psf() -> (Vec<[Vec3; 3]>, Psf) {
    let tris = scene(7, 1 | 2 | 4 | 8);
    let psf = Psf::build(&tris, &PsfParams { level: 1, tiles: 8 }).unwrap();
    (tris, psf)
}

// ---------------------------------------------------------------------------------------
// round trip

#[derive(Clone, Debug)]
struct Case {
    seed: u64,
    parts: u32,
    level: u32,
    tiles: u32,
}

fn case() -> impl Strategy<Value = Case> {
    (any::<u64>(), 0u32..32, 0u32..=2, 1u32..=24).prop_map(|(seed, parts, level, tiles)| Case {
        seed,
        parts,
        level,
        tiles,
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// The tracer opened from a file gives exactly the hits of the one built in memory,
    /// with both codecs, from memory and from a mapped file.
    #[test]
    fn round_trip_gives_the_same_hits(c in case()) {
        let tris = scene(c.seed, c.parts);
        let built = Psf::build(&tris, &PsfParams { level: c.level, tiles: c.tiles }).unwrap();
        let rays = rays(c.seed, &tris, 300);
        let dir = TempDir::new(&format!("rt-{}", c.seed));
        for codec in [Codec::None, Codec::Zstd] {
            let bytes = to_bytes(&built, &opts(codec)).unwrap();
            let mem = open_mem(&bytes).unwrap();
            assert_same_psf(&built, &mem.psf);
            assert_same_hits(&built, &mem.psf, &rays);

            let path = dir.0.join(format!("scene-{codec}.psf"));
            let report = write_psf(&path, &built, &opts(codec)).unwrap();
            prop_assert_eq!(report.file_length, bytes.len() as u64);
            prop_assert_eq!(std::fs::read(&path).unwrap(), bytes.clone());
            let want = OpenOptions { expect_scene_hash: Some(scene_hash(&tris)) };
            let file = open_psf(&path, &want).unwrap();
            assert_same_psf(&built, &file.psf);
            assert_same_hits(&built, &file.psf, &rays);
            prop_assert_eq!(file.header.triangle_count, tris.len() as u64);
            if codec == Codec::None && !tris.is_empty() {
                // Used in place from the mapping.
                prop_assert!(!file.psf.subfields()[0].entries.is_owned());
            }
        }
    }
}

#[test]
fn empty_scene_round_trips() {
    let psf = Psf::build(&[], &PsfParams::default()).unwrap();
    for codec in [Codec::None, Codec::Zstd] {
        let bytes = to_bytes(&psf, &opts(codec)).unwrap();
        let back = open_mem(&bytes).unwrap();
        assert_eq!(back.psf.triangles().len(), 0);
        assert_eq!(back.psf.subfields().len(), 0);
        assert_eq!(back.sections.len(), 2);
    }
}

#[test]
fn zstd_is_smaller_and_level_matters_not_for_hits() {
    let tris = scene(3, 16 | 2);
    let psf = Psf::build(
        &tris,
        &PsfParams {
            level: 2,
            tiles: 16,
        },
    )
    .unwrap();
    let raw = to_bytes(&psf, &opts(Codec::None)).unwrap();
    let z = to_bytes(&psf, &opts(Codec::Zstd)).unwrap();
    assert!(z.len() < raw.len(), "{} vs {}", z.len(), raw.len());
    let z9 = to_bytes(
        &psf,
        &WriteOptions {
            codec: Codec::Zstd,
            zstd_level: 9,
        },
    )
    .unwrap();
    assert_same_psf(&open_mem(&z).unwrap().psf, &open_mem(&z9).unwrap().psf);
}

// ---------------------------------------------------------------------------------------
// determinism

#[test]
fn same_bytes_with_one_or_two_threads() {
    let tris = synth::room(&mut Rng::new(11), 3000);
    let params = PsfParams {
        level: 2,
        tiles: 24,
    };
    let mut files = Vec::new();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        files.push(pool.install(|| {
            let psf = Psf::build(&tris, &params).unwrap();
            [Codec::None, Codec::Zstd].map(|c| to_bytes(&psf, &opts(c)).unwrap())
        }));
    }
    for (c, (one, two)) in files[0].iter().zip(&files[1]).enumerate() {
        assert!(one == two, "codec {c}: bytes differ with 1 and 2 threads");
    }
    // and the same again from a second bake on the global pool
    let psf = Psf::build(&tris, &params).unwrap();
    assert!(to_bytes(&psf, &opts(Codec::Zstd)).unwrap() == files[0][1]);
}

// ---------------------------------------------------------------------------------------
// damage

fn section_name(e: &FormatError) -> Option<&str> {
    match e {
        FormatError::Checksum { section, .. }
        | FormatError::Truncated { section, .. }
        | FormatError::Invalid { section, .. } => Some(section),
        _ => None,
    }
}

#[test]
fn a_flipped_byte_in_any_section_names_that_section() {
    let (_, psf) = small_psf();
    for codec in [Codec::None, Codec::Zstd] {
        let good = to_bytes(&psf, &opts(codec)).unwrap();
        let sections = open_mem(&good).unwrap().sections;
        assert_eq!(sections.len(), 2 + 4 * psf.subfields().len());
        let mut checked = 0;
        for s in &sections {
            if s.stored_length == 0 {
                continue;
            }
            for at in [0, s.stored_length / 2, s.stored_length - 1] {
                let mut bad = good.clone();
                bad[(s.offset + at) as usize] ^= 0x10;
                let err = open_mem(&bad).unwrap_err();
                match &err {
                    FormatError::Checksum {
                        section,
                        expected,
                        found,
                    } => {
                        assert_eq!(section, &s.id.to_string(), "{codec}: {err}");
                        assert_eq!(*expected, s.stored_checksum);
                        assert_ne!(expected, found);
                    }
                    _ => panic!("{codec} {}: expected a checksum error, got {err}", s.id),
                }
                assert!(err.to_string().contains(&s.id.to_string()), "{err}");
                checked += 1;
            }
        }
        assert!(checked >= 3 * sections.len() / 2, "{checked}");
    }
}

#[test]
fn a_flipped_byte_in_header_table_or_padding_is_caught() {
    let (_, psf) = small_psf();
    let good = to_bytes(&psf, &opts(Codec::Zstd)).unwrap();
    let sections = open_mem(&good).unwrap().sections;
    // every header byte
    for at in 0..128 {
        let mut bad = good.clone();
        bad[at] ^= 0x01;
        let err = open_mem(&bad).unwrap_err();
        match (&err, at) {
            (FormatError::Magic(m), 0..=7) => assert_eq!(m[..], bad[..8]),
            (
                FormatError::Version {
                    found,
                    supported: 3,
                },
                8..=11,
            ) => {
                assert_eq!(*found, 3 ^ (1 << (8 * (at - 8))))
            }
            // 3 with its low bit flipped is 2, a version this build reads: the header
            // checksum catches it.
            (FormatError::Checksum { section, .. }, 8) => assert_eq!(section, "header"),
            (FormatError::NotSupported { what }, 12..=15) => assert!(what.contains("byte-order")),
            (FormatError::Checksum { section, .. }, 16..) => assert_eq!(section, "header"),
            _ => panic!("header byte {at}: {err}"),
        }
    }
    // every table byte
    let table_end = 128 + 48 * sections.len();
    for at in 128..table_end {
        let mut bad = good.clone();
        bad[at] ^= 0x80;
        let err = open_mem(&bad).unwrap_err();
        assert_eq!(
            section_name(&err),
            Some("section table"),
            "table byte {at}: {err}"
        );
    }
    // padding between sections
    let mut gaps = 0;
    for w in sections.windows(2) {
        if w[1].offset > w[0].end() {
            let mut bad = good.clone();
            bad[w[0].end() as usize] = 1;
            let err = open_mem(&bad).unwrap_err();
            assert_eq!(
                section_name(&err),
                Some(format!("padding before {}", w[1].id).as_str()),
                "{err}"
            );
            gaps += 1;
        }
    }
    assert!(gaps > 0);
}

#[test]
fn truncation_names_the_section_it_cuts() {
    let (_, psf) = small_psf();
    let dir = TempDir::new("trunc");
    for codec in [Codec::None, Codec::Zstd] {
        let good = to_bytes(&psf, &opts(codec)).unwrap();
        let sections = open_mem(&good).unwrap().sections;
        let mut cuts: Vec<(usize, String)> = vec![
            (0, "header".into()),
            (5, "header".into()),
            (127, "header".into()),
            (128, "section table".into()),
            (128 + 48 * sections.len() - 1, "section table".into()),
        ];
        for s in sections.iter().filter(|s| s.stored_length > 1) {
            cuts.push(((s.offset + s.stored_length / 2) as usize, s.id.to_string()));
        }
        cuts.push((good.len() - 1, sections.last().unwrap().id.to_string()));
        for (len, name) in cuts {
            let err = open_mem(&good[..len]).unwrap_err();
            match &err {
                FormatError::Truncated {
                    section,
                    needed,
                    have,
                } => {
                    assert_eq!(section, &name, "{codec}, cut at {len}: {err}");
                    assert_eq!(*have, len as u64);
                    assert!(*needed > *have);
                }
                _ => panic!("{codec}, cut at {len}: {err}"),
            }
            // the same from a file on disk (mapped, or read when shorter than a header)
            let path = dir.0.join("cut.psf");
            std::fs::write(&path, &good[..len]).unwrap();
            let err2 = open_psf(&path, &OpenOptions::default()).unwrap_err();
            assert_eq!(err.to_string(), err2.to_string());
        }
        // and bytes after the end
        let mut long = good.clone();
        long.extend_from_slice(&[0; 64]);
        let err = open_mem(&long).unwrap_err();
        assert_eq!(section_name(&err), Some("file"), "{err}");
    }
}

#[test]
fn wrong_magic_version_or_byte_order() {
    let (_, psf) = small_psf();
    let good = to_bytes(&psf, &opts(Codec::None)).unwrap();
    let mut bad = good.clone();
    bad[..4].copy_from_slice(b"glTF");
    // A glTF scene given for its bake says what it is (issue 35).
    assert!(matches!(
        open_mem(&bad),
        Err(FormatError::GltfScene { kind: "GLB" })
    ));
    assert!(matches!(
        open_mem(b" \n{\"asset\": {\"version\": \"2.0\"}}"),
        Err(FormatError::GltfScene { kind: "JSON" })
    ));
    assert!(matches!(
        open_mem(b"PK\x03\x04"),
        Err(FormatError::Magic(_))
    ));

    // A newer file, and a version 1 file (before flat tiles): both refused by name.
    for v in [4u32, 1] {
        let mut other = good.clone();
        other[8..12].copy_from_slice(&v.to_le_bytes());
        let err = open_mem(&other).unwrap_err();
        assert!(
            matches!(err, FormatError::Version { found, supported: 3 } if found == v),
            "{err}"
        );
        assert!(err.to_string().contains("re-bake"), "{err}");
    }

    let mut be = good.clone();
    be[12..16].copy_from_slice(&0x0A0B_0C0Du32.to_be_bytes());
    assert!(matches!(
        open_mem(&be),
        Err(FormatError::NotSupported { .. })
    ));
}

#[test]
fn a_stale_scene_is_refused_with_a_clear_message() {
    let (tris, psf) = small_psf();
    let bytes = Arc::new(to_bytes(&psf, &opts(Codec::Zstd)).unwrap());
    let mine = scene_hash(&tris);
    let mut moved = tris.clone();
    moved[3][1].x += 1e-3;
    let other = scene_hash(&moved);
    assert_ne!(mine, other);
    let err = from_bytes(
        bytes.clone(),
        &OpenOptions {
            expect_scene_hash: Some(other),
        },
    )
    .unwrap_err();
    match &err {
        FormatError::StaleScene { expected, found } => {
            assert_eq!((*expected, *found), (other, mine));
        }
        _ => panic!("{err}"),
    }
    let msg = err.to_string();
    assert!(
        msg.contains("re-bake") && msg.contains(&mine.to_string()),
        "{msg}"
    );
    // reordering is a different scene too: hits name triangles by index
    let mut swapped = tris.clone();
    swapped.swap(0, 1);
    assert_ne!(scene_hash(&swapped), mine);
    // the right scene opens
    let ok = from_bytes(
        bytes,
        &OpenOptions {
            expect_scene_hash: Some(mine),
        },
    )
    .unwrap();
    assert_eq!(ok.header.scene_hash, mine);
}

#[test]
fn a_header_hash_that_does_not_match_its_triangles_is_refused() {
    let (_, psf) = small_psf();
    let mut bad = to_bytes(&psf, &opts(Codec::None)).unwrap();
    bad[64] ^= 1;
    reseal(&mut bad);
    let err = open_mem(&bad).unwrap_err();
    assert_eq!(section_name(&err), Some("triangles"), "{err}");
}

#[test]
fn resealed_structural_damage_is_caught() {
    // Coarse enough that some tiles keep a BSP (more than 32 entries), fine enough that
    // others are flat.
    let (tris, _) = small_psf();
    let mixed = |p: &Psf| {
        let tiles = || p.subfields().iter().flat_map(|s| s.tiles.iter());
        tiles().any(|h| h.is_flat()) && tiles().any(|h| h.slabs() > 0)
    };
    let psf = (2..8)
        .map(|tiles| Psf::build(&tris, &PsfParams { level: 1, tiles }).unwrap())
        .find(|p| mixed(p))
        .expect("a grid with both kinds of tile");
    let good = to_bytes(&psf, &opts(Codec::None)).unwrap();
    let sections = open_mem(&good).unwrap().sections;
    let word = |b: &mut Vec<u8>, at: u64, v: u32| {
        b[at as usize..at as usize + 4].copy_from_slice(&v.to_le_bytes());
        reseal(b);
    };
    let find = |name: &str| sections.iter().find(|s| s.id.to_string() == name).unwrap();
    // The first non-empty section of a per-subfield kind, and its subfield.
    let first = |kind: &str| {
        let s = sections
            .iter()
            .find(|s| s.id.to_string().starts_with(kind) && s.raw_length > 0)
            .unwrap_or_else(|| panic!("no {kind} section holds anything"));
        (s.offset, format!("subfield[{}]", s.id.subfield))
    };
    // The first tile header (file offset, subfield) whose slab count passes `pick`.
    let tile = |pick: &dyn Fn(u32) -> bool| {
        let s = psf
            .subfields()
            .iter()
            .enumerate()
            .find_map(|(k, s)| {
                let i = s.tiles.iter().position(|h| pick(h.slab_count))?;
                Some((find(&format!("tiles[{k}]")).offset + 16 * i as u64, k))
            })
            .expect("a tile of that kind");
        (s.0, format!("subfield[{}]", s.1))
    };
    let (entries, entries_sub) = first("entries[");
    let (blocks, blocks_sub) = first("blocks[");
    let (bsp, bsp_sub) = tile(&|n| n > 0 && n < 1 << 31);
    let (flat, flat_sub) = tile(&|n| n & (1 << 31) != 0);
    let cases: Vec<(u64, u32, &str)> = vec![
        // header: level, tiles, triangle count
        (20, 9, "header"),
        (24, 0, "header"),
        (40, 1, "triangles"),
        // an entry naming a triangle that does not exist
        (entries, 1_000_000, &entries_sub),
        // a flat tile's block naming one (lane 0's triangle, after the depths)
        (blocks + 64, 1_000_000, &blocks_sub),
        // a tile whose slabs run past the slab starts
        (bsp + 4, 1000, &bsp_sub),
        // a flat tile whose blocks run past the blocks, or that has five of them
        (flat, 1_000_000, &flat_sub),
        (flat + 4, (1 << 31) | 5, &flat_sub),
        // a frame with a different grid: the tile section no longer fits it
        (find("frames").offset + 52, 3, "tiles[0]"),
        // a table row whose offset moves its section
        (128 + 48 * 4 + 8, 64, "entries[0]"),
    ];
    for (at, v, name) in cases {
        let mut bad = good.clone();
        word(&mut bad, at, v);
        let err = open_mem(&bad).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains(name),
            "poke {v} at {at}: {text} (wanted {name})"
        );
    }
}

// ---------------------------------------------------------------------------------------
// fuzz: seeded, bounded; the only claim is "an error or a valid tracer, never a panic"

fn mutate(rng: &mut Rng, good: &[u8]) -> Vec<u8> {
    let mut b = good.to_vec();
    match rng.below(6) {
        0 => {
            let i = rng.below(b.len());
            b[i] ^= 1 << rng.below(8);
        }
        1 => {
            for _ in 0..1 + rng.below(8) {
                let i = rng.below(b.len());
                b[i] = rng.next_u64() as u8;
            }
        }
        2 => b.truncate(rng.below(b.len())),
        3 => {
            let n = 1 + rng.below(200);
            b.extend((0..n).map(|_| rng.next_u64() as u8));
        }
        4 => {
            // a run of one value: zeros and 0xff make counts and indices extreme
            let i = rng.below(b.len());
            let n = (1 + rng.below(16)).min(b.len() - i);
            let v = [0u8, 0xff, 0x7f, 0x80][rng.below(4)];
            b[i..i + n].fill(v);
        }
        _ => {
            // an aligned little-endian word set to an interesting value
            let i = rng.below(b.len() / 4) * 4;
            let v = [0u32, 1, 2, 3, 64, 4096, u32::MAX, 0x7f80_0000, 0xffc0_0000][rng.below(9)];
            if i + 4 <= b.len() {
                b[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
    }
    b
}

/// 0: opened (and traced), 1: refused before the PSF checks, 2: refused by them.
fn try_open_and_trace(bytes: Vec<u8>, probe: &[Ray]) -> u8 {
    match from_bytes(Arc::new(bytes), &OpenOptions::default()) {
        Ok(baked) => {
            // Valid files must trace without panicking; the hits are whatever they are.
            for r in probe {
                let _ = baked.psf.intersect(r);
                let _ = baked.psf.occluded(r);
            }
            let _ = format::Inspection::of(&baked, format::ContentHash::default()).to_json();
            0
        }
        Err(e) => {
            let _ = e.to_string();
            matches!(e, FormatError::Psf(_)) as u8 + 1
        }
    }
}

#[test]
fn fuzz_mutated_files_never_panic() {
    let mut rng = Rng::new(0xf022);
    let scenes = [
        scene(1, 1 | 4),
        scene(2, 2 | 8),
        synth::box_faces(Vec3::ZERO, Vec3::ONE),
    ];
    // [unresealed, resealed] x [opened, refused early, refused by Psf::from_parts]
    let mut outcomes = [[0usize; 3]; 2];
    for (k, tris) in scenes.iter().enumerate() {
        let params = PsfParams {
            level: k as u32 % 2,
            tiles: 4 + k as u32,
        };
        let psf = Psf::build(tris, &params).unwrap();
        let probe = rays(k as u64, tris, 20);
        for codec in [Codec::None, Codec::Zstd] {
            let good = to_bytes(&psf, &opts(codec)).unwrap();
            for i in 0..700 {
                let mut bad = mutate(&mut rng, &good);
                // Raw files: half the mutations get their checksums recomputed, so they
                // reach the structural checks, Psf::from_parts and the tracer.
                let resealed = codec == Codec::None && i % 2 == 1;
                if resealed {
                    reseal(&mut bad);
                }
                let outcome = std::panic::catch_unwind(|| try_open_and_trace(bad, &probe))
                    .unwrap_or_else(|_| panic!("scene {k} {codec} mutation {i} panicked"));
                outcomes[resealed as usize][outcome as usize] += 1;
            }
        }
    }
    let total: usize = outcomes.iter().flatten().sum();
    assert_eq!(total, 4200);
    // Checksums stop nearly every plain mutation (those that open changed nothing, or
    // wrote a byte's own value).
    assert!(outcomes[0][0] < 50, "{outcomes:?}");
    // Resealed ones get through to the deeper checks and to tracing (a changed depth or
    // slab start can still be a valid file).
    assert!(outcomes[1][0] > 0 && outcomes[1][2] > 0, "{outcomes:?}");
}

// ---------------------------------------------------------------------------------------
// inspect and the atomic write

#[test]
fn inspect_describes_the_file_and_serialises_to_json() {
    let (tris, psf) = small_psf();
    let dir = TempDir::new("inspect");
    let path = dir.0.join("small.psf");
    let report = write_psf(&path, &psf, &opts(Codec::Zstd)).unwrap();
    let ins = format::inspect(&path).unwrap();
    assert_eq!(ins.header.file_length, report.file_length);
    assert_eq!(ins.header.scene_hash, scene_hash(&tris));
    assert_eq!(ins.sections.len(), 2 + 4 * psf.subfields().len());
    assert_eq!(ins.raw_bytes, report.raw_length);
    assert!(ins.stored_bytes < report.file_length);
    assert_eq!(ins.directions.len(), psf.subfields().len());
    let stats = psf.stats();
    assert_eq!(ins.occupancy.tiles, stats.tiles as u64);
    assert_eq!(ins.occupancy.empty_tiles, stats.empty_tiles as u64);
    let flat: u64 = ins.directions.iter().map(|d| d.flat_tiles).sum();
    let flat_here = psf.subfields().iter().flat_map(|s| s.tiles.iter());
    let flat_here = flat_here.filter(|h| h.is_flat()).count() as u64;
    assert_eq!((flat, ins.occupancy.flat_tiles), (flat_here, flat_here));
    assert!(flat > 0);
    let tiles: u64 = ins.directions.iter().map(|d| d.tiles).sum();
    let empty: u64 = ins.directions.iter().map(|d| d.empty_tiles).sum();
    assert_eq!(
        (tiles, empty),
        (ins.occupancy.tiles, ins.occupancy.empty_tiles)
    );
    let v: serde_json::Value = serde_json::from_str(&ins.to_json()).unwrap();
    assert_eq!(v["header"]["triangle_count"], tris.len() as u64);
    assert_eq!(v["header"]["scene_hash"], scene_hash(&tris).to_string());
    assert_eq!(v["sections"][2]["name"], "tiles[0]");
    assert_eq!(v["sections"][2]["codec"], "zstd");
    assert_eq!(
        v["header"]["table_checksum"].as_str().map(str::len),
        Some(16)
    );
    let text = ins.to_string();
    assert!(
        text.contains("entries[0]") && text.contains("occupancy"),
        "{text}"
    );
}

#[test]
fn write_replaces_atomically_and_reports_io_errors_with_the_path() {
    let (_, psf) = small_psf();
    let dir = TempDir::new("atomic");
    let path = dir.0.join("scene.psf");
    std::fs::write(&path, b"old contents").unwrap();
    write_psf(&path, &psf, &opts(Codec::None)).unwrap();
    write_psf(&path, &psf, &opts(Codec::Zstd)).unwrap();
    assert!(open_psf(&path, &OpenOptions::default()).is_ok());
    // nothing but the file is left in the folder
    let names: Vec<_> = std::fs::read_dir(&dir.0)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("scene.psf")]);
    let missing = dir.0.join("no/such/folder/scene.psf");
    match write_psf(&missing, &psf, &opts(Codec::None)) {
        Err(FormatError::Io { path, .. }) => assert!(path.starts_with(dir.0.join("no"))),
        other => panic!("{other:?}"),
    }
    match open_psf(&missing, &OpenOptions::default()) {
        Err(FormatError::Io { path, .. }) => assert_eq!(path, missing),
        other => panic!("{other:?}"),
    }
}

/// Version 3 records how the file was baked in header bytes 80..120; a version 2 file
/// (those bytes zero) still opens, as a default bake, and traces the same.
#[test]
fn a_version_2_file_opens_as_a_default_bake() {
    let (_, psf) = small_psf();
    let good = to_bytes(&psf, &opts(Codec::None)).unwrap();
    assert_eq!(u32::from_le_bytes(good[8..12].try_into().unwrap()), 3);
    let record = open_mem(&good).unwrap().header.bake;
    assert_eq!(record, format::BakeRecord::default_bake());
    // The default layout is written out: 3 entries a slab, flat up to 32.
    assert_eq!((good[80], good[81], good[82]), (0, 3, 32));
    let mut v2 = good.clone();
    v2[8..12].copy_from_slice(&2u32.to_le_bytes());
    v2[80..120].fill(0);
    reseal(&mut v2);
    let old = open_mem(&v2).unwrap();
    assert_eq!(old.header.version, 2);
    assert_eq!(old.header.bake, format::BakeRecord::default_bake());
    let new = open_mem(&good).unwrap();
    let mut rng = synth::Rng::new(4);
    for _ in 0..500 {
        let r = Ray::new(rng.in_box(Vec3::splat(-3.0), Vec3::splat(3.0)), rng.unit());
        assert_eq!(old.psf.intersect(&r), new.psf.intersect(&r));
    }
    // A version 2 file with anything in those bytes is refused.
    let mut bad = v2.clone();
    bad[90] = 1;
    reseal(&mut bad);
    let err = open_mem(&bad).unwrap_err();
    assert!(err.to_string().contains("reserved byte 90"), "{err}");
}

/// A bake record out of range is refused, naming it, whatever the checksums say.
#[test]
fn a_bad_bake_record_is_refused_by_name() {
    let (_, psf) = small_psf();
    let good = to_bytes(&psf, &opts(Codec::None)).unwrap();
    type Damage = fn(&mut Vec<u8>);
    let cases: [(&str, Damage); 7] = [
        ("quality 7", |b| b[80] = 7),
        ("entries a slab 0", |b| b[81] = 0),
        ("entries a slab 33", |b| b[81] = 33),
        ("threshold 40", |b| b[82] = 40),
        ("reserved byte 83", |b| b[83] = 1),
        ("records no tuning", |b| b[88] = 1),
        ("exceeds the default", |b| {
            b[80] = 1;
            b[84] = 2;
            b[96] = 9;
            b[104] = 8;
        }),
    ];
    for (needle, damage) in cases {
        let mut bad = good.clone();
        damage(&mut bad);
        reseal(&mut bad);
        let err = open_mem(&bad).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("header bake record") && text.contains(needle),
            "{needle}: {text}"
        );
    }
}
