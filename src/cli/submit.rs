//! `subfield submit slurm|openjd SCENE [--baked FILE.psf] -o PATTERN [render options]
//! ...`: the render as farm work (DESIGN.md §4). The scene is planned here exactly as
//! `render` plans it; the frames whose files are already complete are left out; the bake
//! (made here when none is given) and the scene file are named by content hash; each
//! task renders its share with `--resume` from the bake staged on its node.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use subfield::farm::{
    self,
    openjd::{JobBundle, OpenJdJob},
    slurm::SlurmJob,
};
use subfield::format::{self, ContentHash, WriteOptions};
use subfield::render::{self, FrameSet, FrameSpan, RenderOptions, RenderPlan};

use subfield::plural;

use super::progress::Progress;
use super::render as render_cmd;

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub engine: Engine,
}

#[derive(clap::Subcommand, Debug)]
pub enum Engine {
    /// Submit a Slurm job array (one task per shard) with sbatch and print its job id.
    #[command(allow_negative_numbers = true)]
    Slurm(Box<SlurmArgs>),
    /// Write an Open Job Description job template (one task per chunk of frames).
    #[command(allow_negative_numbers = true)]
    Openjd(Box<OpenJdArgs>),
}

#[derive(clap::Args, Debug)]
pub struct SlurmArgs {
    #[command(flatten)]
    pub render: render_cmd::Args,
    /// Array tasks, one shard of the frames each (default: the frame count, at most 8).
    #[arg(long)]
    pub tasks: Option<u32>,
    /// Slurm partition (checked with sinfo before anything is submitted).
    #[arg(long)]
    pub partition: Option<String>,
    /// Time limit per task, as Slurm spells it (30, 1:00:00, 1-0).
    #[arg(long)]
    pub time: Option<String>,
    /// CPUs per task; each task renders with that many threads.
    #[arg(long)]
    pub cpus_per_task: Option<u32>,
    /// GPUs per task (`--gres=gpu:N`); tasks then render with --device gpu.
    #[arg(long, value_name = "N")]
    pub gpus_per_task: Option<u32>,
    /// Follow the job with a progress bar over the frames written; fail listing the
    /// frames still missing if any task failed.
    #[arg(long)]
    pub wait: bool,
    /// Print the job script instead of writing and submitting it.
    #[arg(long)]
    pub dry_run: bool,
    /// Extra sbatch arguments, after `--`.
    #[arg(last = true, value_name = "SBATCH ARGS")]
    pub sbatch_args: Vec<String>,
}

#[derive(clap::Args, Debug)]
pub struct OpenJdArgs {
    #[command(flatten)]
    pub render: render_cmd::Args,
    /// The job template to write (.yaml).
    #[arg(long, value_name = "JOB.yaml", required_unless_present = "bundle")]
    pub template: Option<PathBuf>,
    /// Frames per task (default 8); with --bundle, the chunk size until the scheduler
    /// has timed a chunk (defaultTaskCount), unless --frame-seconds sets it.
    #[arg(long, default_value_t = 8)]
    pub chunk: u32,
    /// Write a Deadline Cloud job bundle into DIR (template.yaml, parameter_values.yaml,
    /// asset_references.yaml; `deadline bundle submit DIR`): the scene, the bake and the
    /// output folder as PATH job parameters, frames chunked by the TASK_CHUNKING
    /// extension.
    #[arg(long, value_name = "DIR")]
    pub bundle: Option<PathBuf>,
    /// With --bundle: the run time a chunk should take (targetRuntimeSeconds), seconds.
    #[arg(long, value_name = "S", requires = "bundle")]
    pub chunk_seconds: Option<u32>,
    /// With --bundle: seconds a frame takes (measured from an earlier render's
    /// --stats or --log-format json); the first chunks are then --chunk-seconds long
    /// (default 600 s).
    #[arg(long, value_name = "S", requires = "bundle")]
    pub frame_seconds: Option<f64>,
    /// With --bundle: render the first missing frame here, into the output, and take its
    /// time (update, trace, shade, write) as --frame-seconds; the frame is then done.
    /// It is this machine's time, not a farm worker's.
    #[arg(long, requires = "bundle", conflicts_with = "frame_seconds")]
    pub measure: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    match a.engine {
        Engine::Slurm(s) => slurm(*s),
        Engine::Openjd(o) => openjd(*o),
    }
}

/// What both engines share: the plan, the frames still missing, the bake and the
/// command every task runs.
struct Work {
    /// The render's options as the tasks will see them (absolute output).
    opts: RenderOptions,
    plan: RenderPlan,
    missing: Vec<u32>,
    /// The task's `subfield render ...` without the per-engine flags.
    command: Vec<String>,
    /// Its parts, for a job bundle whose parameters give the paths: the binary, the
    /// scene, the bake, and the flags after the output (hashes, `--resume`, the look).
    exe: String,
    scene: PathBuf,
    baked: PathBuf,
    flags: Vec<String>,
    /// The scene as imported (to render a frame for `--measure`).
    scene_model: subfield::scene::Scene,
    /// Where job files go: the output pattern's folder, and the name they share.
    dir: PathBuf,
    base: String,
}

fn absolute(p: &Path) -> anyhow::Result<PathBuf> {
    std::path::absolute(p).with_context(|| format!("cannot make {} absolute", p.display()))
}

/// Flags `submit` sets itself or that make no sense per task.
fn refuse_task_flags(r: &render_cmd::Args) -> anyhow::Result<()> {
    let taken = [
        (
            r.shard.is_some(),
            "--shard (submit shards the frames itself)",
        ),
        (
            r.threads.is_some(),
            "--threads (tasks use their CPUs: --cpus-per-task)",
        ),
        (r.resume, "--resume (tasks always resume)"),
        (r.stats.is_some(), "--stats (one file per run)"),
        (r.plot.is_some(), "--plot (one file per run)"),
        (r.preview.is_some(), "--preview (one file per run)"),
        (
            r.baked_hash.is_some(),
            "--baked-hash (submit hashes the bake)",
        ),
        (
            r.scene_file_hash.is_some(),
            "--scene-file-hash (submit hashes the scene)",
        ),
        (
            r.log_format != super::report::LogFormat::Text,
            "--log-format (tasks log as text)",
        ),
        (
            r.progress.is_some(),
            "--progress (a task under Open Job Description prints openjd lines by itself)",
        ),
    ];
    if let Some((_, what)) = taken.iter().find(|(given, _)| *given) {
        bail!("submit does not take {what}");
    }
    Ok(())
}

/// The render flags a task repeats, each as one `--flag=value` word (so a value such
/// as `-278,273,1000` is never read as a flag).
fn render_flags(r: &render_cmd::Args) -> Vec<String> {
    let mut v = Vec::new();
    let mut opt = |flag: &str, val: Option<String>| {
        if let Some(x) = val {
            v.push(format!("--{flag}={x}"));
        }
    };
    opt("fps", r.fps.map(|f| f.to_string()));
    opt("animation", r.animation.clone());
    opt("size", r.size.clone());
    opt(
        "exposure",
        (r.exposure != 0.0).then(|| r.exposure.to_string()),
    );
    opt("spp", Some(r.spp.to_string()));
    opt("max-depth", Some(r.max_depth.to_string()));
    opt("camera", r.camera.clone());
    opt("look-from", r.look_from.clone());
    opt("look-at", r.look_at.clone());
    opt("up", r.up.clone());
    opt("yfov", r.yfov.map(|f| f.to_string()));
    opt("aov", r.aov.clone());
    opt("crypto-levels", r.crypto_levels.map(|n| n.to_string()));
    opt(
        "compression",
        (r.compression != subfield::render::ExrCompression::Zip)
            .then(|| r.compression.name().to_string()),
    );
    opt("overscan", (r.overscan > 0).then(|| r.overscan.to_string()));
    opt("shutter", r.shutter.map(|x| x.to_string()));
    opt("motion-steps", r.motion_steps.map(|k| k.to_string()));
    opt(
        "frames-in-flight",
        r.frames_in_flight.map(|n| n.to_string()),
    );
    if r.float {
        v.push("--float".into());
    }
    // The device is part of the job: a resubmitted job never mixes CPU and GPU frames.
    if r.device != subfield::render::TraceDevice::Cpu {
        v.push(format!("--device={}", r.device.name()));
    }
    v
}

/// The job files' shared name: the pattern's file name up to its `#` run, trimmed of
/// separators (`frame.####.exr` → `frame`), else `subfield`.
fn base_name(pattern: &Path) -> String {
    let name = pattern
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let head = name.split('#').next().unwrap_or("");
    let head = head.strip_suffix(".exr").unwrap_or(head);
    let trimmed = head.trim_end_matches(['.', '_', '-', ' ']);
    let clean: String = trimmed
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if clean.is_empty() {
        "subfield".into()
    } else {
        clean
    }
}

fn complete(plan: &RenderPlan, opts: &RenderOptions, frame: u32) -> bool {
    render::is_complete(
        &plan.pattern.path(frame),
        opts.width + 2 * opts.overscan,
        opts.height + 2 * opts.overscan,
        opts.aovs,
        opts.pixel_type,
        &opts.options_string(plan.fps, plan.ambient, plan.default_light),
    )
}

/// Plans the work: checks every flag and input (and that the files it writes, the bake
/// and with `slurm_script` the job script, are not in the way of something that is not a
/// regular file), makes the bake when none is given (unless `dry_run`: then it is made in
/// memory, for its hash), and hashes both files.
fn prepare(r: &render_cmd::Args, dry_run: bool, slurm_script: bool) -> anyhow::Result<Work> {
    refuse_task_flags(r)?;
    if r.stage_dir.as_ref().is_some_and(|d| d.is_relative()) {
        bail!(
            "--stage-dir must be an absolute path: tasks run on other machines, in other folders"
        );
    }
    let mut opts = render_cmd::options(r)?;
    opts.output = absolute(&r.output)?;
    let scene_path = absolute(&r.scene)?;
    if let Some(b) = &r.baked {
        if !b.is_file() {
            bail!("{}: no such baked file", b.display());
        }
    }
    let scene = super::load_scene(&scene_path)?;
    render_cmd::size_from_scene(r, &scene, &mut opts);
    let plan = render::plan(&scene, &opts)
        .with_context(|| format!("cannot render {}", r.scene.display()))?;
    if !r.quiet {
        for w in &plan.warnings {
            eprintln!("warning: {w}");
        }
    }
    let missing: Vec<u32> = plan
        .frames
        .iter()
        .filter(|&f| !complete(&plan, &opts, f))
        .collect();
    let first = plan.pattern.path(plan.range.start);
    let dir = subfield::atomic::folder_of(&first);
    let base = base_name(&opts.output);
    // The files this command writes, refused before any work when something other than
    // a regular file is there (the frames are the tasks' to check).
    if r.baked.is_none() {
        super::check_target("-o", &dir.join(format!("{base}.psf")))?;
    }
    if slurm_script {
        super::check_target("-o", &dir.join(format!("{base}.slurm.sh")))?;
    }

    let (baked, baked_hash) = match &r.baked {
        Some(b) => {
            let b = absolute(b)?;
            let h = format::hash_file(&b).with_context(|| b.display().to_string())?;
            (b, h)
        }
        None => {
            let out = dir.join(format!("{base}.psf"));
            let (psf, secs) = super::bake::bake_static(&scene, &r.scene, None, None, r.quiet)?;
            let hash = if dry_run {
                ContentHash::of(&format::to_bytes(&psf, &WriteOptions::default())?)
            } else {
                std::fs::create_dir_all(&dir)
                    .with_context(|| format!("cannot create {}", dir.display()))?;
                format::write_psf(&out, &psf, &WriteOptions::default())?.content_hash
            };
            if !r.quiet {
                eprintln!(
                    "baked the static part in {secs:.2} s{} {} (content hash {hash})",
                    if dry_run { ", would write" } else { " to" },
                    out.display()
                );
            }
            (out, hash)
        }
    };
    let scene_hash =
        format::hash_file(&scene_path).with_context(|| scene_path.display().to_string())?;

    let exe = std::env::current_exe().context("cannot tell where this subfield binary is")?;
    let exe = exe.to_string_lossy().into_owned();
    let mut flags = vec![
        format!("--baked-hash={baked_hash}"),
        format!("--scene-file-hash={scene_hash}"),
        "--resume".into(),
    ];
    flags.extend(render_flags(r));
    let mut command = vec![
        exe.clone(),
        "render".into(),
        scene_path.to_string_lossy().into_owned(),
        format!("--baked={}", baked.display()),
        format!("--output={}", opts.output.display()),
    ];
    command.extend(flags.iter().cloned());
    Ok(Work {
        opts,
        plan,
        missing,
        command,
        exe,
        scene: scene_path,
        baked,
        flags,
        scene_model: scene,
        dir,
        base,
    })
}

fn nothing_missing(w: &Work, quiet: bool) -> bool {
    if w.missing.is_empty() {
        if !quiet {
            eprintln!(
                "{} complete in {}; nothing to submit",
                match w.plan.frames.len() {
                    1 => "the frame is".to_string(),
                    n => format!("all {n} frames are"),
                },
                w.dir.display()
            );
        }
        return true;
    }
    false
}

fn slurm(a: SlurmArgs) -> anyhow::Result<ExitCode> {
    let r = &a.render;
    if a.tasks == Some(0) {
        bail!("--tasks 0: a job needs at least one task");
    }
    if a.cpus_per_task == Some(0) {
        bail!("--cpus-per-task 0: a task needs at least one CPU");
    }
    if a.gpus_per_task == Some(0) {
        bail!("--gpus-per-task 0: give at least 1, or leave it out to render on CPUs");
    }

    if !a.dry_run {
        if !farm::slurm::on_path("sbatch") {
            bail!("sbatch is not on the PATH: is Slurm installed here? (nothing submitted)");
        }
        if let Some(p) = &a.partition {
            farm::slurm::check_partition(p)?;
        }
    }
    let w = prepare(r, a.dry_run, !a.dry_run)?;
    if nothing_missing(&w, r.quiet) {
        return Ok(ExitCode::SUCCESS);
    }
    let count = u32::try_from(w.plan.frames.len()).unwrap_or(u32::MAX);
    let tasks = a.tasks.unwrap_or_else(|| count.min(8)).min(count).max(1);
    // As many shards as give each task frames: stepped frames (`0..20:2`) leave some
    // of `tasks` shards empty, since a shard takes the frames `k % N == i`.
    let shards = if (count as usize) <= farm::SHARD_SEARCH / 64 {
        farm::shard_count(&w.plan.frames.iter().collect::<Vec<u32>>(), tasks)
    } else {
        tasks
    };
    if shards != tasks && !r.quiet {
        eprintln!(
            "note: {} as {} (a shard takes the frames k with k % {shards} == i), so that \
             each holds some of the frames {}",
            plural(tasks, "task"),
            plural(shards, "shard"),
            w.plan.set
        );
    }
    let mut array: Vec<u32> = w.missing.iter().map(|f| f % shards).collect();
    array.sort_unstable();
    array.dedup();
    let mut command = w.command.clone();
    if a.gpus_per_task.is_some() && r.device != subfield::render::TraceDevice::Gpu {
        command.retain(|x| !x.starts_with("--device="));
        command.push("--device=gpu".into());
    }
    // Every task plans the same frames as this plan, and takes its shard of them.
    command.push(format!("--frames={}", w.plan.set));
    let job = SlurmJob {
        name: format!("subfield-{}", w.base),
        shards,
        array,
        partition: a.partition.clone(),
        time: a.time.clone(),
        cpus_per_task: a.cpus_per_task,
        log_dir: w.dir.join(format!("{}.logs", w.base)),
        command,
        stage_dir: r.stage_dir.clone(),
        gpus_per_task: a.gpus_per_task,
        sbatch_args: a.sbatch_args.clone(),
    };
    let script = job.script();
    if a.dry_run {
        super::print_stdout(&script)?;
        return Ok(ExitCode::SUCCESS);
    }
    std::fs::create_dir_all(&job.log_dir)
        .with_context(|| format!("cannot create {}", job.log_dir.display()))?;
    let path = w.dir.join(format!("{}.slurm.sh", w.base));
    subfield::atomic::write_atomically(&path, script.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))?;
    let id = farm::slurm::sbatch(&path, &a.sbatch_args)?;
    if !r.quiet {
        eprintln!(
            "submitted job {id}: {} of {} for {} of {} ({}), script {}, logs {}",
            job.array.len(),
            plural(shards, "task"),
            plural(w.missing.len() as u64, "missing frame"),
            w.plan.frames.len(),
            w.plan.set,
            path.display(),
            job.log_dir.display()
        );
    }
    super::print_stdout(&format!("{id}\n"))?;
    if a.wait {
        return follow(&id, &w, r, &job.log_dir);
    }
    Ok(ExitCode::SUCCESS)
}

/// `--wait`: a bar over the frames written until the job leaves the queue, then the
/// verdict: every frame complete, or the missing ones and the errors the tasks logged.
fn follow(id: &str, w: &Work, r: &render_cmd::Args, log_dir: &Path) -> anyhow::Result<ExitCode> {
    let total = w.plan.frames.len() as u64;
    let bar = Progress::new("frames", total, r.quiet);
    let written = || {
        w.plan
            .frames
            .iter()
            .filter(|&f| w.plan.pattern.path(f).is_file())
            .count() as u64
    };
    // squeue is cheap; a coarse poll would add its period to every wait.
    let poll = Duration::from_millis(250);
    // A task its script requeues (exit 5) can be missing from squeue for a moment
    // between leaving and re-entering the queue: the job is gone once the queue has
    // stayed empty this long.
    let settle = Duration::from_secs(2);
    let start = Instant::now();
    let mut empty_since: Option<Instant> = None;
    loop {
        let queued = farm::slurm::queued_tasks(id)?;
        let running = queued.iter().filter(|t| t.state == "RUNNING").count();
        bar.set(
            written(),
            &format!("job {id}: {running} running, {} queued", queued.len()),
        );
        if !queued.is_empty() {
            empty_since = None;
        } else if empty_since.get_or_insert_with(Instant::now).elapsed() >= settle {
            break;
        }
        std::thread::sleep(poll);
    }
    bar.finish();
    let missing: Vec<u32> = w
        .plan
        .frames
        .iter()
        .filter(|&f| !complete(&w.plan, &w.opts, f))
        .collect();
    if missing.is_empty() {
        if !r.quiet {
            eprintln!(
                "job {id} done: {} complete in {:.1} s",
                if total == 1 {
                    "the frame".to_string()
                } else {
                    format!("all {total} frames")
                },
                start.elapsed().as_secs_f64()
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
    for line in task_errors(log_dir, id) {
        eprintln!("{line}");
    }
    let runs: Vec<String> = farm::frame_runs(&missing)
        .iter()
        .map(|&(a, b)| {
            if b == a + 1 {
                a.to_string()
            } else {
                format!("{a}..{b}")
            }
        })
        .collect();
    bail!(
        "job {id} ended with {} of {} missing: {}; submit the same command again to render them",
        missing.len(),
        plural(total, "frame"),
        runs.join(",")
    )
}

/// The `error:` lines of the job's task logs, each prefixed with its log's name.
fn task_errors(log_dir: &Path, id: &str) -> Vec<String> {
    let mut logs: Vec<PathBuf> = std::fs::read_dir(log_dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with(&format!("{id}_")))
                })
                .collect()
        })
        .unwrap_or_default();
    logs.sort();
    let mut out = Vec::new();
    for p in logs {
        let Ok(text) = std::fs::read_to_string(&p) else {
            continue;
        };
        for l in text.lines().filter(|l| l.starts_with("error:")) {
            out.push(format!("{}: {l}", p.display()));
        }
    }
    out
}

fn openjd(a: OpenJdArgs) -> anyhow::Result<ExitCode> {
    let r = &a.render;
    if a.chunk == 0 {
        bail!("--chunk 0: a task needs at least one frame");
    }
    if a.chunk_seconds == Some(0) {
        bail!("--chunk-seconds 0: a chunk takes some time");
    }
    if let Some(f) = a.frame_seconds {
        if !(f.is_finite() && f > 0.0) {
            bail!("--frame-seconds {f}: must be a positive number of seconds");
        }
    }
    if let Some(t) = &a.template {
        if t.extension().and_then(|e| e.to_str()) != Some("yaml") {
            bail!("--template {}: a job template is a .yaml file", t.display());
        }
        super::check_target("--template", t)?;
    }
    if let Some(b) = &a.bundle {
        if b.exists() && !b.is_dir() {
            bail!("--bundle {}: names a file, not a folder", b.display());
        }
    }
    let mut w = prepare(r, false, false)?;
    let measured = match (a.measure, w.missing.first()) {
        (true, Some(&f)) => {
            let secs = measure_frame(&w, f)?;
            w.missing.remove(0);
            if !r.quiet {
                eprintln!("rendered frame {f} here to measure it: {secs:.3} s a frame");
            }
            Some(secs)
        }
        _ => None,
    };
    if nothing_missing(&w, r.quiet) {
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(t) = &a.template {
        let job = OpenJdJob {
            name: format!("subfield render {}", w.base),
            chunks: chunks(&w.missing, a.chunk),
            command: w.command.clone(),
            stage_dir: r.stage_dir.clone(),
            gpu: r.device == subfield::render::TraceDevice::Gpu,
        };
        if let Some(parent) = t.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        subfield::atomic::write_atomically(t, job.template().as_bytes())
            .with_context(|| format!("cannot write {}", t.display()))?;
        if !r.quiet {
            eprintln!(
                "wrote {}: {} for {} of {}; run it with `openjd run {}`",
                t.display(),
                plural(job.chunks.len() as u64, "task"),
                plural(w.missing.len() as u64, "missing frame"),
                w.plan.frames.len(),
                t.display()
            );
        }
    }
    if let Some(dir) = &a.bundle {
        let bundle = job_bundle(&a, &w, measured.or(a.frame_seconds))?;
        bundle.write(dir)?;
        if !r.quiet {
            eprintln!(
                "wrote the job bundle {}: {} in chunks of {}{}; submit it with `deadline bundle submit {}`",
                dir.display(),
                plural(w.missing.len() as u64, "missing frame"),
                bundle.chunk,
                match bundle.target_seconds {
                    Some(s) => format!(" (resized to about {s} s each by the scheduler)"),
                    None => String::new(),
                },
                dir.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The job bundle of `w`: chunks of `--chunk` frames, or as many frames as fill
/// `--chunk-seconds` (default 600) at `--frame-seconds` each.
fn job_bundle(a: &OpenJdArgs, w: &Work, frame_seconds: Option<f64>) -> anyhow::Result<JobBundle> {
    const DEFAULT_CHUNK_SECONDS: u32 = 600;
    let target = match (a.chunk_seconds, frame_seconds) {
        (Some(t), _) => Some(t),
        (None, Some(_)) => Some(DEFAULT_CHUNK_SECONDS),
        (None, None) => None,
    };
    let chunk = match (target, frame_seconds) {
        // At least one frame a chunk, at most every frame in one.
        (Some(t), Some(f)) => {
            ((t as f64 / f).floor() as u64).clamp(1, w.missing.len() as u64) as u32
        }
        _ => a.chunk,
    };
    let pattern_name = w
        .opts
        .output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .context("-o: the pattern has no file name")?;
    Ok(JobBundle {
        name: format!("subfield render {}", w.base),
        frames: w.missing.clone(),
        chunk,
        target_seconds: target,
        exe: w.exe.clone(),
        scene: w.scene.clone(),
        baked: w.baked.clone(),
        output_dir: subfield::atomic::folder_of(&w.opts.output),
        pattern_name,
        flags: w.flags.clone(),
        stage_dir: a.render.stage_dir.clone(),
        gpu: a.render.device == subfield::render::TraceDevice::Gpu,
    })
}

/// `--measure`: renders `frame` into the output as a task would (from the bake) and
/// returns its seconds: update, trace, shade and write, not the import or the bake's
/// opening, which a task pays once for its whole chunk.
fn measure_frame(w: &Work, frame: u32) -> anyhow::Result<f64> {
    let mut o = w.opts.clone();
    o.frames = Some(FrameSet::from_sorted(&[frame]));
    o.baked = Some(w.baked.clone());
    let summary = render::render_sequence(&w.scene_model, &o, &mut |_| {})
        .with_context(|| format!("cannot render frame {frame} to measure it"))?;
    let t = &summary.totals;
    Ok(((t.update_ms + t.trace_ms + t.shade_ms + t.write_ms) / 1e3).max(1e-3))
}

/// The missing frames (ascending) as OpenJD tasks of at most `k` frames each, spelled as
/// `--frames` reads them: consecutive frames in chunks of `A..B` that a gap ends (as
/// before), and frames with steps between them (`--frames 0..800:100`) `k` to a task.
fn chunks(missing: &[u32], k: u32) -> Vec<String> {
    let consecutive = missing.windows(2).all(|w| w[1] == w[0] + 1);
    let stepped = missing.len() > 1 && !missing.windows(2).any(|w| w[1] == w[0] + 1);
    if consecutive || !stepped {
        return farm::frame_chunks(missing, k)
            .into_iter()
            .map(|(a, b)| {
                FrameSet::new(vec![FrameSpan {
                    start: a,
                    end: b,
                    step: 1,
                }])
                .to_string()
            })
            .collect();
    }
    missing
        .chunks(k.max(1) as usize)
        .map(|c| FrameSet::from_sorted(c).to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn openjd_chunks_spell_frames_as_render_reads_them() {
        assert_eq!(
            chunks(&[0, 1, 2, 3, 4, 9, 10], 2),
            ["0..2", "2..4", "4", "9..11"]
        );
        assert_eq!(
            chunks(&[0, 100, 200, 300, 400, 500, 600, 700], 3),
            ["0..201:100", "300..501:100", "600,700"]
        );
    }

    #[test]
    fn job_files_are_named_after_the_pattern() {
        assert_eq!(base_name(Path::new("out/frame.####.exr")), "frame");
        assert_eq!(base_name(Path::new("out/shot_010_####.exr")), "shot_010");
        assert_eq!(base_name(Path::new("out/####.exr")), "subfield");
        assert_eq!(base_name(Path::new("still.exr")), "still");
        assert_eq!(base_name(Path::new("a b$.####.exr")), "a_b_");
    }
}
