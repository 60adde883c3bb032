//! Render farms: the bake shipped once by content hash and rendered by scheduler tasks.
//!
//! * [`stage`]: a task never maps the shared bake in place; it resolves it through a
//!   node-local cache, `<stage-dir>/<content hash>.psf`, copied there once per node,
//!   atomically, verified, then mapped (see [`stage_file`]).
//! * [`slurm`]: the job script of a Slurm job array (one task per shard), `sbatch`,
//!   and the queue as `squeue` shows it.
//! * [`openjd`]: the same work as an Open Job Description job template (frame chunks).
//!
//! Each task runs `subfield render --resume` on its share of the frames, so a task that
//! dies, is cancelled or requeued loses at most the frames in flight, and submitting the
//! same job again renders only what is missing. Temporaries carry the host's name
//! ([`crate::atomic`]), so nodes sharing an output folder never remove each other's.

pub mod openjd;
pub mod slurm;
pub mod stage;

use std::path::PathBuf;

pub use stage::{default_stage_dir, stage_file, verify_file, Staged};

use crate::format::ContentHash;

/// What can stop a farm operation. Every variant names the file or the program.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FarmError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file is not the one the job was submitted with.
    #[error("{what} {} has content hash {found}, but the job expects {expected}; it changed since the job was submitted: submit again", path.display())]
    HashMismatch {
        /// "baked file" or "scene file".
        what: &'static str,
        path: PathBuf,
        expected: ContentHash,
        found: ContentHash,
    },
    /// A scheduler program could not be started.
    #[error("cannot run {program}: {source} (is it installed and on the PATH?)")]
    Spawn {
        program: String,
        #[source]
        source: std::io::Error,
    },
    /// A scheduler program ran and failed.
    #[error("{program} failed ({status}): {message}")]
    Command {
        program: String,
        status: String,
        message: String,
    },
    /// A job that cannot be described (the message says why).
    #[error("{0}")]
    Invalid(String),
}

impl FarmError {
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> FarmError {
        FarmError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// `s` quoted for a POSIX shell: as it is when it is plainly safe, else in single
/// quotes (a single quote inside becomes `'\''`).
pub fn shell_quote(s: &str) -> String {
    let plain = !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-_./=:,+@%".contains(&b));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// The frames split into runs of consecutive numbers, as `A..B` spellings (B exclusive).
pub fn frame_runs(frames: &[u32]) -> Vec<(u32, u32)> {
    let mut runs: Vec<(u32, u32)> = Vec::new();
    for &f in frames {
        match runs.last_mut() {
            Some((_, end)) if *end == f => *end = f + 1,
            _ => runs.push((f, f + 1)),
        }
    }
    runs
}

/// The shard count `N` for a job of `tasks` array tasks over `frames` (task `i` renders
/// the frames `k` with `k % N == i`, DESIGN.md §4): `tasks` where that puts frames in
/// as many shards as it can (`tasks`, or one a frame when fewer); else the least `N`
/// up to 64 × `tasks` whose shards holding frames are exactly that many (every frame
/// even, `0..20:2`, filled one shard of two and none of the other: four shards fill
/// two, five frames each); `tasks` again when none does within [`SHARD_SEARCH`] frame
/// visits.
pub fn shard_count(frames: &[u32], tasks: u32) -> u32 {
    let tasks = tasks.max(1);
    let want = (frames.len() as u64).min(u64::from(tasks));
    let mut seen = Vec::new();
    let mut filled = |n: u32| -> u64 {
        seen.clear();
        seen.resize(n as usize, false);
        for &f in frames {
            seen[(f % n) as usize] = true;
        }
        seen.iter().filter(|&&b| b).count() as u64
    };
    if want == 0 || filled(tasks) == want {
        return tasks;
    }
    let tries = (SHARD_SEARCH / frames.len().max(1)) as u32;
    (tasks + 1..=tasks.saturating_mul(64).min(tasks.saturating_add(tries)))
        .find(|&n| filled(n) == want)
        .unwrap_or(tasks)
}

/// Frames [`shard_count`] visits at most in its search (a few tenths of a second).
pub const SHARD_SEARCH: usize = 100_000_000;

/// `frames` (ascending) cut into chunks of at most `k` consecutive frames each, as
/// `(A, B)` ranges; a gap always starts a new chunk.
pub fn frame_chunks(frames: &[u32], k: u32) -> Vec<(u32, u32)> {
    let k = k.max(1);
    let mut out = Vec::new();
    for (a, b) in frame_runs(frames) {
        let mut s = a;
        while s < b {
            let e = b.min(s.saturating_add(k));
            out.push((s, e));
            s = e;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_counts_spread_stepped_frames_over_the_tasks_asked() {
        let even: Vec<u32> = (0..20).step_by(2).collect();
        assert_eq!(shard_count(&even, 2), 4);
        let shards = |n: u32| {
            let mut s: Vec<u32> = even.iter().map(|f| f % n).collect();
            s.sort_unstable();
            s.dedup();
            s
        };
        assert_eq!(shards(4), [0, 2]);
        // Eight tasks over ten even frames: sixteen shards, eight of them holding frames.
        assert_eq!(shards(shard_count(&even, 8)).len(), 8);
        // Consecutive frames keep the count asked; fewer frames than tasks, one a frame.
        let run: Vec<u32> = (5..25).collect();
        assert_eq!(shard_count(&run, 3), 3);
        assert_eq!(shard_count(&[7, 9], 8), 8);
        assert_eq!(shard_count(&[], 4), 4);
        assert_eq!(shard_count(&[3], 0), 1);
    }

    #[test]
    fn quoting_survives_a_shell() {
        assert_eq!(shell_quote("out/frame.####.exr"), "'out/frame.####.exr'");
        assert_eq!(shell_quote("/a/b.glb"), "/a/b.glb");
        assert_eq!(shell_quote(""), "''");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
        for s in ["a b", "$HOME", "x'y\"z", "-278,273,1000", "`ls`", "a\nb"] {
            let out = std::process::Command::new("sh")
                .arg("-c")
                .arg(format!("printf %s {}", shell_quote(s)))
                .output()
                .unwrap();
            assert_eq!(String::from_utf8_lossy(&out.stdout), s, "{s:?}");
        }
    }

    #[test]
    fn runs_and_chunks() {
        assert_eq!(frame_runs(&[0, 1, 2, 5, 7, 8]), [(0, 3), (5, 6), (7, 9)]);
        assert!(frame_runs(&[]).is_empty());
        assert_eq!(
            frame_chunks(&[0, 1, 2, 3, 4, 9, 10], 2),
            [(0, 2), (2, 4), (4, 5), (9, 11)]
        );
        assert_eq!(frame_chunks(&[3], 0), [(3, 4)]);
    }
}
