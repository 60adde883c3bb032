//! A scene file's bytes, read by the render's threads side by side.
//!
//! `std::fs::read` of a 19 MB `.glb` took 25–32 ms of a render's start-up on one thread
//! (the kernel's copy into fresh pages, each first touched and zeroed by the reader), the
//! largest serial step before the first frame (`benches/PERF.md`, issue 38, round 19).
//! Here the buffer is allocated zeroed and untouched (`vec![0; n]`: fresh pages from the
//! system), and its chunks are read with positioned reads from the pool's threads, so
//! that the page work and the copy are shared out. The bytes are those of one read from
//! start to end: a file that changes size while it is read is read again by
//! `std::fs::read`, whose result (or error) stands.

#[cfg(unix)]
use std::fs::File;
use std::io;
use std::path::Path;

/// Below this a file is read in one call: threads would not pay for themselves.
#[cfg(unix)]
const PARALLEL_FROM: u64 = 4 << 20;

/// Bytes a task reads at a time.
#[cfg(unix)]
const CHUNK: usize = 1 << 20;

/// The whole file, as `std::fs::read` returns it (read that way outside Unix: the
/// positioned reads used here, `FileExt::read_exact_at`, are Unix's).
pub(crate) fn read_whole(path: &Path) -> io::Result<Vec<u8>> {
    #[cfg(unix)]
    {
        let file = File::open(path)?;
        let len = file.metadata()?.len();
        if len >= PARALLEL_FROM {
            if let Ok(n) = usize::try_from(len) {
                if let Some(bytes) = read_chunks(&file, n) {
                    return Ok(bytes);
                }
            }
        }
    }
    std::fs::read(path)
}

/// `n` bytes read in chunks side by side, if the file has exactly `n` (`None`
/// otherwise, or on any error: the caller reads it the plain way).
#[cfg(unix)]
fn read_chunks(file: &File, n: usize) -> Option<Vec<u8>> {
    use rayon::prelude::*;
    use std::os::unix::fs::FileExt;

    let mut bytes = vec![0u8; n];
    let read = bytes
        .par_chunks_mut(CHUNK)
        .enumerate()
        .try_for_each(|(k, chunk)| file.read_exact_at(chunk, (k * CHUNK) as u64));
    if read.is_err() {
        return None;
    }
    // Nothing past the end: a file that grew is read again whole.
    let mut probe = [0u8; 1];
    match file.read_at(&mut probe, n as u64) {
        Ok(0) => Some(bytes),
        _ => None,
    }
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    fn folder(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("subfield-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn reads_what_fs_read_reads_at_every_size() {
        let dir = folder("read-whole");
        // Below the parallel size, exactly at it, and over it by a part chunk.
        for n in [0usize, 1, 4 << 20, (4 << 20) + CHUNK * 3 + 12_345] {
            let path = dir.join(format!("f{n}.bin"));
            let data: Vec<u8> = (0..n)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
                .collect();
            std::fs::write(&path, &data).unwrap();
            assert_eq!(read_whole(&path).unwrap(), data, "{n} bytes");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_file_is_the_error_fs_read_gives() {
        let path = folder("read-missing").join("missing.glb");
        let ours = read_whole(&path).unwrap_err();
        let theirs = std::fs::read(&path).unwrap_err();
        assert_eq!(ours.kind(), theirs.kind());
    }
}
