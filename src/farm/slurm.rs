//! Slurm: the job script of a job array (one task per shard of the frames), `sbatch`,
//! and what `squeue` says of the job.
//!
//! The script is self-contained: absolute paths, the content hashes of the bake and the
//! scene file, the shard count, and a task body that stages the bake and renders its
//! shard with `--resume`. Running it again (or `subfield submit` again) renders only
//! what is missing; a task requeued by Slurm starts over and skips what it wrote.
//!
//! Requeueing follows the render's exit code (DESIGN.md §4): a task that ends with 5
//! (an I/O or resource failure: a full disk, out of memory, a GPU lost) requeues itself
//! with `scontrol requeue`, at most [`MAX_REQUEUES`] times, since it may succeed later
//! or on another node; 3 (bad input) and 4 (a file whose hash is not the job's) fail the
//! task for good, since a retry would fail the same way. Preemption and node failure are
//! Slurm's own requeues (`--requeue`); a task stopped by a signal it was sent
//! (`scancel`, the time limit: exit 143) is not requeued by the script.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use super::{shell_quote, FarmError};

/// A Slurm job array, ready to be written as a script.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlurmJob {
    /// `--job-name`.
    pub name: String,
    /// The shard count `N`: task `i` renders `--shard i/N`.
    pub shards: u32,
    /// The array indices to run (those shards with frames missing), ascending.
    pub array: Vec<u32>,
    pub partition: Option<String>,
    /// `--time`, in any spelling Slurm takes (`30`, `1:00:00`, `1-0`).
    pub time: Option<String>,
    pub cpus_per_task: Option<u32>,
    /// Where each task's log goes (`<log_dir>/<job>_<task>.log`).
    pub log_dir: PathBuf,
    /// The task's render command, without `--shard`, `--threads` and `--stage-dir`
    /// (the script adds them from the task's environment).
    pub command: Vec<String>,
    /// The node-local stage; `None`: `$SUBFIELD_STAGE_DIR`, else `$TMPDIR/subfield-stage`.
    pub stage_dir: Option<PathBuf>,
    /// GPUs per task (`--gres=gpu:N`); the command then renders with `--device gpu`.
    pub gpus_per_task: Option<u32>,
    /// sbatch's own options given after `--`, which the script names so that it can be
    /// submitted again as it was.
    pub sbatch_args: Vec<String>,
}

/// How many times a task requeues itself after an I/O or resource failure (exit 5).
pub const MAX_REQUEUES: u32 = 3;

/// `0-3,7,9-10`: Slurm's spelling of an index list.
pub fn array_spec(indices: &[u32]) -> String {
    super::frame_runs(indices)
        .iter()
        .map(|&(a, b)| {
            if b == a + 1 {
                a.to_string()
            } else {
                format!("{a}-{}", b - 1)
            }
        })
        .collect::<Vec<_>>()
        .join(",")
}

impl SlurmJob {
    /// The job script (bash, `#SBATCH` directives first).
    pub fn script(&self) -> String {
        let mut s = String::new();
        let q = |p: &Path| shell_quote(&p.to_string_lossy());
        let _ = writeln!(s, "#!/bin/bash");
        let _ = writeln!(
            s,
            "# Written by `subfield submit slurm` ({} {}): a job array, task i renders",
            env!("CARGO_PKG_NAME"),
            env!("CARGO_PKG_VERSION")
        );
        let _ = writeln!(
            s,
            "# shard i/{} of the frames with --resume, from the bake staged by content hash.",
            self.shards
        );
        if self.sbatch_args.is_empty() {
            let _ = writeln!(
                s,
                "# Submitting it again (sbatch FILE) renders only the frames still missing."
            );
        } else {
            let args: Vec<String> = self.sbatch_args.iter().map(|a| shell_quote(a)).collect();
            let _ = writeln!(
                s,
                "# Submitted with sbatch's options {}: submitting it again with them",
                args.join(" ")
            );
            let _ = writeln!(
                s,
                "# (sbatch {} FILE) renders only the frames still missing.",
                args.join(" ")
            );
        }
        let _ = writeln!(s, "#SBATCH --job-name={}", self.name);
        let _ = writeln!(s, "#SBATCH --array={}", array_spec(&self.array));
        let _ = writeln!(
            s,
            "#SBATCH --output={}",
            self.log_dir.join("%A_%a.log").display()
        );
        // A requeued task appends to its log rather than erasing it.
        let _ = writeln!(s, "#SBATCH --open-mode=append");
        let _ = writeln!(s, "#SBATCH --requeue");
        if let Some(p) = &self.partition {
            let _ = writeln!(s, "#SBATCH --partition={p}");
        }
        if let Some(t) = &self.time {
            let _ = writeln!(s, "#SBATCH --time={t}");
        }
        if let Some(c) = self.cpus_per_task {
            let _ = writeln!(s, "#SBATCH --cpus-per-task={c}");
        }
        if let Some(g) = self.gpus_per_task {
            let _ = writeln!(s, "#SBATCH --gres=gpu:{g}");
        }
        let _ = writeln!(s, "set -eu");
        match &self.stage_dir {
            Some(d) => {
                let _ = writeln!(s, "stage={}", q(d));
            }
            None => {
                let _ = writeln!(
                    s,
                    "stage=\"${{SUBFIELD_STAGE_DIR:-${{TMPDIR:-/tmp}}/subfield-stage}}\""
                );
            }
        }
        let _ = writeln!(
            s,
            "echo \"subfield: task ${{SLURM_ARRAY_TASK_ID}} of job ${{SLURM_ARRAY_JOB_ID}} on $(hostname), shard ${{SLURM_ARRAY_TASK_ID}}/{} (restart ${{SLURM_RESTART_COUNT:-0}})\"",
            self.shards
        );
        // Not `exec`: the script reads the render's exit code to decide on a requeue.
        let mut line = String::from("set +e\n");
        for (i, a) in self.command.iter().enumerate() {
            if i > 0 {
                line.push(' ');
            }
            line.push_str(&shell_quote(a));
        }
        let _ = writeln!(
            s,
            "{line} \\\n  --shard \"${{SLURM_ARRAY_TASK_ID}}/{}\" --threads \"${{SLURM_CPUS_PER_TASK:-1}}\" --stage-dir \"$stage\"",
            self.shards
        );
        let _ = writeln!(s, "rc=$?");
        let _ = writeln!(
            s,
            "if [ \"$rc\" -eq 5 ] && [ \"${{SLURM_RESTART_COUNT:-0}}\" -lt {MAX_REQUEUES} ]; then"
        );
        let _ = writeln!(
            s,
            "  echo \"subfield: exit 5 (I/O or resource failure): requeueing task ${{SLURM_ARRAY_TASK_ID}} (restart ${{SLURM_RESTART_COUNT:-0}} of {MAX_REQUEUES})\""
        );
        let _ = writeln!(s, "  scontrol requeue \"${{SLURM_JOB_ID}}\"");
        let _ = writeln!(s, "fi");
        let _ = writeln!(s, "exit \"$rc\"");
        s
    }
}

fn run(program: &str, args: &[String]) -> Result<String, FarmError> {
    let out = Command::new(program)
        .args(args)
        .output()
        .map_err(|source| FarmError::Spawn {
            program: program.to_string(),
            source,
        })?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let msg = err
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect::<Vec<_>>()
            .join("; ");
        return Err(FarmError::Command {
            program: program.to_string(),
            status: out.status.to_string(),
            message: if msg.is_empty() {
                "no message".into()
            } else {
                msg
            },
        });
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Whether a program can be found on the `PATH` (or is a path that exists).
pub fn on_path(program: &str) -> bool {
    if program.contains('/') {
        return Path::new(program).is_file();
    }
    std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).any(|d| d.join(program).is_file()))
        .unwrap_or(false)
}

/// Checks that a partition exists (`sinfo`), so a typo is one line before anything is
/// submitted.
pub fn check_partition(partition: &str) -> Result<(), FarmError> {
    let out = run("sinfo", &["-h".into(), "-o".into(), "%R".into()])?;
    let known: Vec<&str> = out
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    if known.contains(&partition) {
        Ok(())
    } else {
        Err(FarmError::Invalid(format!(
            "--partition {partition:?}: no such partition on this cluster; it has {}",
            if known.is_empty() {
                "none".to_string()
            } else {
                known.join(", ")
            }
        )))
    }
}

/// Submits a script with `sbatch --parsable [extra...] SCRIPT` and returns the job id.
pub fn sbatch(script: &Path, extra: &[String]) -> Result<String, FarmError> {
    let mut args = vec!["--parsable".to_string()];
    args.extend(extra.iter().cloned());
    args.push(script.to_string_lossy().into_owned());
    let out = run("sbatch", &args)?;
    // `--parsable` prints `jobid` or `jobid;cluster`.
    let id = out
        .trim()
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_string();
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return Err(FarmError::Command {
            program: "sbatch".into(),
            status: "exit status 0".into(),
            message: format!("printed {:?}, not a job id", out.trim()),
        });
    }
    Ok(id)
}

/// A task of the job that the queue still holds: its id (`123_4`) and state
/// (`PENDING`, `RUNNING`, ...).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QueuedTask {
    pub id: String,
    pub state: String,
}

/// The job's tasks still in the queue (pending, running, requeued, completing); empty
/// when the whole job has left it.
pub fn queued_tasks(job: &str) -> Result<Vec<QueuedTask>, FarmError> {
    let args = [
        "-h".to_string(),
        "-r".into(),
        "-j".into(),
        job.to_string(),
        "-o".into(),
        "%i %T".into(),
    ];
    match run("squeue", &args) {
        Ok(out) => Ok(parse_queue(&out)),
        // A job that finished long enough ago is unknown to squeue.
        Err(FarmError::Command { message, .. }) if message.contains("Invalid job id") => {
            Ok(Vec::new())
        }
        Err(e) => Err(e),
    }
}

fn parse_queue(out: &str) -> Vec<QueuedTask> {
    out.lines()
        .filter_map(|l| {
            let mut it = l.split_whitespace();
            Some(QueuedTask {
                id: it.next()?.to_string(),
                state: it.next()?.to_string(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_specs() {
        assert_eq!(array_spec(&[0, 1, 2, 3]), "0-3");
        assert_eq!(array_spec(&[1, 3, 4, 7]), "1,3-4,7");
        assert_eq!(array_spec(&[5]), "5");
    }

    #[test]
    fn queue_lines() {
        let q = parse_queue("12_0 RUNNING\n12_[1-3] PENDING\n\n");
        assert_eq!(q.len(), 2);
        assert_eq!(q[1].state, "PENDING");
    }

    #[test]
    fn script_is_valid_bash_with_the_directives_first() {
        let job = SlurmJob {
            name: "subfield-frame".into(),
            shards: 4,
            array: vec![0, 2, 3],
            partition: Some("debug".into()),
            time: Some("10:00".into()),
            cpus_per_task: Some(2),
            log_dir: "/farm/out/frame.logs".into(),
            command: vec![
                "/opt/subfield".into(),
                "render".into(),
                "/farm/my scene.glb".into(),
                "-o".into(),
                "/farm/out/frame.####.exr".into(),
            ],
            stage_dir: None,
            gpus_per_task: Some(2),
            sbatch_args: vec!["--mem=4G".into(), "--qos".into(), "low prio".into()],
        };
        let s = job.script();
        assert!(
            s.contains("# (sbatch --mem=4G --qos 'low prio' FILE) renders only"),
            "{s}"
        );
        assert!(s.contains("#SBATCH --gres=gpu:2\n"), "{s}");
        assert!(s.starts_with("#!/bin/bash\n"));
        assert!(s.contains("#SBATCH --array=0,2-3\n"), "{s}");
        assert!(s.contains("#SBATCH --cpus-per-task=2\n"));
        assert!(s.contains("#SBATCH --output=/farm/out/frame.logs/%A_%a.log\n"));
        assert!(s.contains("'/farm/my scene.glb'"));
        assert!(s.contains("--shard \"${SLURM_ARRAY_TASK_ID}/4\""));
        // sbatch reads directives only before the first command.
        let first_cmd = s.lines().position(|l| !l.starts_with('#')).unwrap();
        assert!(s.lines().skip(first_cmd).all(|l| !l.starts_with("#SBATCH")));
        let check = Command::new("bash")
            .arg("-n")
            .arg("-c")
            .arg(&s)
            .status()
            .unwrap();
        assert!(check.success());
    }

    /// The script requeues its task after exit 5 only, and at most MAX_REQUEUES times;
    /// run here with a stand-in render (`sh -c 'exit N'`) and a stand-in `scontrol`
    /// that records its arguments.
    #[test]
    fn only_a_resource_failure_requeues_the_task() {
        let dir = std::env::temp_dir().join(format!("subfield-requeue-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("scontrol.log");
        let fake = dir.join("scontrol");
        std::fs::write(
            &fake,
            format!("#!/bin/sh\necho \"$@\" >> {}\n", log.display()),
        )
        .unwrap();
        std::process::Command::new("chmod")
            .args(["+x", &fake.to_string_lossy()])
            .status()
            .unwrap();
        let path = format!(
            "{}:{}",
            dir.display(),
            std::env::var("PATH").unwrap_or_default()
        );
        for (code, restarts, requeued) in [
            (0, 0, false),
            (3, 0, false),
            (4, 0, false),
            (143, 0, false),
            (5, 0, true),
            (5, MAX_REQUEUES - 1, true),
            (5, MAX_REQUEUES, false),
        ] {
            let _ = std::fs::remove_file(&log);
            let job = SlurmJob {
                name: "t".into(),
                shards: 2,
                array: vec![0, 1],
                partition: None,
                time: None,
                cpus_per_task: None,
                log_dir: dir.clone(),
                command: vec!["sh".into(), "-c".into(), format!("exit {code}")],
                stage_dir: Some(dir.join("stage")),
                gpus_per_task: None,
                sbatch_args: Vec::new(),
            };
            let out = Command::new("bash")
                .arg("-c")
                .arg(job.script())
                .env("PATH", &path)
                .env("SLURM_JOB_ID", "77")
                .env("SLURM_ARRAY_JOB_ID", "70")
                .env("SLURM_ARRAY_TASK_ID", "1")
                .env("SLURM_RESTART_COUNT", restarts.to_string())
                .output()
                .unwrap();
            assert_eq!(out.status.code(), Some(code), "exit {code}");
            let said = std::fs::read_to_string(&log).unwrap_or_default();
            assert_eq!(
                said == "requeue 77\n",
                requeued,
                "exit {code}, restart {restarts}: scontrol got {said:?}"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
