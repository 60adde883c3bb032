//! ZIP compression of a frame's EXR, by libdeflate instead of the `exr` crate's
//! miniz_oxide: the same format (OpenEXR's `ZIP_COMPRESSION`, 16 scan lines a block)
//! in half the time, for files of the same size (a 640x480 RGBA half frame: 8.5–9 ms
//! and 219,685 bytes against 15–18 ms and 221,934, `benches/PERF.md`, issue 23, step 4).
//! On two cores the writer thread's compression runs beside the next frame's trace,
//! so every millisecond it spends is taken from the render.
//!
//! The `exr` crate writes the frame uncompressed (one scan line a block, which costs
//! nothing beside compressing); [`zip_scanlines`] then regroups its lines sixteen to a
//! block, compresses each block as OpenEXR's `ZIP_COMPRESSION` does (the bytes split
//! into even and odd halves, each byte replaced by its difference from the one before
//! plus 128, then zlib), sets the header's `compression` to ZIP and its `chunkCount` to
//! the blocks, and writes the new offset table. A block that would not shrink is stored raw, as the format allows.
//! The blocks are compressed in parallel (issue 38: one writer thread was 15 ms of a
//! 16-core frame at 640x480 and 84 ms at 1920x1080), each on its own, so the bytes do
//! not depend on the thread count.

/// What one compression worker made: (block number, its bytes), or why it failed.
type Compressed = Result<Vec<(usize, Vec<u8>)>, Malformed>;

/// Scan lines a ZIP block holds (OpenEXR's `ZIP_COMPRESSION`).
pub const LINES: usize = 16;

/// libdeflate's level: 4 gives files as small as miniz_oxide's level 4 (the `exr`
/// crate's) at about half its time; level 1 was 25% faster again and 15% larger.
const LEVEL: i32 = 4;

/// OpenEXR's code of `ZIP_COMPRESSION` in the `compression` attribute.
const ZIP_COMPRESSION: u8 = 3;

/// What [`zip_scanlines`] cannot make sense of (a file not as the `exr` crate writes
/// an uncompressed single-part scan-line image).
#[derive(Debug, thiserror::Error)]
#[error("uncompressed EXR not as expected: {0}")]
pub struct Malformed(&'static str);

fn read_i32(b: &[u8], at: usize) -> Result<i32, Malformed> {
    b.get(at..at + 4)
        .map(|s| i32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or(Malformed("truncated"))
}

fn read_u64(b: &[u8], at: usize) -> Result<u64, Malformed> {
    b.get(at..at + 8)
        .map(|s| u64::from_le_bytes([s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]]))
        .ok_or(Malformed("truncated"))
}

/// Where the header's values [`zip_scanlines`] changes are.
struct HeaderAt {
    /// Just past the header's terminating zero.
    end: usize,
    /// The `compression` attribute's value byte.
    compression: usize,
    /// The `chunkCount` attribute's value (an `int`), where the header has one.
    chunk_count: Option<usize>,
}

fn header_end(b: &[u8]) -> Result<HeaderAt, Malformed> {
    let cstr = |from: usize| {
        b.get(from..)
            .and_then(|s| s.iter().position(|&c| c == 0))
            .map(|n| from + n)
            .ok_or(Malformed("unterminated header"))
    };
    let mut at = 8; // magic number and version
    let (mut compression, mut chunk_count) = (None, None);
    loop {
        let name_end = cstr(at)?;
        if name_end == at {
            return Ok(HeaderAt {
                end: at + 1,
                compression: compression.ok_or(Malformed("no compression"))?,
                chunk_count,
            });
        }
        let type_end = cstr(name_end + 1)?;
        let size = read_i32(b, type_end + 1)?;
        let size = usize::try_from(size).map_err(|_| Malformed("negative attribute size"))?;
        let value = type_end + 5;
        if &b[at..name_end] == b"compression" {
            if size != 1 {
                return Err(Malformed("compression attribute size"));
            }
            compression = Some(value);
        }
        if &b[at..name_end] == b"chunkCount" {
            if size != 4 {
                return Err(Malformed("chunkCount attribute size"));
            }
            chunk_count = Some(value);
        }
        at = value + size;
    }
}

/// OpenEXR's ZIP predictor on `raw`, into `out`: even bytes, then odd bytes, each
/// replaced by its difference from the one before plus 128 (wrapping).
fn predict(raw: &[u8], out: &mut Vec<u8>) {
    out.clear();
    out.extend(raw.iter().step_by(2));
    out.extend(raw.iter().skip(1).step_by(2));
    let mut prev = match out.first() {
        Some(&p) => p,
        None => return,
    };
    for b in out.iter_mut().skip(1) {
        let v = *b;
        *b = v.wrapping_sub(prev).wrapping_add(128);
        prev = v;
    }
}

/// `uncompressed` (an EXR the `exr` crate wrote with `Compression::Uncompressed`,
/// scan lines, one part) as the same image ZIP-compressed, sixteen lines a block.
pub fn zip_scanlines(uncompressed: &[u8]) -> Result<Vec<u8>, Malformed> {
    let b = uncompressed;
    if b.get(0..4) != Some(&[0x76, 0x2f, 0x31, 0x01]) {
        return Err(Malformed("magic number"));
    }
    // Version 2, single part, scan lines, no long names, not deep (flags 0).
    if b.get(4..8) != Some(&[2, 0, 0, 0]) {
        return Err(Malformed("version or flags"));
    }
    let HeaderAt {
        end,
        compression: comp_at,
        chunk_count,
    } = header_end(b)?;
    if b[comp_at] != 0 {
        return Err(Malformed("already compressed"));
    }
    // The offset table: one offset a scan line, the lines in order after it.
    let first = read_u64(b, end)? as usize;
    if first < end || !(first - end).is_multiple_of(8) {
        return Err(Malformed("offset table"));
    }
    let lines = (first - end) / 8;
    let mut spans = Vec::with_capacity(lines);
    let mut y0 = 0;
    let mut at = first;
    for i in 0..lines {
        if read_u64(b, end + 8 * i)? as usize != at {
            return Err(Malformed("lines out of order"));
        }
        let y = read_i32(b, at)?;
        if i == 0 {
            y0 = y;
        } else if i64::from(y) != i64::from(y0) + i as i64 {
            return Err(Malformed("line numbers"));
        }
        let size = usize::try_from(read_i32(b, at + 4)?).map_err(|_| Malformed("line size"))?;
        let data = at + 8;
        if data + size > b.len() {
            return Err(Malformed("truncated line"));
        }
        spans.push((data, size));
        at = data + size;
    }

    let blocks = lines.div_ceil(LINES);
    let mut out = Vec::with_capacity(b.len() / 4 + end + 8 * blocks);
    out.extend_from_slice(&b[..end]);
    out[comp_at] = ZIP_COMPRESSION;
    if let Some(at) = chunk_count {
        let n = i32::try_from(blocks).map_err(|_| Malformed("too many blocks"))?;
        out[at..at + 4].copy_from_slice(&n.to_le_bytes());
    }
    out.resize(end + 8 * blocks, 0);
    let level =
        libdeflater::CompressionLvl::new(LEVEL).map_err(|_| Malformed("compression level"))?;
    // The blocks are independent: each is compressed by whichever worker takes it
    // next (one compressor and scratch a worker), and the bytes of each depend on its
    // lines alone, so the file is the same whatever the thread count. The workers are
    // threads of their own, as many as the render's pool has (`--threads`), not tasks
    // of that pool: the writer thread calls this while the pool's threads may be
    // waiting for the writer to take the next frame, and tasks queued on them then
    // would never run (with `--threads 1` that hung every render).
    let groups: Vec<&[(usize, usize)]> = spans.chunks(LINES).collect();
    let workers = rayon::current_num_threads().clamp(1, groups.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let compress = || -> Compressed {
        let mut compressor = libdeflater::Compressor::new(level);
        let (mut raw, mut predicted, mut packed) = (Vec::new(), Vec::new(), Vec::new());
        let mut done = Vec::new();
        loop {
            let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let Some(group) = groups.get(k) else {
                return Ok(done);
            };
            raw.clear();
            for &(data, size) in group.iter() {
                raw.extend_from_slice(&b[data..data + size]);
            }
            predict(&raw, &mut predicted);
            packed.resize(compressor.zlib_compress_bound(predicted.len()), 0);
            let n = compressor
                .zlib_compress(&predicted, &mut packed)
                .map_err(|_| Malformed("compression failed"))?;
            // Stored raw where compression does not shrink it (readers take a block of
            // the uncompressed size as raw).
            done.push((
                k,
                if n < raw.len() {
                    packed[..n].to_vec()
                } else {
                    raw.clone()
                },
            ));
        }
    };
    let mut bodies: Vec<Vec<u8>> = vec![Vec::new(); groups.len()];
    let results: Vec<Compressed> = if workers == 1 {
        vec![compress()]
    } else {
        std::thread::scope(|scope| {
            let handles: Vec<_> = (0..workers).map(|_| scope.spawn(compress)).collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or(Err(Malformed("a compression worker panicked")))
                })
                .collect()
        })
    };
    for r in results {
        for (k, body) in r? {
            bodies[k] = body;
        }
    }
    for (k, body) in bodies.into_iter().enumerate() {
        let offset = out.len() as u64;
        out[end + 8 * k..end + 8 * k + 8].copy_from_slice(&offset.to_le_bytes());
        let y = y0 + (k * LINES) as i32;
        out.extend_from_slice(&y.to_le_bytes());
        let len = i32::try_from(body.len()).map_err(|_| Malformed("block too large"))?;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&body);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_predictor_splits_and_differences_as_openexr_does() {
        let mut out = Vec::new();
        predict(&[10, 1, 12, 2, 9, 3], &mut out);
        // Even bytes 10 12 9, odd 1 2 3; differences + 128 from the second on.
        assert_eq!(out, vec![10, 130, 125, 120, 129, 129]);
        predict(&[], &mut out);
        assert!(out.is_empty());
    }

    /// An image of `h` lines (half and float channels, noisy and flat parts) through
    /// the `exr` crate uncompressed, then [`zip_scanlines`]; read back by the crate.
    fn round_trip(w: usize, h: usize) -> (usize, usize) {
        use exr::prelude::*;
        let n = w * h;
        let noise = |i: usize, k: u32| {
            let x = (i as u32).wrapping_mul(2_654_435_761).wrapping_add(k) >> 8;
            x as f32 / (1 << 24) as f32
        };
        let r: Vec<f16> = (0..n).map(|i| f16::from_f32(noise(i, 1))).collect();
        let flat: Vec<f16> = vec![f16::from_f32(1.0); n];
        let z: Vec<f32> = (0..n).map(|i| 1.0 + (i % w) as f32 * noise(i, 2)).collect();
        let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        list.push(AnyChannel::new("A", FlatSamples::F16(flat.clone())));
        list.push(AnyChannel::new("R", FlatSamples::F16(r.clone())));
        list.push(AnyChannel::new("Z", FlatSamples::F32(z.clone())));
        let enc = Encoding {
            compression: Compression::Uncompressed,
            blocks: Blocks::ScanLines,
            line_order: LineOrder::Increasing,
        };
        let layer = Layer::new(
            (w, h),
            LayerAttributes::default(),
            enc,
            AnyChannels::sort(list),
        );
        let mut raw = std::io::Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .non_parallel()
            .to_buffered(&mut raw)
            .unwrap();
        let raw = raw.into_inner();
        let zipped = zip_scanlines(&raw).unwrap();
        // The blocks are compressed in parallel: one thread and three give the same
        // bytes as the global pool.
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            assert!(
                pool.install(|| zip_scanlines(&raw).unwrap()) == zipped,
                "{threads} thread(s) gave other bytes"
            );
        }
        // Never larger: a block that would grow is stored raw.
        assert!(
            zipped.len() <= raw.len(),
            "{} of {}",
            zipped.len(),
            raw.len()
        );
        let back = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .pedantic()
            .from_buffered(std::io::Cursor::new(&zipped))
            .unwrap();
        assert_eq!(back.layer_data.encoding.compression, Compression::ZIP16);
        let chans = &back.layer_data.channel_data.list;
        let names: Vec<String> = chans.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(names, ["A", "R", "Z"]);
        assert_eq!(chans[0].sample_data, FlatSamples::F16(flat));
        assert_eq!(chans[1].sample_data, FlatSamples::F16(r));
        assert_eq!(chans[2].sample_data, FlatSamples::F32(z));
        (zipped.len(), raw.len())
    }

    #[test]
    fn zipped_frames_read_back_exactly_whole_and_partial_blocks() {
        // One line of noise does not shrink: stored raw, read back the same.
        round_trip(7, 1);
        round_trip(13, 16);
        round_trip(9, 37);
        let (zipped, raw) = round_trip(64, 48);
        assert!(zipped < raw * 3 / 4, "{zipped} of {raw}");
    }

    #[test]
    fn a_file_not_from_the_exr_crate_is_refused() {
        assert!(zip_scanlines(b"not an exr").is_err());
        assert!(zip_scanlines(&[0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0]).is_err());
    }
}
