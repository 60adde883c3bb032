//! Atomic file writes, shared by everything that writes a file (glTF, .psf, EXR, PNG,
//! AFF, stats): a reader sees the old file or the whole new one, never a part, and a
//! killed process leaves at most a hidden temporary beside the target.
//!
//! A temporary is named `.{target}.{pid}-{n}-{host}.tmp`: the process, a counter, and the
//! host it runs on ([`host_id`]), so that on a folder shared by several machines (a
//! render farm's output) a starting render removes only the temporaries of dead processes
//! *of its own host* and never another node's frame in flight.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
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

/// What sits at a path that is not a regular file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FileKind {
    Directory,
    Fifo,
    Socket,
    CharDevice,
    BlockDevice,
    /// Anything else a platform has.
    Other,
}

impl std::fmt::Display for FileKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FileKind::Directory => "a folder",
            FileKind::Fifo => "a FIFO (named pipe)",
            FileKind::Socket => "a socket",
            FileKind::CharDevice => "a character device",
            FileKind::BlockDevice => "a block device",
            FileKind::Other => "not a plain file",
        })
    }
}

impl FileKind {
    fn of(t: fs::FileType) -> FileKind {
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if t.is_fifo() {
                return FileKind::Fifo;
            }
            if t.is_socket() {
                return FileKind::Socket;
            }
            if t.is_char_device() {
                return FileKind::CharDevice;
            }
            if t.is_block_device() {
                return FileKind::BlockDevice;
            }
        }
        if t.is_dir() {
            FileKind::Directory
        } else {
            FileKind::Other
        }
    }
}

/// Why a path cannot be written as a file (see [`write_target`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NotRegular {
    #[error("is {0}, not a regular file (a file is written by replacing it, and a device, FIFO, socket or folder is never replaced)")]
    Kind(FileKind),
    #[error("is a symbolic link to {}, which is {kind}, not a regular file", target.display())]
    LinkTo { target: PathBuf, kind: FileKind },
    #[error("is a symbolic link to {}, which cannot be followed ({source}); a link is written through only to an existing file", target.display())]
    BrokenLink {
        target: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The file a write to `path` replaces: `path` itself when nothing is there or a regular
/// file is; the file a symbolic link at `path` leads to, when it leads to a regular file
/// (the link stays, its target gets the new bytes). Refused: a folder, FIFO, socket or
/// device at `path` or at the end of its link, and a link that leads nowhere. A path
/// whose metadata cannot be read (no such folder, no permission) is returned as it is:
/// the write itself reports why it fails.
pub fn write_target(path: &Path) -> Result<PathBuf, NotRegular> {
    let Ok(meta) = fs::symlink_metadata(path) else {
        return Ok(path.to_path_buf());
    };
    let t = meta.file_type();
    if t.is_file() {
        return Ok(path.to_path_buf());
    }
    if !t.is_symlink() {
        return Err(NotRegular::Kind(FileKind::of(t)));
    }
    let shown = fs::read_link(path).unwrap_or_else(|_| path.to_path_buf());
    let real = fs::canonicalize(path).map_err(|source| NotRegular::BrokenLink {
        target: shown.clone(),
        source,
    })?;
    match fs::metadata(&real) {
        Ok(m) if m.is_file() => Ok(real),
        Ok(m) => Err(NotRegular::LinkTo {
            target: shown,
            kind: FileKind::of(m.file_type()),
        }),
        Err(source) => Err(NotRegular::BrokenLink {
            target: shown,
            source,
        }),
    }
}

/// A file written in pieces that appears at its path only when complete
/// ([`AtomicFile::commit`]): a hidden temporary beside the target (see the module docs)
/// until then, removed when the `AtomicFile` is dropped uncommitted. The target is
/// [`write_target`]'s: a symbolic link is written through to its regular file.
pub struct AtomicFile {
    file: Option<std::io::BufWriter<File>>,
    tmp: PathBuf,
    target: PathBuf,
}

impl AtomicFile {
    /// Creates the temporary for `path` (refusing what [`write_target`] refuses).
    pub fn create(path: &Path) -> std::io::Result<AtomicFile> {
        let target = write_target(path)
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
        let name = target.file_name().ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the path has no file name",
            )
        })?;
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let tmp = folder_of(&target).join(format!(
            ".{}.{}-{}-{}.tmp",
            name.to_string_lossy(),
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed),
            host_id()
        ));
        let f = OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        Ok(AtomicFile {
            file: Some(std::io::BufWriter::new(f)),
            tmp,
            target,
        })
    }

    /// Appends `bytes` (buffered: an error may show only at a later write or the commit).
    pub fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        match &mut self.file {
            Some(f) => f.write_all(bytes),
            None => Err(std::io::Error::other("the file was committed already")),
        }
    }

    /// Flushes the bytes to disk and renames the temporary over the target, then syncs
    /// the folder where the platform allows.
    pub fn commit(mut self) -> std::io::Result<()> {
        let Some(f) = self.file.take() else {
            return Ok(());
        };
        let f = f.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        drop(f);
        fs::rename(&self.tmp, &self.target)?;
        // Persist the rename itself; not every platform can open a folder.
        if let Ok(d) = File::open(folder_of(&self.target)) {
            let _ = d.sync_all();
        }
        // Renamed: nothing for `drop` to remove.
        self.tmp = PathBuf::new();
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        // Not committed, or the commit failed part-way: the temporary goes (it may be
        // gone already).
        self.file = None;
        if !self.tmp.as_os_str().is_empty() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Writes `bytes` to `path` through an [`AtomicFile`]: a new temporary file in the same
/// folder (named after the target, the process, a counter and the host, so concurrent
/// writers never share one, even across machines), flushed to disk, renamed over `path`,
/// then the folder synced where the platform allows. The temporary is removed on
/// failure. A symbolic link at `path` is written through to the regular file it leads
/// to; a folder, FIFO, socket or device is refused ([`write_target`]).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes)?;
    f.commit()
}

/// The folder a file is written in: its parent, or `.` for a bare file name.
pub fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Creates `folder` and the folders above it (`create_dir_all`); where a file sits where
/// one of them should be, the error says which, with [`ErrorKind::NotADirectory`]
/// (bad input: no retry makes a file a folder), not "File exists".
///
/// [`ErrorKind::NotADirectory`]: std::io::ErrorKind::NotADirectory
pub fn create_folder(folder: &Path) -> io::Result<()> {
    fs::create_dir_all(folder).map_err(|e| match folder.ancestors().find(|a| a.exists()) {
        Some(a) if !a.is_dir() => io::Error::new(
            io::ErrorKind::NotADirectory,
            format!("{} is a file, not a folder", a.display()),
        ),
        _ => e,
    })
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

    /// A folder or FIFO is refused and left as it is; a link to a regular file is written
    /// through (the link stays); a link to a FIFO or to nothing is refused.
    #[cfg(unix)]
    #[test]
    fn only_regular_files_are_replaced() {
        use std::os::unix::fs::symlink;
        let dir = std::env::temp_dir().join(format!("subfield-target-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(dir.join("folder")).unwrap();
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .is_ok_and(|s| s.success());
        assert!(made, "mkfifo is needed for this test");
        let kind = |p: &Path| match write_target(p) {
            Err(NotRegular::Kind(k)) => Some(k),
            _ => None,
        };
        assert_eq!(kind(&dir.join("folder")), Some(FileKind::Directory));
        assert_eq!(kind(&fifo), Some(FileKind::Fifo));
        assert!(write_atomically(&fifo, b"x").is_err());
        {
            use std::os::unix::fs::FileTypeExt;
            assert!(fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        }
        // Nothing, or a regular file: itself.
        assert_eq!(write_target(&dir.join("new")).unwrap(), dir.join("new"));
        // A link to a regular file: written through, the link kept.
        fs::write(dir.join("real"), b"old").unwrap();
        symlink("real", dir.join("link")).unwrap();
        write_atomically(&dir.join("link"), b"new").unwrap();
        assert!(fs::symlink_metadata(dir.join("link"))
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(fs::read(dir.join("real")).unwrap(), b"new");
        // A link to the FIFO, a dangling link: refused, left alone.
        symlink(&fifo, dir.join("to-fifo")).unwrap();
        assert!(matches!(
            write_target(&dir.join("to-fifo")),
            Err(NotRegular::LinkTo {
                kind: FileKind::Fifo,
                ..
            })
        ));
        symlink("missing", dir.join("dangling")).unwrap();
        assert!(matches!(
            write_target(&dir.join("dangling")),
            Err(NotRegular::BrokenLink { .. })
        ));
        assert!(write_atomically(&dir.join("dangling"), b"x").is_err());
        assert!(!dir.join("missing").exists());
        // No temporary left by any of it.
        let hidden = fs::read_dir(&dir)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with('.')
            })
            .count();
        assert_eq!(hidden, 0);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_uncommitted_file_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("subfield-atomicfile-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let p = dir.join("s.csv");
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"a,b\n").unwrap();
        assert!(!p.exists());
        drop(f);
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 0);
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"a,b\n").unwrap();
        f.write_all(b"1,2\n").unwrap();
        f.commit().unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"a,b\n1,2\n");
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
