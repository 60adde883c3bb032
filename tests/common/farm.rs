//! What the farm tests share: running the binary, snapshots of an output folder, and
//! the rule for tools a test needs (a Slurm cluster, `openjd`): present, the test runs;
//! absent, it fails when `CI` is set (CI installs and starts them, `.ci/run`) and
//! otherwise prints `SKIPPED` with the reason.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn subfield(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args)
        .output()
        .unwrap()
}

pub fn ok(args: &[&str]) -> Output {
    ok_with(args, &[])
}

/// [`ok`] with environment variables set for the run.
pub fn ok_with(args: &[&str], env: &[(&str, &str)]) -> Output {
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "subfield {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The visible files of a folder (no hidden temporaries, no sub-folders) with their
/// bytes, sorted by name.
pub fn frames(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .filter(|e| e.path().is_file())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| !n.starts_with('.') && n.ends_with(".exr"))
                .map(|n| {
                    let b = std::fs::read(dir.join(&n)).unwrap();
                    (n, b)
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Hidden temporaries (`.*.tmp`) anywhere under `dir`.
pub fn temporaries(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            let n = e.file_name().to_string_lossy().into_owned();
            if p.is_dir() {
                stack.push(p);
            } else if n.starts_with('.') && n.ends_with(".tmp") {
                out.push(p);
            }
        }
    }
    out
}

/// Whether a tool the test needs is here; when it is not, fails under CI and prints a
/// skip line elsewhere (returns false: the caller returns).
pub fn need(test: &str, present: bool, what: &str) -> bool {
    if present {
        return true;
    }
    if std::env::var_os("CI").is_some() {
        panic!("{test}: {what} is missing, and CI must have it (.ci/run installs and starts it)");
    }
    eprintln!(
        "SKIPPED {test}: {what} is missing (CI installs it; run .ci/run or scripts/slurm-up.sh)"
    );
    false
}

pub fn on_path(tool: &str) -> bool {
    Command::new("sh")
        .arg("-c")
        .arg(format!("command -v {tool} >/dev/null 2>&1"))
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

/// Whether a Slurm cluster answers here (`sinfo` lists a node that is up).
pub fn slurm_up() -> bool {
    Command::new("sinfo")
        .args(["-h", "-o", "%T"])
        .output()
        .map(|o| {
            o.status.success()
                && String::from_utf8_lossy(&o.stdout).lines().any(|l| {
                    l.starts_with("idle") || l.starts_with("mix") || l.starts_with("alloc")
                })
        })
        .unwrap_or(false)
}
