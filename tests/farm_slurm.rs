//! `subfield submit slurm` on a real one-node Slurm cluster (Debian's slurm-wlm, started
//! by `scripts/slurm-up.sh`, which `.ci/run` calls): an array's frames equal one local
//! render's; cancelled, killed and requeued tasks lose nothing and a second submit
//! renders exactly what is missing; a bake changed after submission is refused in the
//! task's log and `--wait` names it. Without a cluster these fail under CI and are
//! skipped (with a printed line) elsewhere.

mod common;

use std::collections::BTreeMap;
use std::io::BufRead;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use common::farm::{frames, need, ok, s, slurm_up, stderr, subfield, temporaries};
use common::render_scene::{temp_dir, write_scene};

/// The cluster runs one job at a time for these tests (it has two CPUs).
static CLUSTER: Mutex<()> = Mutex::new(());

fn cluster(test: &str) -> Option<MutexGuard<'static, ()>> {
    if !need(
        test,
        slurm_up(),
        "a running Slurm cluster (scripts/slurm-up.sh)",
    ) {
        return None;
    }
    Some(CLUSTER.lock().unwrap_or_else(|p| p.into_inner()))
}

struct Setup {
    dir: PathBuf,
    scene: PathBuf,
    psf: PathBuf,
}

fn setup(name: &str) -> Setup {
    let dir = temp_dir(name);
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    ok(&["bake", s(&scene), "-o", s(&psf), "--quiet"]);
    Setup { dir, scene, psf }
}

/// The render options every run of a test shares (the farm's and the local one's).
fn look(size: &str, spp: &str) -> Vec<String> {
    ["--frames", "0..24", "--size", size, "--spp", spp]
        .iter()
        .map(|x| x.to_string())
        .collect()
}

fn local(st: &Setup, opts: &[String]) -> Vec<(String, Vec<u8>)> {
    let out = st.dir.join("local/f.##.exr");
    let mut args = vec![
        "render",
        s(&st.scene),
        "--baked",
        s(&st.psf),
        "-o",
        s(&out),
        "--quiet",
    ];
    args.extend(opts.iter().map(|x| x.as_str()));
    ok(&args);
    frames(&st.dir.join("local"))
}

fn submit_args<'a>(st: &'a Setup, opts: &'a [String], extra: &[&'a str]) -> Vec<&'a str> {
    let out = Box::leak(Box::new(st.dir.join("farm/f.##.exr")));
    let stage = Box::leak(Box::new(st.dir.join("stage")));
    let mut a = vec![
        "submit",
        "slurm",
        s(&st.scene),
        "--baked",
        s(&st.psf),
        "-o",
        s(out),
        "--stage-dir",
        s(stage),
        "--cpus-per-task",
        "1",
    ];
    a.extend(opts.iter().map(|x| x.as_str()));
    a.extend_from_slice(extra);
    a
}

fn job_id(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).trim().to_string()
}

fn squeue(job: &str) -> Vec<(String, String)> {
    let o = Command::new("squeue")
        .args(["-h", "-r", "-j", job, "-o", "%i %T"])
        .output()
        .unwrap();
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect()
}

fn wait_until(what: &str, limit_s: u64, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(
            t0.elapsed().as_secs() < limit_s,
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn wait_job_gone(job: &str) {
    wait_until(&format!("job {job} to leave the queue"), 300, || {
        squeue(job).is_empty()
    });
}

fn running(job: &str, task: u32) -> bool {
    squeue(job)
        .iter()
        .any(|(id, st)| id == &format!("{job}_{task}") && st == "RUNNING")
}

/// Frames written so far of shard `i` of `n` (frames k with k % n == i).
fn shard_written(dir: &Path, i: u32, n: u32) -> usize {
    (0..24u32)
        .filter(|k| k % n == i)
        .filter(|k| dir.join(format!("farm/f.{k:02}.exr")).is_file())
        .count()
}

fn inodes(dir: &Path) -> BTreeMap<String, u64> {
    frames(dir)
        .into_iter()
        .map(|(n, _)| {
            let ino = std::fs::metadata(dir.join(&n)).unwrap().ino();
            (n, ino)
        })
        .collect()
}

#[test]
fn a_four_task_array_gives_the_frames_of_one_local_render() {
    let Some(_c) = cluster("a_four_task_array_gives_the_frames_of_one_local_render") else {
        return;
    };
    let st = setup("slurm-array");
    let opts = look("48x36", "1");
    let want = local(&st, &opts);
    assert_eq!(want.len(), 24);
    let o = subfield(&submit_args(&st, &opts, &["--tasks", "4", "--wait"]));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(frames(&st.dir.join("farm")), want);
    assert!(st.dir.join("farm/f.slurm.sh").is_file());
    assert!(temporaries(&st.dir.join("farm")).is_empty());
    // The bake was staged once under its hash.
    let hash = subfield::format::hash_file(&st.psf).unwrap();
    assert!(st.dir.join(format!("stage/{hash}.psf")).is_file());
    // Everything is there: the same command submits nothing.
    let again = ok(&submit_args(&st, &opts, &["--tasks", "4", "--wait"]));
    assert!(
        stderr(&again).contains("nothing to submit"),
        "{}",
        stderr(&again)
    );
    assert!(again.stdout.is_empty());
}

#[test]
fn a_cancelled_and_a_killed_task_are_rendered_again_and_only_their_frames() {
    let Some(_c) =
        cluster("a_cancelled_and_a_killed_task_are_rendered_again_and_only_their_frames")
    else {
        return;
    };
    let st = setup("slurm-faults");
    // Slow enough frames that a task is caught mid-shard.
    let opts = look("200x150", "4");
    let args = submit_args(&st, &opts, &["--tasks", "4"]);
    let first = ok(&args);
    let job = job_id(&first);
    // Tasks 0 and 1 run first (two CPUs); 2 and 3 when they end.
    wait_until("task 2 to write a frame", 240, || {
        running(&job, 2) && shard_written(&st.dir, 2, 4) >= 1
    });
    let status = Command::new("scancel")
        .arg(format!("{job}_2"))
        .status()
        .unwrap();
    assert!(status.success());
    wait_until("task 3 to write a frame", 240, || {
        running(&job, 3) && shard_written(&st.dir, 3, 4) >= 1 || squeue(&job).is_empty()
    });
    // kill -9 the render of task 3 (its command line names its shard and this folder).
    let pattern = format!("{}.*--shard 3/4", st.dir.join("farm").display());
    let _ = Command::new("pkill").args(["-9", "-f", &pattern]).status();
    wait_job_gone(&job);
    // The cancelled task's render finishes its frame in flight on SIGTERM; the job can
    // leave the queue a moment before that render has written it and exited (seen once
    // in CI: a frame more on disk than counted here). Count once no render of this
    // folder runs.
    let renders = format!("{}.*--shard", st.dir.join("farm").display());
    wait_until("the job's renders to exit", 120, || {
        !Command::new("pgrep")
            .args(["-f", &renders])
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false)
    });

    let before = inodes(&st.dir.join("farm"));
    let missing = 24 - before.len();
    assert!(
        missing > 0,
        "every frame was written before the faults: make the frames slower"
    );
    let second = ok(&[args.as_slice(), &["--wait"]].concat());
    let e = stderr(&second);
    assert!(
        e.contains(&format!(
            "for {} of 24",
            subfield::plural(missing as u64, "missing frame")
        )),
        "{e}"
    );
    // The frames of the first job were kept, not written again.
    let after = inodes(&st.dir.join("farm"));
    for (name, ino) in &before {
        assert_eq!(after.get(name), Some(ino), "{name} was rendered again");
    }
    assert_eq!(after.len(), 24);
    assert_eq!(frames(&st.dir.join("farm")), local(&st, &opts));
    assert!(
        temporaries(&st.dir.join("farm")).is_empty(),
        "{:?}",
        temporaries(&st.dir)
    );
}

#[test]
fn a_task_requeued_by_slurm_resumes_and_loses_nothing() {
    let Some(_c) = cluster("a_task_requeued_by_slurm_resumes_and_loses_nothing") else {
        return;
    };
    let st = setup("slurm-requeue");
    let opts = look("200x150", "4");
    let first = ok(&submit_args(&st, &opts, &["--tasks", "2"]));
    let job = job_id(&first);
    wait_until("task 1 to write two frames", 240, || {
        running(&job, 1) && shard_written(&st.dir, 1, 2) >= 2
    });
    let kept = inodes(&st.dir.join("farm"));
    let o = Command::new("scontrol")
        .args(["requeue", &format!("{job}_1")])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The requeued task waits two minutes or so for its begin time: moved to three
    // seconds ahead, once (see the resource-failure test for why not to now).
    let mut moved = false;
    wait_until(&format!("job {job} to leave the queue"), 300, || {
        let q = squeue(&job);
        if !moved
            && q.iter()
                .any(|(id, st)| id == &format!("{job}_1") && st == "PENDING")
        {
            let _ = Command::new("scontrol")
                .args(["update", &format!("JobId={job}_1"), "StartTime=now+3"])
                .output();
            moved = true;
        }
        q.is_empty()
    });
    let after = inodes(&st.dir.join("farm"));
    assert_eq!(after.len(), 24, "frames lost after the requeue");
    for (name, ino) in &kept {
        assert_eq!(after.get(name), Some(ino), "{name} was rendered again");
    }
    assert_eq!(frames(&st.dir.join("farm")), local(&st, &opts));
    assert!(temporaries(&st.dir.join("farm")).is_empty());
    let log = std::fs::read_to_string(st.dir.join(format!("farm/f.logs/{job}_1.log"))).unwrap();
    assert!(log.contains("(restart 1)"), "{log}");
}

#[test]
fn a_bake_changed_after_submission_is_refused_and_wait_names_it() {
    let Some(_c) = cluster("a_bake_changed_after_submission_is_refused_and_wait_names_it") else {
        return;
    };
    let st = setup("slurm-stale");
    let opts = look("48x36", "1");
    let submitted = subfield::format::hash_file(&st.psf).unwrap().to_string();
    // Held in the queue until the bake has been replaced.
    let mut args = submit_args(&st, &opts, &["--tasks", "2", "--wait", "--"]);
    args.push("--hold");
    let mut child = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(&args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let job = line.trim().to_string();
    assert!(!job.is_empty(), "no job id printed");
    // Another bake of the scene (other tiles: other bytes), renamed over the old one.
    let other = st.dir.join("other.psf");
    ok(&[
        "bake",
        s(&st.scene),
        "-o",
        s(&other),
        "--tiles",
        "8",
        "--quiet",
    ]);
    std::fs::rename(&other, &st.psf).unwrap();
    let found = subfield::format::hash_file(&st.psf).unwrap().to_string();
    assert_ne!(found, submitted);
    assert!(Command::new("scontrol")
        .args(["release", &job])
        .status()
        .unwrap()
        .success());
    let o = child.wait_with_output().unwrap();
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    assert!(e.contains(&found) && e.contains(&submitted), "{e}");
    assert!(e.contains("24 of 24 frames missing"), "{e}");
    assert!(frames(&st.dir.join("farm")).is_empty());
    // Exit 4 (a bake whose hash is not the job's) fails a task for good: each task ran
    // once, and its script did not requeue it (it requeues on 5 alone).
    for task in 0..2 {
        let log = st.dir.join(format!("farm/f.logs/{job}_{task}.log"));
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        assert_eq!(text.matches("subfield: task ").count(), 1, "{text}");
        assert!(!text.contains("requeueing"), "{text}");
    }
}

/// Exit 5 (an I/O or resource failure) requeues the task, at most three times. Slurm
/// propagates the submitting shell's file-size limit (`ulimit -f`, PropagateResourceLimits)
/// to the task, where staging the 7 KiB bake fails with `File too large` every time: the
/// task runs four times (the first try and three requeues) and then fails for good.
/// Slurm holds a requeued job back for two minutes or so (its begin time); the test
/// moves that to three seconds ahead, once per failed try, which changes nothing the
/// script decides. Not to now, and not again while the job waits: a launch within a
/// moment of the requeue finds the killed try's credential still revoked, slurmd
/// refuses it ("Job 343 already killed, do not launch batch job") and Slurm ends the
/// job with exit 1 and no further requeue (seen once in CI).
#[test]
fn a_resource_failure_requeues_the_task_three_times_then_fails() {
    let Some(_c) = cluster("a_resource_failure_requeues_the_task_three_times_then_fails") else {
        return;
    };
    let st = setup("slurm-resource");
    let opts = look("48x36", "1");
    let o = Command::new("bash")
        .arg("-c")
        .arg("ulimit -f 4 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_subfield"))
        .args(submit_args(&st, &opts, &["--tasks", "1"]))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let job = job_id(&o);
    let log_path = st.dir.join(format!("farm/f.logs/{job}_0.log"));
    let tries = || {
        std::fs::read_to_string(&log_path)
            .unwrap_or_default()
            .matches("File too large")
            .count()
    };
    // The queue can be empty for a moment while a task is requeued: wait for the fourth
    // try's failure and an empty queue, then a little more for any further requeue.
    // Up to 300 s, as `wait_job_gone`: on 2 cores beside the other Slurm tests' jobs a
    // requeued try can wait that long for the node (120 s timed out once in CI).
    let mut moved_after = 0;
    wait_until(&format!("job {job} to fail four times"), 300, || {
        let q = squeue(&job);
        let failed = tries();
        if failed > moved_after && q.iter().any(|(_, state)| state == "PENDING") {
            let _ = Command::new("scontrol")
                .args(["update", &format!("JobId={job}"), "StartTime=now+3"])
                .output();
            moved_after = failed;
        }
        failed >= 4 && q.is_empty()
    });
    std::thread::sleep(Duration::from_secs(2));
    assert!(squeue(&job).is_empty(), "requeued after the third restart");
    let log = std::fs::read_to_string(&log_path).unwrap();
    assert_eq!(log.matches("subfield: task ").count(), 4, "{log}");
    assert_eq!(log.matches("requeueing").count(), 3, "{log}");
    assert_eq!(log.matches("File too large").count(), 4, "{log}");
    assert!(log.contains("(restart 3)"), "{log}");
    assert!(frames(&st.dir.join("farm")).is_empty());
}

#[test]
fn an_unknown_partition_is_one_line_and_nothing_is_submitted() {
    let Some(_c) = cluster("an_unknown_partition_is_one_line_and_nothing_is_submitted") else {
        return;
    };
    let st = setup("slurm-partition");
    let opts = look("48x36", "1");
    let o = subfield(&submit_args(&st, &opts, &["--partition", "nosuch"]));
    let e = stderr(&o);
    assert!(!o.status.success());
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(e.contains("nosuch") && e.contains("debug"), "{e}");
    assert!(!st.dir.join("farm").exists());
}
