//! An independent implementation of `formats/psf-v2.md`'s checksums (written from the
//! spec's byte tables, not from the library): `tests/psf_file.rs` uses it to push damaged
//! files past the checksums to the structural checks, and so does the fuzz target
//! `fuzz/fuzz_targets/psf_reader.rs`.

use xxhash_rust::xxh3::xxh3_64;

/// Recomputes every checksum of a file whose sections are all stored raw, as the spec
/// defines them (an independent implementation of its byte tables): so a mutation gets
/// past the checksums and reaches the structural validation.
pub fn reseal(b: &mut [u8]) {
    if b.len() < 128 {
        return;
    }
    let n = u32::from_le_bytes(b[52..56].try_into().unwrap()) as usize;
    let table_end = 128 + 48 * n;
    if n > 10_000 || b.len() < table_end {
        return;
    }
    for i in 0..n {
        let row = 128 + 48 * i;
        let off = u64::from_le_bytes(b[row + 8..row + 16].try_into().unwrap());
        let len = u64::from_le_bytes(b[row + 16..row + 24].try_into().unwrap());
        let Some(end) = off.checked_add(len) else {
            continue;
        };
        if b[row + 2] != 0 || end > b.len() as u64 {
            continue;
        }
        let sum = xxh3_64(&b[off as usize..end as usize]).to_le_bytes();
        b[row + 32..row + 40].copy_from_slice(&sum);
        b[row + 40..row + 48].copy_from_slice(&sum);
    }
    let t = xxh3_64(&b[128..table_end]).to_le_bytes();
    b[56..64].copy_from_slice(&t);
    let h = xxh3_64(&b[..120]).to_le_bytes();
    b[120..128].copy_from_slice(&h);
}
