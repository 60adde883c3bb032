//! Content hashes: a hash of a file's bytes, whatever they hold. A baked file is
//! shipped and cached under its content hash (`<hash>.psf` in a node's stage, see
//! [`crate::farm`]), and a job names the bake and the scene file it was submitted with
//! by theirs, so a task refuses any other file. Distinct from the *scene hash* in a
//! baked file's header, which hashes the static triangles it was baked from.

use std::fmt;
use std::fs::File;
use std::io::{Read, Write};
use std::path::Path;
use std::str::FromStr;

use serde::Serialize;
use xxhash_rust::xxh3::{xxh3_128, Xxh3};

/// xxh3-128 (seed 0) of a file's bytes, shown as 32 lower-case hex digits. Not a
/// cryptographic hash: it guards against stale, truncated and mixed-up files, not
/// against an adversary who can write to the farm's storage.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ContentHash(pub u128);

impl ContentHash {
    /// The hash of `bytes`.
    pub fn of(bytes: &[u8]) -> ContentHash {
        ContentHash(xxh3_128(bytes))
    }
}

impl fmt::Display for ContentHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:032x}", self.0)
    }
}

impl fmt::Debug for ContentHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ContentHash({self})")
    }
}

impl Serialize for ContentHash {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// A content hash that is not 32 hex digits.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not a content hash (32 hex digits, as `subfield bake` prints)")]
pub struct BadContentHash(pub String);

impl FromStr for ContentHash {
    type Err = BadContentHash;

    fn from_str(s: &str) -> Result<ContentHash, BadContentHash> {
        let t = s.trim();
        if t.len() != 32 || !t.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(BadContentHash(s.to_string()));
        }
        u128::from_str_radix(t, 16)
            .map(ContentHash)
            .map_err(|_| BadContentHash(s.to_string()))
    }
}

/// A copy that stopped: reading its source or writing its destination failed.
#[derive(Debug)]
#[non_exhaustive]
pub enum CopyError {
    Read(std::io::Error),
    Write(std::io::Error),
}

/// Copies everything `reader` yields to `writer` in 1 MiB pieces, hashing it on the
/// way; returns the hash of what was copied and its length.
pub fn hash_copy(
    mut reader: impl Read,
    mut writer: impl Write,
) -> Result<(ContentHash, u64), CopyError> {
    let mut h = Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0u64;
    loop {
        let n = match reader.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(CopyError::Read(e)),
        };
        h.update(&buf[..n]);
        writer.write_all(&buf[..n]).map_err(CopyError::Write)?;
        total += n as u64;
    }
    Ok((ContentHash(h.digest128()), total))
}

/// Hashes everything `reader` yields, in 1 MiB reads.
pub fn hash_reader(reader: impl Read) -> std::io::Result<(ContentHash, u64)> {
    hash_copy(reader, std::io::sink()).map_err(|e| match e {
        CopyError::Read(e) | CopyError::Write(e) => e,
    })
}

/// The content hash of the file at `path` (read once, in 1 MiB pieces).
pub fn hash_file(path: &Path) -> std::io::Result<ContentHash> {
    hash_reader(File::open(path)?).map(|(h, _)| h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streamed_hash_equals_one_shot_and_round_trips_as_text() {
        let bytes: Vec<u8> = (0..3_000_000u32).map(|i| (i * 7 + i / 13) as u8).collect();
        let (streamed, n) = hash_reader(&bytes[..]).unwrap();
        assert_eq!(n, bytes.len() as u64);
        assert_eq!(streamed, ContentHash::of(&bytes));
        let text = streamed.to_string();
        assert_eq!(text.len(), 32);
        assert_eq!(text.parse::<ContentHash>().unwrap(), streamed);
        assert_eq!(
            text.to_uppercase().parse::<ContentHash>().unwrap(),
            streamed
        );
        assert_ne!(ContentHash::of(&bytes[1..]), streamed);
        for bad in [
            "",
            "xyz",
            &text[1..],
            &format!("{text}0"),
            &format!("g{}", &text[1..]),
        ] {
            assert!(bad.parse::<ContentHash>().is_err(), "{bad:?}");
        }
    }
}
