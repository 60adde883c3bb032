//! The baked file (`.psf`): a static scene's parallel subfields, written once and opened
//! many times. The normative description is `formats/psf-v2.md`; this module follows it.
//!
//! * [`write_psf`] / [`to_bytes`]: one section per array (triangles, frames, and per
//!   subfield its tiles, slab starts, entries and flat tiles' blocks), each its own zstd frame compressed in
//!   parallel (single-threaded per frame, so the bytes do not depend on the thread count)
//!   or stored raw and 64-byte aligned; written atomically.
//! * [`open_psf`] / [`from_bytes`]: memory-maps the file and validates all of it once
//!   (header, table, layout, checksums, sizes implied by other checked fields), then
//!   serves raw sections in place and decompresses zstd sections in parallel straight
//!   from the mapping. [`Psf::from_parts`](crate::psf::Psf::from_parts) checks every index
//!   the traversal follows.
//! * [`inspect`]: what is inside a file, serialisable to JSON.
//! * [`ContentHash`]: the hash of a whole file's bytes, under which a bake is shipped
//!   and staged ([`crate::farm`]).
//! * [`scene_hash`]: the hash of the static input recorded in the header, so that a file
//!   baked from another scene is refused ([`FormatError::StaleScene`]).

mod content;
mod error;
mod inspect;
mod read;
mod write;

use std::fmt;

use glam::Vec3;
use serde::Serialize;
use xxhash_rust::xxh3::{xxh3_64, Xxh3};

use crate::psf::TuneRecord;

pub use content::{hash_copy, hash_file, hash_reader, BadContentHash, ContentHash, CopyError};
pub use error::FormatError;
// `Header::bake`'s types, for readers of a file's record.
pub use crate::psf::{BspParams, Quality};
pub use inspect::{
    inspect, inspect_bytes, DirectionInfo, Inspection, InspectionSummary, Occupancy, SectionInfo,
};
pub use read::{from_bytes, open_psf, read_header, BakedPsf, OpenOptions};
pub use write::{to_bytes, write_psf, WriteOptions, WriteReport};

/// The first 8 bytes of every file. After PNG: a non-ASCII first byte, and CR LF / SUB / LF
/// so that text-mode transfers that rewrite line ends are caught.
pub const MAGIC: [u8; 8] = *b"\x89PSF\r\n\x1a\n";
/// The format version this build writes. Version 3 records how the file was baked (the
/// header's bake record: quality, the BSP layout, what tuning measured); version 2
/// added flat tiles and their `blocks` section.
pub const VERSION: u32 = 3;
/// The oldest version this build reads: a version 2 file (its bake record all zero)
/// opens as a default bake; a version 1 file is refused (re-bake it: the file is a cache).
pub const MIN_VERSION: u32 = 2;
/// Sections per subfield: tiles, slab starts, entries, blocks.
pub(crate) const PER_SUBFIELD: usize = 4;
/// Written as a little-endian `u32`: a reader that sees other bytes (`0a 0b 0c 0d`) was
/// handed a byte-swapped file.
pub const ENDIAN_MARKER: u32 = 0x0A0B_0C0D;
pub const HEADER_LEN: usize = 128;
pub const TABLE_ENTRY_LEN: usize = 48;
/// Every section starts at a multiple of this (a cache line; the mapping itself is page
/// aligned, so every array is aligned for its element type).
pub const ALIGN: u64 = 64;
/// A zstd section may claim at most this many raw bytes per stored byte. It caps what a
/// reader allocates (at most `MAX_RATIO` times the file length) whatever the table says;
/// the writer stores a section raw when zstd would compress it further. The sections of
/// the benchmark room compress 1.7x to 7x (`subfield inspect`), far below the cap.
pub const MAX_RATIO: u64 = 256;

/// The xxh3-64 checksum every section, the table and the header carry (seed 0).
pub(crate) fn checksum(bytes: &[u8]) -> u64 {
    xxh3_64(bytes)
}

/// What a section holds. Each is an array of one fixed-size little-endian element type.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum SectionKind {
    /// `[[f32; 3]; 3]` per triangle, 36 bytes.
    Triangles = 1,
    /// [`GridFrame`](crate::psf::GridFrame) per subfield, 60 bytes.
    Frames = 2,
    /// [`TileHeader`](crate::psf::TileHeader) per tile of one subfield, 16 bytes.
    Tiles = 3,
    /// `u32` slab starts of one subfield.
    SlabStarts = 4,
    /// [`Entry`](crate::psf::Entry) per listed triangle of one subfield, 12 bytes.
    Entries = 5,
    /// [`Block`](crate::psf::Block) of eight entries of the flat tiles of one subfield,
    /// 96 bytes.
    Blocks = 6,
}

impl SectionKind {
    pub fn from_code(code: u16) -> Option<SectionKind> {
        Some(match code {
            1 => SectionKind::Triangles,
            2 => SectionKind::Frames,
            3 => SectionKind::Tiles,
            4 => SectionKind::SlabStarts,
            5 => SectionKind::Entries,
            6 => SectionKind::Blocks,
            _ => return None,
        })
    }

    /// Bytes per element.
    pub fn item_size(self) -> u64 {
        match self {
            SectionKind::Triangles => 36,
            SectionKind::Frames => 60,
            SectionKind::Tiles => 16,
            SectionKind::SlabStarts => 4,
            SectionKind::Entries => 12,
            SectionKind::Blocks => 96,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            SectionKind::Triangles => "triangles",
            SectionKind::Frames => "frames",
            SectionKind::Tiles => "tiles",
            SectionKind::SlabStarts => "slab_starts",
            SectionKind::Entries => "entries",
            SectionKind::Blocks => "blocks",
        }
    }

    pub(crate) fn per_subfield(self) -> bool {
        matches!(
            self,
            SectionKind::Tiles
                | SectionKind::SlabStarts
                | SectionKind::Entries
                | SectionKind::Blocks
        )
    }
}

// The arrays are stored as the in-memory `repr(C)` structs: these sizes are the spec's.
const _: () = assert!(std::mem::size_of::<[Vec3; 3]>() == 36);
const _: () = assert!(std::mem::size_of::<crate::psf::GridFrame>() == 60);
const _: () = assert!(std::mem::size_of::<crate::psf::TileHeader>() == 16);
const _: () = assert!(std::mem::size_of::<crate::psf::Entry>() == 12);
const _: () = assert!(std::mem::size_of::<crate::psf::Block>() == 96);

/// How a section's bytes are stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum Codec {
    /// The raw array, used in place from the mapping.
    None = 0,
    /// One zstd frame (RFC 8878) holding the raw array.
    #[default]
    Zstd = 1,
}

impl Codec {
    pub fn from_code(code: u8) -> Option<Codec> {
        match code {
            0 => Some(Codec::None),
            1 => Some(Codec::Zstd),
            _ => None,
        }
    }
}

impl std::str::FromStr for Codec {
    type Err = String;

    fn from_str(s: &str) -> Result<Codec, String> {
        match s {
            "none" => Ok(Codec::None),
            "zstd" => Ok(Codec::Zstd),
            _ => Err(format!("unknown codec {s:?} (expected zstd or none)")),
        }
    }
}

impl fmt::Display for Codec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Codec::None => "none",
            Codec::Zstd => "zstd",
        })
    }
}

/// The hash of a static scene's triangles (xxh3-128; see [`scene_hash`]). Shown as 32
/// hex digits.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct SceneHash(pub [u8; 16]);

impl fmt::Display for SceneHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for b in self.0 {
            write!(f, "{b:02x}")?;
        }
        Ok(())
    }
}

impl fmt::Debug for SceneHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SceneHash({self})")
    }
}

impl Serialize for SceneHash {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// The hash of the static input a PSF is baked from: xxh3-128 (seed 0) over the ASCII
/// tag `subfield-scene-v1`, the triangle count as a little-endian `u64`, then every
/// vertex coordinate as a little-endian `f32`, in triangle order. The order counts: hits
/// name triangles by index. It detects a changed scene, it is not a defence against a
/// forger (not cryptographic).
pub fn scene_hash(tris: &[[Vec3; 3]]) -> SceneHash {
    let mut h = Xxh3::new();
    h.update(b"subfield-scene-v1");
    h.update(&(tris.len() as u64).to_le_bytes());
    #[cfg(target_endian = "little")]
    h.update(bytemuck::cast_slice(tris));
    #[cfg(not(target_endian = "little"))]
    for t in tris {
        for v in t {
            for c in v.to_array() {
                h.update(&c.to_le_bytes());
            }
        }
    }
    SceneHash(h.digest128().to_le_bytes())
}

/// Which section: its kind, and for per-subfield kinds the subfield index. Shown as the
/// errors and `inspect` name it: `triangles`, `frames`, `tiles[3]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SectionId {
    pub kind: SectionKind,
    pub subfield: u32,
}

impl fmt::Display for SectionId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.kind.per_subfield() {
            write!(f, "{}[{}]", self.kind.name(), self.subfield)
        } else {
            f.write_str(self.kind.name())
        }
    }
}

/// The sections of a file with `subfields` subfields, in the order the spec fixes:
/// triangles, frames, then per subfield its tiles, slab starts, entries and blocks.
pub(crate) fn section_ids(subfields: u32) -> impl Iterator<Item = SectionId> {
    let head = [SectionKind::Triangles, SectionKind::Frames]
        .into_iter()
        .map(|kind| SectionId { kind, subfield: 0 });
    let per = (0..subfields).flat_map(|k| {
        [
            SectionKind::Tiles,
            SectionKind::SlabStarts,
            SectionKind::Entries,
            SectionKind::Blocks,
        ]
        .into_iter()
        .map(move |kind| SectionId { kind, subfield: k })
    });
    head.chain(per)
}

/// Checksums as 16 hex digits in JSON (a `u64` does not survive a JSON number).
fn hex_u64<S: serde::Serializer>(x: &u64, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(&format_args!("{x:016x}"))
}

/// How a file was baked: header bytes 80..120 of version 3 (all zero in version 2,
/// which reads as a default bake with the default layout). Tracing does not depend on
/// it; `inspect` shows it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct BakeRecord {
    /// `default`: parameters from the triangle count (or given); `high`: chosen by
    /// [`tune`](crate::psf::tune) on the scene's sample rays.
    #[serde(serialize_with = "display")]
    pub quality: Quality,
    /// The BSP layout the tiles were built with ([`BspParams`]).
    pub leaf: u32,
    pub flat_max: u32,
    /// Parameter sets measured, sample rays, the chosen set's cost and the default's
    /// (all zero for a default bake).
    pub trials: u32,
    pub sample_rays: u64,
    pub cost: u64,
    pub default_cost: u64,
}

fn display<T: fmt::Display, S: serde::Serializer>(x: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(x)
}

impl BakeRecord {
    /// The record of a default bake with the default layout (what a version 2 file means).
    pub fn default_bake() -> BakeRecord {
        BakeRecord::of(&BspParams::default(), None)
    }

    /// The record of a bake laid out by `bsp`, tuned as `tuned` says when it was.
    pub fn of(bsp: &BspParams, tuned: Option<&TuneRecord>) -> BakeRecord {
        let t = tuned.copied().unwrap_or_default();
        BakeRecord {
            quality: if tuned.is_some() {
                Quality::High
            } else {
                Quality::Default
            },
            leaf: bsp.leaf,
            flat_max: bsp.flat_max,
            trials: t.trials,
            sample_rays: t.sample_rays,
            cost: t.cost,
            default_cost: t.default_cost,
        }
    }

    pub fn bsp(&self) -> BspParams {
        BspParams {
            leaf: self.leaf,
            flat_max: self.flat_max,
        }
    }

    /// What tuning measured (`None` for a default bake).
    pub fn tuning(&self) -> Option<TuneRecord> {
        (self.quality == Quality::High).then_some(TuneRecord {
            trials: self.trials,
            sample_rays: self.sample_rays,
            cost: self.cost,
            default_cost: self.default_cost,
        })
    }

    fn encode(&self, b: &mut [u8]) {
        b[80] = self.quality as u8;
        // Checked in range (`BspParams::validate`: at most 32) before a bake.
        b[81] = self.leaf.min(255) as u8;
        b[82] = self.flat_max.min(255) as u8;
        // 83 reserved, zero
        b[84..88].copy_from_slice(&self.trials.to_le_bytes());
        b[88..96].copy_from_slice(&self.sample_rays.to_le_bytes());
        b[96..104].copy_from_slice(&self.cost.to_le_bytes());
        b[104..112].copy_from_slice(&self.default_cost.to_le_bytes());
        // 112..120 reserved, zero
    }

    /// Parses and checks a version 3 record (header bytes 80..120).
    fn decode(b: &[u8]) -> Result<BakeRecord, FormatError> {
        let bad = |d: String| FormatError::invalid("header bake record", d);
        let quality = match b[80] {
            0 => Quality::Default,
            1 => Quality::High,
            q => {
                return Err(bad(format!(
                    "quality {q} is neither 0 (default) nor 1 (high)"
                )))
            }
        };
        if let Some(i) = [83usize].into_iter().chain(112..120).find(|&i| b[i] != 0) {
            return Err(bad(format!("reserved byte {i} is not zero")));
        }
        let r = BakeRecord {
            quality,
            leaf: b[81] as u32,
            flat_max: b[82] as u32,
            trials: le_u32(b, 84),
            sample_rays: le_u64(b, 88),
            cost: le_u64(b, 96),
            default_cost: le_u64(b, 104),
        };
        r.bsp().validate().map_err(bad)?;
        match quality {
            Quality::Default
                if (r.trials, r.sample_rays, r.cost, r.default_cost) != (0, 0, 0, 0) =>
            {
                Err(bad(
                    "a default bake records no tuning, but its trials, rays or costs are not zero"
                        .into(),
                ))
            }
            Quality::High if r.trials == 0 => Err(bad("a tuned bake records no trial".into())),
            Quality::High if r.cost > r.default_cost => Err(bad(format!(
                "the chosen cost {} exceeds the default's {}",
                r.cost, r.default_cost
            ))),
            _ => Ok(r),
        }
    }
}

/// The file header: the first [`HEADER_LEN`] bytes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Header {
    pub version: u32,
    /// [`PsfParams`](crate::psf::PsfParams): subdivision level and tiles per side.
    pub level: u32,
    pub tiles: u32,
    /// The PSF's rounding allowance (see [`margin_for`](crate::psf::margin_for)).
    pub margin: f32,
    pub file_length: u64,
    pub triangle_count: u64,
    pub subfield_count: u32,
    pub section_count: u32,
    #[serde(serialize_with = "hex_u64")]
    pub table_checksum: u64,
    pub scene_hash: SceneHash,
    /// How it was baked (version 3; a version 2 file reads as a default bake).
    pub bake: BakeRecord,
}

fn le_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

impl Header {
    pub(crate) fn encode(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[0..8].copy_from_slice(&MAGIC);
        b[8..12].copy_from_slice(&self.version.to_le_bytes());
        b[12..16].copy_from_slice(&ENDIAN_MARKER.to_le_bytes());
        // 16..20 flags: none defined, zero
        b[20..24].copy_from_slice(&self.level.to_le_bytes());
        b[24..28].copy_from_slice(&self.tiles.to_le_bytes());
        b[28..32].copy_from_slice(&self.margin.to_bits().to_le_bytes());
        b[32..40].copy_from_slice(&self.file_length.to_le_bytes());
        b[40..48].copy_from_slice(&self.triangle_count.to_le_bytes());
        b[48..52].copy_from_slice(&self.subfield_count.to_le_bytes());
        b[52..56].copy_from_slice(&self.section_count.to_le_bytes());
        b[56..64].copy_from_slice(&self.table_checksum.to_le_bytes());
        b[64..80].copy_from_slice(&self.scene_hash.0);
        // 80..120: the bake record (version 3; zero in version 2)
        if self.version >= 3 {
            self.bake.encode(&mut b);
        }
        let sum = checksum(&b[..120]);
        b[120..128].copy_from_slice(&sum.to_le_bytes());
        b
    }

    /// Parses and checks the header's own bytes: magic, version, byte order, checksum,
    /// reserved fields. Relations to the rest of the file are the reader's to check.
    pub(crate) fn decode(all: &[u8]) -> Result<Header, FormatError> {
        let have = all.len() as u64;
        // Magic first, so a file that is not ours says so whatever its length.
        let mut magic = [0u8; 8];
        let n = all.len().min(8);
        magic[..n].copy_from_slice(&all[..n]);
        if magic[..n] != MAGIC[..n] {
            // A scene given for its bake is the likely mistake: say so.
            if all.starts_with(b"glTF") {
                return Err(FormatError::GltfScene { kind: "GLB" });
            }
            let json = all.iter().find(|c| !c.is_ascii_whitespace()) == Some(&b'{');
            if json {
                return Err(FormatError::GltfScene { kind: "JSON" });
            }
            return Err(FormatError::Magic(magic));
        }
        let Some(b) = all.get(..HEADER_LEN) else {
            return Err(FormatError::Truncated {
                section: "header".into(),
                needed: HEADER_LEN as u64,
                have,
            });
        };
        let version = le_u32(b, 8);
        if !(MIN_VERSION..=VERSION).contains(&version) {
            return Err(FormatError::Version {
                found: version,
                supported: VERSION,
            });
        }
        let marker = le_u32(b, 12);
        if marker != ENDIAN_MARKER {
            return Err(FormatError::NotSupported {
                what: format!(
                    "byte-order marker {:02x?} (expected {:02x?}, little-endian)",
                    &b[12..16],
                    ENDIAN_MARKER.to_le_bytes()
                ),
            });
        }
        let stored = le_u64(b, 120);
        let found = checksum(&b[..120]);
        if stored != found {
            return Err(FormatError::Checksum {
                section: "header".into(),
                expected: stored,
                found,
            });
        }
        let flags = le_u32(b, 16);
        if flags != 0 {
            return Err(FormatError::invalid(
                "header",
                format!("reserved flags {flags:#x} are not zero"),
            ));
        }
        let bake = if version >= 3 {
            BakeRecord::decode(b)?
        } else {
            if let Some(i) = b[80..120].iter().position(|&x| x != 0) {
                return Err(FormatError::invalid(
                    "header",
                    format!("reserved byte {} is not zero", 80 + i),
                ));
            }
            BakeRecord::default_bake()
        };
        let mut hash = [0u8; 16];
        hash.copy_from_slice(&b[64..80]);
        Ok(Header {
            version,
            level: le_u32(b, 20),
            tiles: le_u32(b, 24),
            margin: f32::from_bits(le_u32(b, 28)),
            file_length: le_u64(b, 32),
            triangle_count: le_u64(b, 40),
            subfield_count: le_u32(b, 48),
            section_count: le_u32(b, 52),
            table_checksum: le_u64(b, 56),
            scene_hash: SceneHash(hash),
            bake,
        })
    }
}

/// One row of the section table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SectionEntry {
    pub id: SectionId,
    pub codec: Codec,
    /// From the start of the file; a multiple of [`ALIGN`].
    pub offset: u64,
    pub stored_length: u64,
    pub raw_length: u64,
    /// xxh3-64 of the stored bytes, and of the raw (decompressed) bytes.
    pub stored_checksum: u64,
    pub raw_checksum: u64,
}

impl SectionEntry {
    pub(crate) fn encode(&self) -> [u8; TABLE_ENTRY_LEN] {
        let mut b = [0u8; TABLE_ENTRY_LEN];
        b[0..2].copy_from_slice(&(self.id.kind as u16).to_le_bytes());
        b[2] = self.codec as u8;
        // 3: reserved, zero
        b[4..8].copy_from_slice(&self.id.subfield.to_le_bytes());
        b[8..16].copy_from_slice(&self.offset.to_le_bytes());
        b[16..24].copy_from_slice(&self.stored_length.to_le_bytes());
        b[24..32].copy_from_slice(&self.raw_length.to_le_bytes());
        b[32..40].copy_from_slice(&self.stored_checksum.to_le_bytes());
        b[40..48].copy_from_slice(&self.raw_checksum.to_le_bytes());
        b
    }

    /// Parses table row `i`, which must describe section `expected`.
    pub(crate) fn decode(
        b: &[u8],
        i: usize,
        expected: SectionId,
    ) -> Result<SectionEntry, FormatError> {
        let row = || format!("section table row {i} ({expected})");
        let code = le_u16(b, 0);
        let kind = SectionKind::from_code(code)
            .ok_or_else(|| FormatError::invalid(row(), format!("unknown section kind {code}")))?;
        let codec = Codec::from_code(b[2]).ok_or_else(|| FormatError::NotSupported {
            what: format!("codec {} in {}", b[2], row()),
        })?;
        if b[3] != 0 {
            return Err(FormatError::invalid(
                row(),
                format!("reserved byte is {:#x}, not zero", b[3]),
            ));
        }
        let id = SectionId {
            kind,
            subfield: le_u32(b, 4),
        };
        if id != expected {
            return Err(FormatError::invalid(
                row(),
                format!("holds {id}, the layout puts {expected} there"),
            ));
        }
        Ok(SectionEntry {
            id,
            codec,
            offset: le_u64(b, 8),
            stored_length: le_u64(b, 16),
            raw_length: le_u64(b, 24),
            stored_checksum: le_u64(b, 32),
            raw_checksum: le_u64(b, 40),
        })
    }

    pub fn end(&self) -> u64 {
        self.offset.saturating_add(self.stored_length)
    }
}

pub(crate) fn align_up(x: u64) -> u64 {
    x.div_ceil(ALIGN).saturating_mul(ALIGN)
}
