//! The node-local stage: a content-addressed cache of the files a task maps.
//!
//! `stage_file(source, Some(h), dir)` returns `dir/<h>.psf`, copying `source` there first
//! unless a file of that name with exactly those bytes is there already. The copy goes to
//! a temporary in `dir` (named after this process and host, so tasks racing on one node
//! never share one), is hashed while it is written, flushed, made read-only and renamed
//! into place; a copy whose hash is not `h` is removed and refused. A cached file with the
//! right name and the wrong bytes (a disk error, a hand edit) is replaced, never used.
//! A staged file is never written again, so mapping it cannot fault the way mapping a
//! shared file that someone overwrites in place does.

use std::fs::{self, File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use super::FarmError;
use crate::format::{hash_copy, hash_file, ContentHash, CopyError};

/// The stage a task uses when none is given: `$TMPDIR/subfield-stage` (`/tmp` when
/// `TMPDIR` is unset), which Slurm and most farms keep node-local.
pub fn default_stage_dir() -> PathBuf {
    std::env::temp_dir().join("subfield-stage")
}

/// A file resolved through the stage.
#[derive(Clone, Debug, PartialEq)]
pub struct Staged {
    /// The staged copy, `<dir>/<hash>.<ext>`.
    pub path: PathBuf,
    pub hash: ContentHash,
    /// Whether this call copied it (false: it was cached and verified).
    pub copied: bool,
    /// A cached file of that name held other bytes and was replaced.
    pub replaced_bad_copy: bool,
    pub bytes: u64,
    /// Time spent hashing and copying.
    pub seconds: f64,
}

/// Checks that `path` hashes to `expected`; `what` names the file in the error ("scene
/// file").
pub fn verify_file(
    what: &'static str,
    path: &Path,
    expected: ContentHash,
) -> Result<(), FarmError> {
    let found = hash_file(path).map_err(|e| FarmError::io(path, e))?;
    if found != expected {
        return Err(FarmError::HashMismatch {
            what,
            path: path.to_path_buf(),
            expected,
            found,
        });
    }
    Ok(())
}

/// Resolves `source` through the stage in `dir` (created if needed) and returns the
/// staged copy (see the module docs). Without `expected`, the source is hashed first
/// and staged under its own hash.
pub fn stage_file(
    source: &Path,
    expected: Option<ContentHash>,
    dir: &Path,
) -> Result<Staged, FarmError> {
    let clock = Instant::now();
    let ext = source
        .extension()
        .and_then(|e| e.to_str())
        .filter(|e| e.bytes().all(|b| b.is_ascii_alphanumeric()))
        .unwrap_or("bin");
    let hash = match expected {
        Some(h) => h,
        None => hash_file(source).map_err(|e| FarmError::io(source, e))?,
    };
    let path = dir.join(format!("{hash}.{ext}"));
    let mut replaced_bad_copy = false;
    if path.is_file() {
        match hash_file(&path) {
            Ok(h) if h == hash => {
                let bytes = fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
                return Ok(Staged {
                    path,
                    hash,
                    copied: false,
                    replaced_bad_copy,
                    bytes,
                    seconds: clock.elapsed().as_secs_f64(),
                });
            }
            // Unreadable or other bytes: replaced below by a verified copy.
            _ => replaced_bad_copy = true,
        }
    }
    fs::create_dir_all(dir).map_err(|e| FarmError::io(dir, e))?;
    let bytes = copy_verified(source, &path, hash)?;
    Ok(Staged {
        path,
        hash,
        copied: true,
        replaced_bad_copy,
        bytes,
        seconds: clock.elapsed().as_secs_f64(),
    })
}

/// Copies `source` to a temporary beside `dest`, hashing as it goes; renames it over
/// `dest` when the hash is `want`, removes it otherwise.
fn copy_verified(source: &Path, dest: &Path, want: ContentHash) -> Result<u64, FarmError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let dir = crate::atomic::folder_of(dest);
    let name = dest
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(
        ".{name}.{}-{}-{}.tmp",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed),
        crate::atomic::host_id()
    ));
    let result = (|| {
        let src = File::open(source).map_err(|e| FarmError::io(source, e))?;
        let mut out = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| FarmError::io(&tmp, e))?;
        let (found, total) = hash_copy(src, &mut out).map_err(|e| match e {
            CopyError::Read(e) => FarmError::io(source, e),
            CopyError::Write(e) => FarmError::io(&tmp, e),
        })?;
        if found != want {
            return Err(FarmError::HashMismatch {
                what: "baked file",
                path: source.to_path_buf(),
                expected: want,
                found,
            });
        }
        out.sync_all().map_err(|e| FarmError::io(&tmp, e))?;
        let mut perms = out
            .metadata()
            .map_err(|e| FarmError::io(&tmp, e))?
            .permissions();
        perms.set_readonly(true);
        fs::set_permissions(&tmp, perms).map_err(|e| FarmError::io(&tmp, e))?;
        drop(out);
        fs::rename(&tmp, dest).map_err(|e| FarmError::io(dest, e))?;
        if let Ok(d) = File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(total)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("subfield-stage-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn copies_once_then_uses_the_cache_and_replaces_a_bad_copy() {
        let d = scratch("cache");
        let src = d.join("scene.psf");
        fs::write(&src, b"baked bytes").unwrap();
        let h = ContentHash::of(b"baked bytes");
        let stage = d.join("stage");
        let a = stage_file(&src, Some(h), &stage).unwrap();
        assert!(a.copied && !a.replaced_bad_copy);
        assert_eq!(a.path, stage.join(format!("{h}.psf")));
        assert_eq!(fs::read(&a.path).unwrap(), b"baked bytes");
        assert!(fs::metadata(&a.path).unwrap().permissions().readonly());
        let b = stage_file(&src, Some(h), &stage).unwrap();
        assert!(!b.copied);
        // Without a hash: staged under the source's own.
        let c = stage_file(&src, None, &stage).unwrap();
        assert_eq!(c.path, a.path);
        assert!(!c.copied);

        // The right name, the wrong bytes: replaced, never used.
        fs::remove_file(&a.path).unwrap();
        fs::write(&a.path, b"other bytes").unwrap();
        let r = stage_file(&src, Some(h), &stage).unwrap();
        assert!(r.copied && r.replaced_bad_copy);
        assert_eq!(fs::read(&r.path).unwrap(), b"baked bytes");
        // Only the staged file: no temporary left.
        assert_eq!(fs::read_dir(&stage).unwrap().count(), 1);
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_source_with_other_bytes_is_refused_and_leaves_nothing() {
        let d = scratch("refuse");
        let src = d.join("scene.psf");
        fs::write(&src, b"new bake").unwrap();
        let want = ContentHash::of(b"old bake");
        let stage = d.join("stage");
        let e = stage_file(&src, Some(want), &stage).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, FarmError::HashMismatch { .. }), "{msg}");
        assert!(msg.contains(&want.to_string()), "{msg}");
        assert!(
            msg.contains(&ContentHash::of(b"new bake").to_string()),
            "{msg}"
        );
        assert!(msg.contains("scene.psf"), "{msg}");
        assert_eq!(fs::read_dir(&stage).unwrap().count(), 0);
        assert!(verify_file("scene file", &src, want).is_err());
        verify_file("scene file", &src, ContentHash::of(b"new bake")).unwrap();
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn racing_stagers_on_one_node_agree() {
        let d = scratch("race");
        let src = d.join("big.psf");
        let bytes: Vec<u8> = (0..4_000_000u32).map(|i| (i % 251) as u8).collect();
        fs::write(&src, &bytes).unwrap();
        let h = ContentHash::of(&bytes);
        let stage = d.join("stage");
        let paths: Vec<PathBuf> = std::thread::scope(|s| {
            let hs: Vec<_> = (0..4)
                .map(|_| s.spawn(|| stage_file(&src, Some(h), &stage).unwrap().path))
                .collect();
            hs.into_iter().map(|t| t.join().unwrap()).collect()
        });
        assert!(paths.iter().all(|p| p == &paths[0]));
        assert_eq!(fs::read(&paths[0]).unwrap(), bytes);
        assert_eq!(fs::read_dir(&stage).unwrap().count(), 1);
        fs::remove_dir_all(&d).unwrap();
    }
}
