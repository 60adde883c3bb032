//! The baked file pays for itself: bake time, file size per triangle, and open time for
//! both codecs, against baking again, on the room scene of 10k and 100k triangles
//! (and 1M with `1m`). Plain timing, prints a table.
//!
//!     cargo bench --bench psf_file              # 10k, 100k
//!     cargo bench --bench psf_file -- 1m        # and 1M (a few GiB of memory, minutes)
//!     cargo bench --bench psf_file -- levels    # zstd level 1 / 3 / 9 / 19 on 100k
//!
//! Open times are with the file in the page cache (it was just written): the cost of
//! validation, checksums, decompression and `Psf::from_parts`, not of the disk.
//!
//! Figures (2 shared cores, level 1 / 128 tiles; bake times vary 2x with the load):
//!
//!     triangles  bake s  codec  file MiB  B/tri  open ms  bake/open
//!       1000000   0.98   none     219.9   230.6    23.5      42x
//!       1000000   0.98   zstd     107.0   112.2   169.4       6x
//!       (another run: bake 1.86 s, none 30.5 ms = 61x, zstd 345 ms = 5x)
//!
//! The raw open reads every byte twice, both passes bound by memory bandwidth: the
//! checksums (8 ms at 1M) and `Psf::from_parts` (18 ms; running its per-subfield checks
//! in parallel was tried and gained nothing). zstd opens are bound by decompression,
//! about 1 GB/s of raw output on two cores.

#[path = "common.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;

use subfield::format::{self, Codec, OpenOptions, WriteOptions};
use subfield::{Intersector, Psf, PsfParams};

/// Best of `runs` timings, in seconds, and the last result.
fn best<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(r);
    }
    (best, out.expect("at least one run"))
}

struct Dir(PathBuf);

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn file_len(p: &Path) -> u64 {
    std::fs::metadata(p).map(|m| m.len()).unwrap_or(0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let has = |a: &str| args.iter().any(|x| x == a);
    let dir = Dir(std::env::temp_dir().join(format!("subfield-psf-bench-{}", std::process::id())));
    std::fs::create_dir_all(&dir.0).expect("temp dir");
    let params = PsfParams::default();
    println!(
        "room scene, level {} / {} tiles, {} threads; open = warm page cache, best of runs",
        params.level,
        params.tiles,
        rayon::current_num_threads()
    );
    if has("levels") {
        levels(&dir.0, &params);
        return;
    }
    let mut sizes = vec![10_000, 100_000];
    if has("1m") {
        sizes.push(1_000_000);
    }
    println!(
        "{:>9} {:>9} {:>6} {:>9} {:>10} {:>8} {:>9} {:>11}",
        "triangles", "bake s", "codec", "write s", "file MiB", "B/tri", "open ms", "bake/open"
    );
    for n in sizes {
        let tris = common::room(n);
        let runs = if n >= 1_000_000 { 1 } else { 3 };
        let (bake, psf) = best(runs, || Psf::build(&tris, &params).expect("bake"));
        let rays = common::random_rays(2000);
        for codec in [Codec::None, Codec::Zstd] {
            let path = dir.0.join(format!("room-{n}-{codec}.psf"));
            let opts = WriteOptions {
                codec,
                ..Default::default()
            };
            let (write, _) = best(1, || format::write_psf(&path, &psf, &opts).expect("write"));
            let want = OpenOptions {
                expect_scene_hash: Some(format::scene_hash(&tris)),
            };
            let (open, baked) = best(if n >= 1_000_000 { 3 } else { 7 }, || {
                format::open_psf(&path, &want).expect("open")
            });
            // The file must serve the same hits, or the timing means nothing.
            for r in &rays {
                assert_eq!(psf.intersect(r), baked.psf.intersect(r));
            }
            let len = file_len(&path);
            println!(
                "{:>9} {:>9.3} {:>6} {:>9.3} {:>10.1} {:>8.1} {:>9.2} {:>10.0}x",
                n,
                bake,
                codec.to_string(),
                write,
                len as f64 / (1024.0 * 1024.0),
                len as f64 / n as f64,
                open * 1e3,
                bake / open
            );
            drop(baked);
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// zstd level: file size, write time and open time on the 100k room.
fn levels(dir: &Path, params: &PsfParams) {
    let n = 100_000;
    let tris = common::room(n);
    let psf = Psf::build(&tris, params).expect("bake");
    let raw = format::to_bytes(
        &psf,
        &WriteOptions {
            codec: Codec::None,
            ..Default::default()
        },
    )
    .expect("encode")
    .len();
    println!("{n} triangles, raw file {raw} bytes");
    println!(
        "{:>5} {:>10} {:>7} {:>9} {:>9}",
        "level", "file", "ratio", "write s", "open ms"
    );
    for level in [1, 3, 9, 19] {
        let path = dir.join(format!("levels-{level}.psf"));
        let opts = WriteOptions {
            codec: Codec::Zstd,
            zstd_level: level,
        };
        let (write, _) = best(1, || format::write_psf(&path, &psf, &opts).expect("write"));
        let (open, _) = best(5, || {
            format::open_psf(&path, &OpenOptions::default()).expect("open")
        });
        let len = file_len(&path);
        println!(
            "{:>5} {:>10} {:>7.2} {:>9.3} {:>9.2}",
            level,
            len,
            raw as f64 / len as f64,
            write,
            open * 1e3
        );
        let _ = std::fs::remove_file(&path);
    }
}
