//! The writer: lays out the sections, compresses them in parallel (each zstd frame on
//! one thread, so the bytes do not depend on the thread count), and writes the file
//! atomically.

use std::borrow::Cow;
use std::path::Path;

use rayon::prelude::*;
use serde::Serialize;

use super::{
    align_up, checksum, scene_hash, section_ids, BakeRecord, Codec, ContentHash, FormatError,
    Header, SceneHash, SectionEntry, SectionId, HEADER_LEN, MAX_RATIO, PER_SUBFIELD,
    TABLE_ENTRY_LEN, VERSION,
};
use crate::psf::Psf;

/// How to write a baked file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteOptions {
    pub codec: Codec,
    /// zstd level for [`Codec::Zstd`]. The default, 3, by measurement on the 100k room
    /// (`cargo bench --bench psf_file -- levels`, 2 cores): level 1 gives a 2.05x smaller
    /// file in 0.13 s, 3 gives 2.23x in 0.18 s, 9 gives 2.28x in 0.70 s, 19 gives 2.59x in
    /// 6.2 s and opens slower (59 ms against 31-39 ms).
    pub zstd_level: i32,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            codec: Codec::Zstd,
            zstd_level: 3,
        }
    }
}

/// What was written.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct WriteReport {
    /// Bytes of the whole file.
    pub file_length: u64,
    /// Bytes of all sections before compression.
    pub raw_length: u64,
    pub sections: usize,
    /// Sections stored raw although zstd was asked for (zstd saved nothing, or would
    /// exceed [`MAX_RATIO`]).
    pub stored_raw: usize,
    pub scene_hash: SceneHash,
    /// The hash of the file's bytes (see [`ContentHash`]).
    pub content_hash: ContentHash,
}

/// A section as stored: its codec, its bytes, and the checksum of its raw bytes.
type Stored<'a> = (Codec, Cow<'a, [u8]>, u64);

/// Encodes `psf` as a baked file in memory.
pub fn to_bytes(psf: &Psf, opts: &WriteOptions) -> Result<Vec<u8>, FormatError> {
    encode(psf, opts).map(|(bytes, _)| bytes)
}

fn encode(psf: &Psf, opts: &WriteOptions) -> Result<(Vec<u8>, WriteReport), FormatError> {
    if cfg!(not(target_endian = "little")) {
        return Err(FormatError::NotSupported {
            what: "writing baked files on a big-endian machine".into(),
        });
    }
    let subfields = psf.subfields();
    let nsub = u32::try_from(subfields.len()).map_err(|_| FormatError::NotSupported {
        what: format!("{} subfields", subfields.len()),
    })?;
    let frames: Vec<crate::psf::GridFrame> = subfields.iter().map(|s| s.frame).collect();
    // Raw bytes of every section in file order: the in-memory arrays are the stored
    // little-endian layout (checked above), so they are cast, not serialised.
    let mut raw: Vec<&[u8]> = Vec::with_capacity(2 + PER_SUBFIELD * subfields.len());
    raw.push(bytemuck::cast_slice(psf.triangles()));
    raw.push(bytemuck::cast_slice(&frames));
    for s in subfields {
        raw.push(bytemuck::cast_slice(&s.tiles));
        raw.push(bytemuck::cast_slice(&s.slab_starts));
        raw.push(bytemuck::cast_slice(&s.entries));
        raw.push(bytemuck::cast_slice(&s.blocks));
    }
    let ids: Vec<SectionId> = section_ids(nsub).collect();
    debug_assert_eq!(ids.len(), raw.len());

    // Compress and checksum in parallel; each frame on one thread.
    let level = opts.zstd_level;
    let stored: Vec<Result<Stored, FormatError>> = raw
        .par_iter()
        .zip(ids.par_iter())
        .map(|(&bytes, id)| {
            let raw_sum = checksum(bytes);
            if opts.codec == Codec::Zstd {
                let z = zstd::bulk::compress(bytes, level).map_err(|e| {
                    FormatError::invalid(id.to_string(), format!("zstd compression failed: {e}"))
                })?;
                let fits = (bytes.len() as u64) <= MAX_RATIO.saturating_mul(z.len() as u64);
                if z.len() < bytes.len() && fits {
                    return Ok((Codec::Zstd, Cow::Owned(z), raw_sum));
                }
            }
            Ok((Codec::None, Cow::Borrowed(bytes), raw_sum))
        })
        .collect();
    let stored: Vec<Stored> = stored.into_iter().collect::<Result<_, _>>()?;

    // Layout: header, table, then the sections in order, each at the next multiple of
    // ALIGN; the file ends where the last section ends.
    let table_len = (TABLE_ENTRY_LEN * ids.len()) as u64;
    let mut at = align_up(HEADER_LEN as u64 + table_len);
    let mut entries = Vec::with_capacity(ids.len());
    for (i, (codec, bytes, raw_sum)) in stored.iter().enumerate() {
        if i > 0 {
            at = align_up(at);
        }
        let stored_checksum = if *codec == Codec::None {
            *raw_sum
        } else {
            checksum(bytes)
        };
        entries.push(SectionEntry {
            id: ids[i],
            codec: *codec,
            offset: at,
            stored_length: bytes.len() as u64,
            raw_length: raw[i].len() as u64,
            stored_checksum,
            raw_checksum: *raw_sum,
        });
        at += bytes.len() as u64;
    }
    let file_length = at;
    let mut table = Vec::with_capacity(table_len as usize);
    for e in &entries {
        table.extend_from_slice(&e.encode());
    }
    let header = Header {
        version: VERSION,
        level: psf.params().level,
        tiles: psf.params().tiles,
        margin: psf.margin(),
        file_length,
        triangle_count: psf.triangles().len() as u64,
        subfield_count: nsub,
        section_count: ids.len() as u32,
        table_checksum: checksum(&table),
        scene_hash: scene_hash(psf.triangles()),
        bake: BakeRecord::of(psf.bsp_params(), psf.tuning()),
    };
    let len = usize::try_from(file_length).map_err(|_| FormatError::NotSupported {
        what: format!("a {file_length}-byte file on this machine"),
    })?;
    let mut out = Vec::with_capacity(len);
    out.extend_from_slice(&header.encode());
    out.extend_from_slice(&table);
    for (e, (_, bytes, _)) in entries.iter().zip(&stored) {
        out.resize(e.offset as usize, 0);
        out.extend_from_slice(bytes);
    }
    debug_assert_eq!(out.len(), len);
    let report = WriteReport {
        file_length,
        raw_length: raw.iter().map(|r| r.len() as u64).sum(),
        sections: entries.len(),
        stored_raw: entries
            .iter()
            .filter(|e| opts.codec == Codec::Zstd && e.codec == Codec::None)
            .count(),
        scene_hash: header.scene_hash,
        content_hash: ContentHash::of(&out),
    };
    Ok((out, report))
}

/// Writes `psf` to `path` atomically: a temporary file in the same folder, written and
/// flushed to disk, then renamed over `path` (and, on unix, the folder flushed), so a
/// crash or a failure leaves either the old file or the new one, never a partial one.
pub fn write_psf(
    path: impl AsRef<Path>,
    psf: &Psf,
    opts: &WriteOptions,
) -> Result<WriteReport, FormatError> {
    let path = path.as_ref();
    let (bytes, report) = encode(psf, opts)?;
    write_atomically(path, &bytes)?;
    Ok(report)
}

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FormatError> {
    crate::atomic::write_atomically(path, bytes).map_err(|e| FormatError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::super::SectionKind;
    use super::*;

    #[test]
    fn section_kinds_cover_the_layout() {
        let ids: Vec<_> = section_ids(2).map(|i| i.to_string()).collect();
        assert_eq!(
            ids,
            [
                "triangles",
                "frames",
                "tiles[0]",
                "slab_starts[0]",
                "entries[0]",
                "blocks[0]",
                "tiles[1]",
                "slab_starts[1]",
                "entries[1]",
                "blocks[1]"
            ]
        );
        assert_eq!(SectionKind::from_code(3), Some(SectionKind::Tiles));
        assert_eq!(SectionKind::from_code(6), Some(SectionKind::Blocks));
        assert_eq!(SectionKind::from_code(7), None);
    }

    #[test]
    fn subfield_counts_are_the_specs() {
        let n: Vec<usize> = (0..=crate::psf::MAX_LEVEL)
            .map(|l| crate::psf::subfield_directions(l).len())
            .collect();
        assert_eq!(n, [4, 7, 25, 109, 469], "formats/psf-v2.md lists these");
    }
}
