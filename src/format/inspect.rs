//! What is inside a baked file: header, sections (stored and raw sizes), directions and
//! tile occupancy. Serialisable to JSON (`subfield inspect --json`); `Display` gives the
//! text form.

use std::fmt;
use std::path::Path;

use serde::Serialize;

use super::{
    open_psf, BakedPsf, Codec, ContentHash, FormatError, Header, OpenOptions, SectionKind,
    PER_SUBFIELD,
};
use crate::psf::SharedBytes;

/// Everything `subfield inspect` shows. Opening validates the whole file, so an
/// inspection is only made of a valid one.
#[derive(Clone, Debug, Serialize)]
pub struct Inspection {
    /// The hash of the file's bytes (see [`ContentHash`]): what `subfield bake` prints
    /// and a farm job stages the file under.
    pub content_hash: ContentHash,
    pub header: Header,
    pub sections: Vec<SectionInfo>,
    /// Sums over the sections.
    pub stored_bytes: u64,
    pub raw_bytes: u64,
    /// `raw_bytes / stored_bytes`.
    pub ratio: f64,
    pub directions: Vec<DirectionInfo>,
    pub occupancy: Occupancy,
}

#[derive(Clone, Debug, Serialize)]
pub struct SectionInfo {
    /// As errors name it: `triangles`, `frames`, `tiles[3]`, `slab_starts[3]`, `entries[3]`.
    pub name: String,
    pub kind: SectionKind,
    pub subfield: Option<u32>,
    pub codec: Codec,
    pub offset: u64,
    pub stored_length: u64,
    pub raw_length: u64,
    pub items: u64,
    /// `raw_length / stored_length` (1 for raw sections; 0 for empty ones).
    pub ratio: f64,
    /// xxh3-64, 16 hex digits.
    pub stored_checksum: String,
    pub raw_checksum: String,
}

/// One subfield: its direction, grid, and how full its tiles are.
#[derive(Clone, Debug, Serialize)]
pub struct DirectionInfo {
    pub subfield: u32,
    pub direction: [f32; 3],
    pub nu: u32,
    pub nv: u32,
    pub tiles: u64,
    pub empty_tiles: u64,
    /// Tiles of at most 32 triangles, stored as blocks of eight instead of a BSP.
    pub flat_tiles: u64,
    /// Entries over all BSP slabs (a triangle is listed once per slab it overlaps).
    pub slab_entries: u64,
    /// Distinct triangles per tile.
    pub triangles_per_tile_mean: f64,
    pub triangles_per_tile_max: u64,
    /// Its four sections together.
    pub stored_bytes: u64,
    pub raw_bytes: u64,
}

/// Tile occupancy over all subfields: distinct triangles per tile.
#[derive(Clone, Debug, Serialize)]
pub struct Occupancy {
    pub tiles: u64,
    pub empty_tiles: u64,
    pub flat_tiles: u64,
    pub slab_entries: u64,
    pub triangles_per_tile_mean: f64,
    pub triangles_per_tile_max: u64,
    /// `(low, high_exclusive, tiles)`: power-of-two buckets.
    pub histogram: Vec<(u64, u64, u64)>,
}

/// Opens, validates and describes a baked file.
pub fn inspect(path: impl AsRef<Path>) -> Result<Inspection, FormatError> {
    let path = path.as_ref();
    let baked = open_psf(path, &OpenOptions::default())?;
    // Validation read every byte already; the hash reads them once more.
    let hash = super::hash_file(path).map_err(|e| FormatError::io(path, e))?;
    Ok(Inspection::of(&baked, hash))
}

/// As [`inspect`], for a file held in memory.
pub fn inspect_bytes(bytes: SharedBytes) -> Result<Inspection, FormatError> {
    let hash = ContentHash::of((*bytes).as_ref());
    Ok(Inspection::of(
        &super::from_bytes(bytes, &OpenOptions::default())?,
        hash,
    ))
}

fn ratio(raw: u64, stored: u64) -> f64 {
    if stored == 0 {
        0.0
    } else {
        raw as f64 / stored as f64
    }
}

impl Inspection {
    /// Describes an opened file whose bytes hash to `content_hash`.
    pub fn of(baked: &BakedPsf, content_hash: ContentHash) -> Inspection {
        let sections: Vec<SectionInfo> = baked
            .sections
            .iter()
            .map(|e| SectionInfo {
                name: e.id.to_string(),
                kind: e.id.kind,
                subfield: e.id.kind.per_subfield().then_some(e.id.subfield),
                codec: e.codec,
                offset: e.offset,
                stored_length: e.stored_length,
                raw_length: e.raw_length,
                items: e.raw_length / e.id.kind.item_size(),
                ratio: ratio(e.raw_length, e.stored_length),
                stored_checksum: format!("{:016x}", e.stored_checksum),
                raw_checksum: format!("{:016x}", e.raw_checksum),
            })
            .collect();
        let stored_bytes = sections.iter().map(|s| s.stored_length).sum();
        let raw_bytes = sections.iter().map(|s| s.raw_length).sum();
        let psf = &baked.psf;
        let mut tris = Vec::new();
        let directions = psf
            .subfields()
            .iter()
            .enumerate()
            .map(|(k, s)| {
                let (mut empty, mut total, mut max) = (0u64, 0u64, 0u64);
                let flat = s.tiles.iter().filter(|h| h.is_flat()).count() as u64;
                for h in s.tiles.iter() {
                    let n = if h.is_flat() {
                        // In range: Psf::from_parts checked every flat tile's blocks.
                        s.blocks[h.blocks()].iter().flat_map(|b| b.used()).count() as u64
                    } else if h.slab_count == 0 {
                        0
                    } else {
                        // In range: Psf::from_parts checked every tile's slabs.
                        let first = h.first_slab as usize;
                        let (a, b) = (
                            s.slab_starts[first] as usize,
                            s.slab_starts[first + h.slab_count as usize] as usize,
                        );
                        tris.clear();
                        tris.extend(s.entries[a..b].iter().map(|e| e.tri));
                        tris.sort_unstable();
                        tris.dedup();
                        tris.len() as u64
                    };
                    empty += (n == 0) as u64;
                    total += n;
                    max = max.max(n);
                }
                let own = &sections[2 + PER_SUBFIELD * k..2 + PER_SUBFIELD * (k + 1)];
                DirectionInfo {
                    subfield: k as u32,
                    direction: s.frame.d.to_array(),
                    nu: s.frame.nu,
                    nv: s.frame.nv,
                    tiles: s.tiles.len() as u64,
                    empty_tiles: empty,
                    flat_tiles: flat,
                    slab_entries: s.entries.len() as u64,
                    triangles_per_tile_mean: total as f64 / s.tiles.len().max(1) as f64,
                    triangles_per_tile_max: max,
                    stored_bytes: own.iter().map(|x| x.stored_length).sum(),
                    raw_bytes: own.iter().map(|x| x.raw_length).sum(),
                }
            })
            .collect();
        let st = psf.stats();
        Inspection {
            content_hash,
            header: baked.header.clone(),
            sections,
            stored_bytes,
            raw_bytes,
            ratio: ratio(raw_bytes, stored_bytes),
            directions,
            occupancy: Occupancy {
                tiles: st.tiles as u64,
                empty_tiles: st.empty_tiles as u64,
                flat_tiles: st.flat_tiles as u64,
                slab_entries: st.slab_entries as u64,
                triangles_per_tile_mean: st.entries_per_tile_mean,
                triangles_per_tile_max: st.entries_per_tile_max,
                histogram: st.entries_per_tile.rows().collect(),
            },
        }
    }

    /// The inspection as pretty-printed JSON.
    pub fn to_json(&self) -> String {
        // Plain structs with string keys and numbers: serde_json cannot fail on them.
        serde_json::to_string_pretty(self)
            .unwrap_or_else(|e| serde_json::json!({ "error": e.to_string() }).to_string())
    }
}

fn mib(b: u64) -> f64 {
    b as f64 / (1024.0 * 1024.0)
}

impl super::BakeRecord {
    /// One line: the quality, the layout, and for a tuned bake what it measured.
    pub fn line(&self) -> String {
        let mut s = format!(
            "bake: quality {}, {} entries a slab, flat tiles up to {}",
            self.quality, self.leaf, self.flat_max
        );
        if self.tuning().is_some() {
            s.push_str(&format!(
                "; tuned over {} trials on {} sample rays: cost {} against the default's {} ({:.3}x)",
                self.trials,
                self.sample_rays,
                self.cost,
                self.default_cost,
                self.cost as f64 / self.default_cost.max(1) as f64
            ));
        }
        s
    }
}

impl Inspection {
    /// The one-screen form (`subfield inspect` without `--verbose`): header, hashes,
    /// sizes by section kind, the directions' grids and the occupancy in a few lines.
    /// `Display` is the full form with one row per section and per direction.
    pub fn summary(&self) -> InspectionSummary<'_> {
        InspectionSummary(self)
    }
}

/// See [`Inspection::summary`].
pub struct InspectionSummary<'a>(&'a Inspection);

impl Occupancy {
    /// The one line both the summary and the full tables open their occupancy with.
    fn headline(&self) -> String {
        format!(
            "occupancy: {} tiles, {} empty, {} flat, {:.2} triangles per tile (max {}), {} slab entries",
            self.tiles,
            self.empty_tiles,
            self.flat_tiles,
            self.triangles_per_tile_mean,
            self.triangles_per_tile_max,
            self.slab_entries
        )
    }
}

impl fmt::Display for InspectionSummary<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ins = self.0;
        let h = &ins.header;
        writeln!(
            f,
            "format version {}, {} bytes ({:.2} MiB stored, {:.2} MiB raw, ratio {:.2})",
            h.version,
            h.file_length,
            mib(ins.stored_bytes),
            mib(ins.raw_bytes),
            ins.ratio
        )?;
        writeln!(
            f,
            "{} triangles; level {}: {} subfields, {} tiles per side, margin {:e}",
            h.triangle_count, h.level, h.subfield_count, h.tiles, h.margin
        )?;
        writeln!(f, "{}", h.bake.line())?;
        writeln!(f, "content hash {}", ins.content_hash)?;
        writeln!(f, "scene hash {}", h.scene_hash)?;
        // Sections by kind (their names without the subfield index), in file order.
        let mut kinds: Vec<(&str, usize, u64, u64)> = Vec::new();
        for sec in &ins.sections {
            let kind = sec.name.split('[').next().unwrap_or(&sec.name);
            match kinds.iter_mut().find(|k| k.0 == kind) {
                Some(k) => {
                    k.1 += 1;
                    k.2 += sec.stored_length;
                    k.3 += sec.raw_length;
                }
                None => kinds.push((kind, 1, sec.stored_length, sec.raw_length)),
            }
        }
        let kinds: Vec<String> = kinds
            .iter()
            .map(|(k, n, st, raw)| {
                let count = if *n == 1 {
                    String::new()
                } else {
                    format!(" ×{n}")
                };
                format!("{k}{count} {:.2}/{:.2}", mib(*st), mib(*raw))
            })
            .collect();
        writeln!(
            f,
            "sections: {} (MiB stored/raw) {}",
            ins.sections.len(),
            kinds.join(", ")
        )?;
        let d = &ins.directions;
        if !d.is_empty() {
            let grids = |g: fn(&DirectionInfo) -> u64| {
                (
                    d.iter().map(g).min().unwrap_or(0),
                    d.iter().map(g).max().unwrap_or(0),
                )
            };
            let (tiles_lo, tiles_hi) = grids(|x| x.tiles);
            let (nu_lo, nu_hi) = grids(|x| x.nu as u64);
            let (nv_lo, nv_hi) = grids(|x| x.nv as u64);
            let busiest = d
                .iter()
                .max_by(|a, b| {
                    a.triangles_per_tile_mean
                        .total_cmp(&b.triangles_per_tile_mean)
                })
                .map(|x| x.subfield)
                .unwrap_or(0);
            let span = |lo: u64, hi: u64| {
                if lo == hi {
                    lo.to_string()
                } else {
                    format!("{lo}-{hi}")
                }
            };
            writeln!(
                f,
                "directions: {} subfields, grids of {} by {} tiles ({} each); the densest is #{busiest}",
                d.len(),
                span(nu_lo, nu_hi),
                span(nv_lo, nv_hi),
                span(tiles_lo, tiles_hi),
            )?;
        }
        let o = &ins.occupancy;
        writeln!(f, "{}", o.headline())?;
        let hist: Vec<String> = o
            .histogram
            .iter()
            .map(|(lo, hi, n)| format!("[{lo},{hi}) {n}"))
            .collect();
        if !hist.is_empty() {
            writeln!(f, "  triangles per tile: {}", hist.join(", "))?;
        }
        writeln!(f, "(--verbose: every section and direction)")
    }
}

impl fmt::Display for Inspection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let h = &self.header;
        writeln!(f, "format version {}, {} bytes", h.version, h.file_length)?;
        writeln!(
            f,
            "level {} ({} subfields), {} tiles per side, {} triangles, margin {:e}",
            h.level, h.subfield_count, h.tiles, h.triangle_count, h.margin
        )?;
        writeln!(f, "{}", h.bake.line())?;
        writeln!(f, "content hash {}", self.content_hash)?;
        writeln!(f, "scene hash {}", h.scene_hash)?;
        writeln!(
            f,
            "sections: {} ({:.2} MiB stored, {:.2} MiB raw, ratio {:.2})",
            self.sections.len(),
            mib(self.stored_bytes),
            mib(self.raw_bytes),
            self.ratio
        )?;
        writeln!(
            f,
            "  {:<18} {:<5} {:>12} {:>12} {:>12} {:>6}",
            "section", "codec", "offset", "stored", "raw", "ratio"
        )?;
        for s in &self.sections {
            writeln!(
                f,
                "  {:<18} {:<5} {:>12} {:>12} {:>12} {:>6.2}",
                s.name,
                s.codec.to_string(),
                s.offset,
                s.stored_length,
                s.raw_length,
                s.ratio
            )?;
        }
        writeln!(f, "directions:")?;
        writeln!(
            f,
            "  {:>3} {:>26} {:>9} {:>7} {:>7} {:>7} {:>10} {:>9} {:>6}",
            "#", "direction", "grid", "tiles", "empty", "flat", "entries", "tri/tile", "max"
        )?;
        for d in &self.directions {
            writeln!(
                f,
                "  {:>3} {:>8.5},{:>8.5},{:>8.5} {:>4}x{:<4} {:>7} {:>7} {:>7} {:>10} {:>9.2} {:>6}",
                d.subfield,
                d.direction[0],
                d.direction[1],
                d.direction[2],
                d.nu,
                d.nv,
                d.tiles,
                d.empty_tiles,
                d.flat_tiles,
                d.slab_entries,
                d.triangles_per_tile_mean,
                d.triangles_per_tile_max
            )?;
        }
        let o = &self.occupancy;
        writeln!(f, "{}", o.headline())?;
        for (lo, hi, n) in &o.histogram {
            writeln!(f, "  [{lo}, {hi}) {n}")?;
        }
        Ok(())
    }
}
