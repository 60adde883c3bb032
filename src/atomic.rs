//! Atomic file writes, shared by everything that writes a file (glTF, .psf, EXR, PNG,
//! AFF, stats): a reader sees the old file or the whole new one, never a part, and a
//! killed process leaves at most a hidden temporary beside the target.
//!
//! A temporary is named `.{target}.{pid}-{n}-{host}.tmp`: the process, a counter, and the
//! host it runs on ([`host_id`]), so that on a folder shared by several machines (a
//! render farm's output) a starting render removes only the temporaries of dead processes
//! *of its own host* and never another node's frame in flight.

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

/// This machine's name as temporaries carry it: `SUBFIELD_HOSTNAME` when set (tests
/// play two hosts with it), else the kernel's host name, cut at the first dot (Slurm
/// names nodes by their short names) and kept to ASCII letters, digits and `_`
/// (anything else becomes `_`); `localhost` when no name can be read.
pub fn host_id() -> &'static str {
    static HOST: OnceLock<String> = OnceLock::new();
    HOST.get_or_init(|| {
        let raw = std::env::var("SUBFIELD_HOSTNAME")
            .ok()
            .or_else(|| fs::read_to_string("/proc/sys/kernel/hostname").ok())
            .or_else(|| fs::read_to_string("/etc/hostname").ok())
            .or_else(|| std::env::var("HOSTNAME").ok())
            .unwrap_or_default();
        sanitize_host(&raw)
    })
}

fn sanitize_host(raw: &str) -> String {
    let short = raw.trim().split('.').next().unwrap_or("");
    let clean: String = short
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if clean.is_empty() {
        "localhost".into()
    } else {
        clean
    }
}

/// Writes `bytes` to `path`: a new temporary file in the same folder (named after the
/// target, the process, a counter and the host, so concurrent writers never share one,
/// even across machines), flushed to
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
        ".{}.{}-{}-{}.tmp",
        name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed),
        host_id()
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

/// Removes the temporaries that killed processes of this host left in `dir` (see
/// [`write_atomically`]): hidden files `.{target}.{pid}-{n}-{host}.tmp` whose `target`
/// passes `wanted`, whose `host` is [`host_id`] and whose process `pid` no longer runs
/// here. A temporary of a live process (a concurrent shard, say) or of another host (a
/// node sharing the folder) is left alone. Where the platform does not show which
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
        let Some((target, pid, host)) = name.to_str().and_then(parse_temporary) else {
            continue;
        };
        if host == host_id() && wanted(target) && !proc_root.join(pid.to_string()).exists() {
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

/// `.{target}.{pid}-{n}-{host}.tmp` → `(target, pid, host)`.
fn parse_temporary(name: &str) -> Option<(&str, u32, &str)> {
    let rest = name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (target, tail) = rest.rsplit_once('.')?;
    let mut parts = tail.splitn(3, '-');
    let pid = parts.next()?.parse().ok()?;
    parts.next()?.parse::<u64>().ok()?;
    let host = parts.next().filter(|h| !h.is_empty())?;
    Some((target, pid, host)).filter(|(t, _, _)| !t.is_empty())
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
    fn host_names_are_kept_short_and_plain() {
        assert_eq!(sanitize_host("node7.cluster.example\n"), "node7");
        assert_eq!(sanitize_host("a-b c"), "a_b_c");
        assert_eq!(sanitize_host(""), "localhost");
        assert!(!host_id().is_empty() && !host_id().contains(['.', '-']));
    }

    #[test]
    fn temporary_names_parse() {
        assert_eq!(
            parse_temporary(".f.0003.exr.123-7-node_a.tmp"),
            Some(("f.0003.exr", 123, "node_a"))
        );
        assert_eq!(
            parse_temporary(".a.b.c.1-0-n-1.tmp"),
            Some(("a.b.c", 1, "n-1"))
        );
        for bad in [
            "f.0003.exr",
            ".f.exr.x-1-h.tmp",
            ".f.exr.1-y-h.tmp",
            "..1-0-h.tmp",
            ".f.exr.1-0-h.tmpx",
            ".f.exr.1-0.tmp",
            ".f.exr.1-0-.tmp",
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
        let host = host_id();
        let names = [
            format!(".a.exr.{dead}-0-{host}.tmp"), // stale, wanted: removed
            format!(".a.exr.{me}-3-{host}.tmp"),   // a live process's: kept
            format!(".b.exr.{dead}-1-{host}.tmp"), // not wanted: kept
            format!(".a.exr.{dead}-2-{host}x.tmp"), // another host's: kept
            "a.exr".to_string(),                   // the target itself: kept
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
