//! Atomic file writes, shared by everything that writes a file (glTF, .psf, EXR, PNG,
//! AFF, stats): a reader sees the old file or the whole new one, never a part, and a
//! killed process leaves at most a hidden temporary beside the target.

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Writes `bytes` to `path`: a new temporary file in the same folder (named after the
/// target, the process and a counter, so concurrent writers never share one), flushed to
/// disk, renamed over `path`, then the folder synced where the platform allows. The
/// temporary is removed on failure.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path has no file name",
        )
    })?;
    let dir = folder_of(path);
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let tmp = dir.join(format!(
        ".{}.{}-{}.tmp",
        name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut f = OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)?;
        // Persist the rename itself; not every platform can open a folder.
        if let Ok(d) = File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    if result.is_err() {
        // The temporary may not exist (create failed) or be gone (renamed).
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// The folder a file is written in: its parent, or `.` for a bare file name.
pub fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Removes the temporaries that killed processes left in `dir` (see
/// [`write_atomically`]): hidden files `.{target}.{pid}-{n}.tmp` whose `target` passes
/// `wanted` and whose process `pid` no longer runs. A temporary of a live process (a
/// concurrent shard, say) is left alone. Where the platform does not show which
/// processes run (no `/proc`), nothing is removed. Returns how many were removed.
pub fn remove_stale_temporaries(
    dir: &Path,
    wanted: impl Fn(&str) -> bool,
) -> std::io::Result<usize> {
    let proc_root = Path::new("/proc");
    if !proc_root.join("self").exists() {
        return Ok(0);
    }
    let mut removed = 0;
    for entry in fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let Some((target, pid)) = name.to_str().and_then(parse_temporary) else {
            continue;
        };
        if wanted(target) && !proc_root.join(pid.to_string()).exists() {
            match fs::remove_file(entry.path()) {
                Ok(()) => removed += 1,
                // Gone already (another cleaner): fine.
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
    }
    Ok(removed)
}

/// `.{target}.{pid}-{n}.tmp` → `(target, pid)`.
fn parse_temporary(name: &str) -> Option<(&str, u32)> {
    let rest = name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (target, tail) = rest.rsplit_once('.')?;
    let (pid, n) = tail.split_once('-')?;
    n.parse::<u64>().ok()?;
    Some((target, pid.parse().ok()?)).filter(|(t, _)| !t.is_empty())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_replaces_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("subfield-atomic-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.bin");
        write_atomically(&p, b"one").unwrap();
        write_atomically(&p, b"two").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"two");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1);
        // A folder that does not exist: an error, and nothing left behind.
        assert!(write_atomically(&dir.join("missing/b.bin"), b"x").is_err());
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn temporary_names_parse() {
        assert_eq!(
            parse_temporary(".f.0003.exr.123-7.tmp"),
            Some(("f.0003.exr", 123))
        );
        assert_eq!(parse_temporary(".a.b.c.1-0.tmp"), Some(("a.b.c", 1)));
        for bad in [
            "f.0003.exr",
            ".f.exr.x-1.tmp",
            ".f.exr.1-y.tmp",
            "..1-0.tmp",
            ".f.exr.1-0.tmpx",
        ] {
            assert_eq!(parse_temporary(bad), None, "{bad}");
        }
    }

    #[test]
    fn stale_temporaries_of_dead_processes_are_removed() {
        if !Path::new("/proc/self").exists() {
            eprintln!("skipped: no /proc on this platform, nothing is ever removed");
            return;
        }
        let dir = std::env::temp_dir().join(format!("subfield-stale-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        // Above Linux's largest pid (2^22): no such process.
        let dead = 4_194_304 + 17;
        let me = std::process::id();
        let names = [
            format!(".a.exr.{dead}-0.tmp"), // stale, wanted: removed
            format!(".a.exr.{me}-3.tmp"),   // a live process's: kept
            format!(".b.exr.{dead}-1.tmp"), // not wanted: kept
            "a.exr".to_string(),            // the target itself: kept
        ];
        for n in &names {
            fs::write(dir.join(n), b"x").unwrap();
        }
        let n = remove_stale_temporaries(&dir, |t| t == "a.exr").unwrap();
        assert_eq!(n, 1);
        let mut left: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        let mut want = names[1..].to_vec();
        want.sort();
        assert_eq!(left, want);
        fs::remove_dir_all(&dir).unwrap();
    }
}
