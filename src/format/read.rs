//! The reader: maps the file, validates all of it once, then hands the tracer its
//! arrays: raw sections in place from the mapping, zstd sections decompressed in
//! parallel straight from it.
//!
//! Order of the checks (the first failure is reported): magic, header length, version,
//! byte order, header checksum, reserved header fields; the expected scene hash; the
//! header's counts against its parameters; the table's length and checksum; every row
//! (kind, codec, offset, lengths, the sizes implied by the header); the file length and
//! the zero padding; then, per section and before its bytes are used, its stored
//! checksum, its decompressed length and its raw checksum; the triangles against the
//! scene hash; finally [`Psf::from_parts`] checks every index the traversal follows.
//! Nothing is allocated from a length before that length is checked against the file.

use std::fs::File;
use std::io::Read;
use std::path::Path;
use std::sync::Arc;

use bytemuck::Pod;
use glam::Vec3;
use rayon::prelude::*;

use super::{
    align_up, checksum, scene_hash, section_ids, Codec, FormatError, Header, SceneHash,
    SectionEntry, SectionKind, HEADER_LEN, MAX_RATIO, PER_SUBFIELD, TABLE_ENTRY_LEN,
};
use crate::psf::{subfield_directions, Buf, GridFrame, Psf, PsfParams, SharedBytes, Subfield};

/// How to open a baked file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OpenOptions {
    /// Refuse the file with [`FormatError::StaleScene`] unless it was baked from the
    /// static scene with this hash (see [`scene_hash`](super::scene_hash)). Checked
    /// right after the header, before any section is read.
    pub expect_scene_hash: Option<SceneHash>,
}

/// An opened baked file: the tracer, and what the file said about itself.
#[derive(Debug)]
pub struct BakedPsf {
    pub psf: Psf,
    pub header: Header,
    /// The section table, in file order.
    pub sections: Vec<SectionEntry>,
}

/// Opens and validates a baked file. Raw sections stay in the memory map (zero copy);
/// zstd sections are decompressed in parallel.
///
/// The mapping is read-only and this process never writes the file; if another process
/// truncates it while it is mapped, touching the lost pages raises SIGBUS (the usual
/// memory-map caveat). Replace baked files by renaming over them, as [`write_psf`]
/// does, and a mapped file is never truncated.
///
/// [`write_psf`]: super::write_psf
pub fn open_psf(path: impl AsRef<Path>, opts: &OpenOptions) -> Result<BakedPsf, FormatError> {
    let path = path.as_ref();
    let io = |e| FormatError::io(path, e);
    let mut file = File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    if len < HEADER_LEN as u64 {
        // Too short to map usefully (and mapping 0 bytes fails on some systems): read
        // what is there so the header check reports it.
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io)?;
        return from_bytes(Arc::new(bytes), opts);
    }
    let map = map_read_only(&file).map_err(io)?;
    from_bytes(Arc::new(map), opts)
}

/// The one place the file is memory-mapped.
fn map_read_only(file: &File) -> std::io::Result<memmap2::Mmap> {
    // SAFETY: `Mmap::map` is unsafe because the mapped bytes may change or vanish under
    // us if the file is modified. The file is opened read-only, the mapping is private
    // and read-only, and nothing in this process writes to it. Another process
    // truncating the file makes accesses past the new end raise SIGBUS (no silent UB on
    // the platforms we support); another process writing it in place could change bytes
    // after validation, which the writer never does (it renames a new file into place,
    // leaving mapped old files intact). Those two are the documented caveat of
    // `open_psf`.
    unsafe { memmap2::Mmap::map(file) }
}

/// Reads and checks the header alone (magic, version, byte order, checksum): cheap,
/// for tools that want a file's parameters or scene hash without opening it.
pub fn read_header(path: impl AsRef<Path>) -> Result<Header, FormatError> {
    let path = path.as_ref();
    let io = |e| FormatError::io(path, e);
    let file = File::open(path).map_err(io)?;
    let mut bytes = Vec::with_capacity(HEADER_LEN);
    file.take(HEADER_LEN as u64)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    Header::decode(&bytes)
}

fn to_usize(x: u64, what: &str) -> Result<usize, FormatError> {
    usize::try_from(x).map_err(|_| FormatError::NotSupported {
        what: format!("{what} of {x} bytes on this machine"),
    })
}

/// Opens a baked file held in memory (a buffer or any shared bytes). Raw sections are
/// used in place when `bytes` is aligned for them, copied otherwise.
pub fn from_bytes(bytes: SharedBytes, opts: &OpenOptions) -> Result<BakedPsf, FormatError> {
    if cfg!(not(target_endian = "little")) {
        return Err(FormatError::NotSupported {
            what: "reading baked files on a big-endian machine".into(),
        });
    }
    let all: &[u8] = (*bytes).as_ref();
    let header = Header::decode(all)?;
    if let Some(expected) = opts.expect_scene_hash {
        if expected != header.scene_hash {
            return Err(FormatError::StaleScene {
                expected,
                found: header.scene_hash,
            });
        }
    }
    let sections = validate_layout(&header, all)?;

    // Frames first: the tile counts they give fix the tile sections' lengths.
    let frames_entry = &sections[1];
    let frames: Buf<GridFrame> = load(&bytes, all, frames_entry)?;
    for (k, f) in frames.iter().enumerate() {
        let e = &sections[2 + PER_SUBFIELD * k];
        let needed = f.nu as u64 * f.nv as u64 * SectionKind::Tiles.item_size();
        if e.raw_length != needed {
            return Err(FormatError::invalid(
                e.id.to_string(),
                format!(
                    "{} raw bytes, subfield {k}'s {}x{} grid needs {needed}",
                    e.raw_length, f.nu, f.nv
                ),
            ));
        }
    }

    let (triangles, subfields) = rayon::join(
        || -> Result<Buf<[Vec3; 3]>, FormatError> {
            let tris: Buf<[Vec3; 3]> = load(&bytes, all, &sections[0])?;
            let found = scene_hash(&tris);
            if found != header.scene_hash {
                return Err(FormatError::invalid(
                    "triangles",
                    format!(
                        "their scene hash is {found}, the header records {}",
                        header.scene_hash
                    ),
                ));
            }
            Ok(tris)
        },
        || {
            // One result per subfield, then the first error in file order, so the
            // report does not depend on thread timing.
            let loaded: Vec<Result<Subfield, FormatError>> = (0..frames.len())
                .into_par_iter()
                .map(|k| {
                    let at = 2 + PER_SUBFIELD * k;
                    Ok(Subfield {
                        frame: frames[k],
                        tiles: load(&bytes, all, &sections[at])?,
                        slab_starts: load(&bytes, all, &sections[at + 1])?,
                        entries: load(&bytes, all, &sections[at + 2])?,
                        blocks: load(&bytes, all, &sections[at + 3])?,
                    })
                })
                .collect();
            loaded.into_iter().collect::<Result<Vec<_>, _>>()
        },
    );
    let triangles = triangles?;
    let subfields = subfields?;
    let params = PsfParams {
        level: header.level,
        tiles: header.tiles,
    };
    let psf = Psf::from_parts(params, header.margin, triangles, subfields)?
        .with_record(header.bake.bsp(), header.bake.tuning());
    Ok(BakedPsf {
        psf,
        header,
        sections,
    })
}

/// Checks the header's counts, the table, the layout of the sections and the file
/// length; returns the table.
fn validate_layout(header: &Header, all: &[u8]) -> Result<Vec<SectionEntry>, FormatError> {
    let have = all.len() as u64;
    let bad_header = |detail: String| FormatError::invalid("header", detail);
    let params = PsfParams {
        level: header.level,
        tiles: header.tiles,
    };
    params.validate().map_err(|e| bad_header(e.to_string()))?;
    if header.triangle_count > u32::MAX as u64 {
        return Err(bad_header(format!(
            "{} triangles is more than a PSF can index",
            header.triangle_count
        )));
    }
    let nsub = if header.triangle_count == 0 {
        0
    } else {
        subfield_directions(header.level).len() as u32
    };
    if header.subfield_count != nsub {
        return Err(bad_header(format!(
            "{} subfields, {} triangles at level {} make {nsub}",
            header.subfield_count, header.triangle_count, header.level
        )));
    }
    let nsec = 2 + PER_SUBFIELD * nsub as usize;
    if header.section_count as usize != nsec {
        return Err(bad_header(format!(
            "{} sections, {nsub} subfields make {nsec}",
            header.section_count
        )));
    }
    // Bounded: at most 2 + 4 * 514 rows.
    let table_end = HEADER_LEN + TABLE_ENTRY_LEN * nsec;
    let Some(table) = all.get(HEADER_LEN..table_end) else {
        return Err(FormatError::Truncated {
            section: "section table".into(),
            needed: table_end as u64,
            have,
        });
    };
    let found = checksum(table);
    if found != header.table_checksum {
        return Err(FormatError::Checksum {
            section: "section table".into(),
            expected: header.table_checksum,
            found,
        });
    }

    let mut sections = Vec::with_capacity(nsec);
    let mut end = table_end as u64;
    for (i, id) in section_ids(nsub).enumerate() {
        let row = &table[i * TABLE_ENTRY_LEN..(i + 1) * TABLE_ENTRY_LEN];
        let e = SectionEntry::decode(row, i, id)?;
        let bad = |detail: String| FormatError::invalid(id.to_string(), detail);
        let at = align_up(end);
        if e.offset != at {
            return Err(bad(format!(
                "starts at {}, the layout puts it at {at}",
                e.offset
            )));
        }
        end = e
            .offset
            .checked_add(e.stored_length)
            .ok_or_else(|| bad(format!("stored length {} overflows", e.stored_length)))?;
        let item = id.kind.item_size();
        if e.raw_length % item != 0 {
            return Err(bad(format!(
                "raw length {} is not a whole number of {item}-byte items",
                e.raw_length
            )));
        }
        match e.codec {
            Codec::None => {
                if e.raw_length != e.stored_length || e.raw_checksum != e.stored_checksum {
                    return Err(bad(
                        "stored raw, but its raw length or checksum differs from the stored one"
                            .into(),
                    ));
                }
            }
            Codec::Zstd => {
                if e.raw_length > MAX_RATIO.saturating_mul(e.stored_length) {
                    return Err(bad(format!(
                        "claims {} raw bytes from {} stored, more than {MAX_RATIO}x",
                        e.raw_length, e.stored_length
                    )));
                }
            }
        }
        let exact = match id.kind {
            SectionKind::Triangles => Some(header.triangle_count * item),
            SectionKind::Frames => Some(nsub as u64 * item),
            _ => None,
        };
        if let Some(n) = exact {
            if e.raw_length != n {
                return Err(bad(format!(
                    "{} raw bytes, the header's counts make {n}",
                    e.raw_length
                )));
            }
        }
        sections.push(e);
    }
    if header.file_length != end {
        return Err(bad_header(format!(
            "file length {}, the sections end at {end}",
            header.file_length
        )));
    }
    if have < end {
        // Name the first section the file stops short of.
        let short = sections
            .iter()
            .find(|e| e.end() > have)
            .map_or("file".to_string(), |e| e.id.to_string());
        return Err(FormatError::Truncated {
            section: short,
            needed: end,
            have,
        });
    }
    if have > end {
        return Err(FormatError::invalid(
            "file",
            format!("{} bytes after the last section", have - end),
        ));
    }
    // Padding between sections must be zero, so that every byte is checked.
    let mut prev = table_end;
    for e in &sections {
        // In range: every offset and end is at most `end == have`.
        let gap = &all[prev..e.offset as usize];
        if gap.iter().any(|&b| b != 0) {
            return Err(FormatError::invalid(
                format!("padding before {}", e.id),
                "is not zero",
            ));
        }
        prev = e.end() as usize;
    }
    Ok(sections)
}

/// Checks a section's stored bytes and turns them into its array: in place from
/// `bytes` when stored raw and aligned, decompressed into a buffer of exactly the raw
/// length (already bounded by the layout checks) otherwise.
fn load<T: Pod>(bytes: &SharedBytes, all: &[u8], e: &SectionEntry) -> Result<Buf<T>, FormatError> {
    let section = || e.id.to_string();
    // In range: validate_layout checked every section against the file length.
    let start = to_usize(e.offset, "an offset")?;
    let stored = &all[start..start + to_usize(e.stored_length, "a section")?];
    let found = checksum(stored);
    if found != e.stored_checksum {
        return Err(FormatError::Checksum {
            section: section(),
            expected: e.stored_checksum,
            found,
        });
    }
    let size = std::mem::size_of::<T>();
    debug_assert_eq!(size as u64, e.id.kind.item_size());
    let count = to_usize(e.raw_length, "a section")? / size;
    match e.codec {
        Codec::None => Ok(Buf::shared(bytes.clone(), start, count)
            // A buffer that is not aligned for T (not a mapping): copy.
            .unwrap_or_else(|| Buf::Owned(bytemuck::pod_collect_to_vec(stored)))),
        Codec::Zstd => {
            // Zeroed by the allocator (fresh pages need no second pass), and an error
            // rather than an abort when the memory is not there.
            let mut v: Vec<T> = bytemuck::allocation::try_zeroed_vec(count).map_err(|_| {
                FormatError::NotSupported {
                    what: format!("allocating {} bytes for {}", e.raw_length, section()),
                }
            })?;
            let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut v);
            let n = zstd::bulk::decompress_to_buffer(stored, dst).map_err(|err| {
                FormatError::invalid(section(), format!("zstd frame does not decode: {err}"))
            })?;
            if n != dst.len() {
                return Err(FormatError::invalid(
                    section(),
                    format!("zstd frame holds {n} bytes, the table says {}", dst.len()),
                ));
            }
            let found = checksum(dst);
            if found != e.raw_checksum {
                return Err(FormatError::Checksum {
                    section: format!("{} (decompressed)", section()),
                    expected: e.raw_checksum,
                    found,
                });
            }
            Ok(Buf::Owned(v))
        }
    }
}

// An opened file is shared across render threads.
const _: fn() = || {
    fn is<T: Send + Sync>() {}
    is::<BakedPsf>();
};
