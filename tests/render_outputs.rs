//! What a render writes, when writing goes wrong (issue 25, "Outputs and ranges"; issue
//! 24, Ctrl-C): outputs that are not regular files refused before anything is rendered,
//! a huge frame range that costs no memory before frame 0, a full disk that names the
//! file and the cause and leaves complete frames to resume from, and Ctrl-C that stops
//! after the frames in flight.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::render_scene::{files_under, temp_dir, write_scene};

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_subfield")
}

fn subfield(args: &[&str]) -> Output {
    Command::new(exe()).args(args).output().unwrap()
}

fn ok(args: &[&str]) -> Output {
    let o = subfield(args);
    assert!(
        o.status.success(),
        "subfield {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// Runs and expects one line of error on stderr, naming every `needle`.
fn refused(args: &[&str], needles: &[&str]) -> String {
    let o = subfield(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "subfield {args:?} succeeded: {err}");
    assert_eq!(err.lines().count(), 1, "not one line: {err}");
    for n in needles {
        assert!(err.contains(n), "{n:?} not in {err:?}");
    }
    err
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn mkfifo(p: &Path) {
    let made = Command::new("mkfifo")
        .arg(p)
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        made,
        "mkfifo {} failed (is coreutils installed?)",
        p.display()
    );
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

fn is_fifo(p: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_fifo())
}

/// The frames (visible regular `.exr` files) under `dir` with their bytes (a FIFO is
/// not opened: that would wait for a writer).
fn frames_in(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    files_under(dir)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "exr"))
        .filter(|p| std::fs::symlink_metadata(dir.join(p)).is_ok_and(|m| m.is_file()))
        .map(|p| {
            let b = std::fs::read(dir.join(&p)).unwrap();
            (p, b)
        })
        .collect()
}

/// Waits until the render `child` has written its first frame into `dir` (two
/// minutes at most; the child must still be running meanwhile).
fn wait_for_first_frame(dir: &Path, child: &mut std::process::Child) {
    let t = Instant::now();
    while frames_in(dir).is_empty() {
        assert!(t.elapsed() < Duration::from_secs(120), "no frame written");
        assert!(child.try_wait().unwrap().is_none(), "ended before frame 0");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Hidden files (temporaries) under `dir`.
fn hidden_in(dir: &Path) -> Vec<PathBuf> {
    files_under(dir)
        .into_iter()
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'))
        })
        .collect()
}

/// Issue 25: `-o /dev/full` replaced the device with an EXR. A FIFO, a device node, a
/// folder, and links to them, where a render (or bake, generate, convert, demo, submit)
/// would write, are refused in one line before anything is rendered, and left as they
/// were; a link to a regular file is written through and stays a link.
#[test]
fn outputs_that_are_not_regular_files_are_refused_before_rendering() {
    let dir = temp_dir("not-regular");
    let scene = write_scene(&dir);
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    let fifo = out.join("f.0002.exr");
    mkfifo(&fifo);
    let base = |o: &Path| -> Vec<String> {
        [
            "render",
            s(&scene),
            "-o",
            s(o),
            "--frames",
            "0..4",
            "--size",
            "16x12",
        ]
        .iter()
        .map(|a| a.to_string())
        .collect()
    };
    let run = |extra: &[&str], o: &Path, needles: &[&str]| {
        let mut a = base(o);
        a.extend(extra.iter().map(|x| x.to_string()));
        let a: Vec<&str> = a.iter().map(|x| x.as_str()).collect();
        refused(&a, needles);
    };
    // A FIFO at the third frame's path: refused before frame 0 is rendered.
    run(&[], &out.join("f.####.exr"), &["f.0002.exr", "FIFO"]);
    assert!(frames_in(&out).is_empty() && is_fifo(&fifo));
    std::fs::remove_file(&fifo).unwrap();
    // A folder at a frame's path, at the stats' and the plot's.
    std::fs::create_dir_all(out.join("f.0001.exr")).unwrap();
    run(&[], &out.join("f.####.exr"), &["f.0001.exr", "a folder"]);
    std::fs::remove_dir(out.join("f.0001.exr")).unwrap();
    std::fs::create_dir_all(dir.join("stats.csv")).unwrap();
    let stats = dir.join("stats.csv");
    run(
        &["--stats", s(&stats)],
        &out.join("f.####.exr"),
        &["stats.csv", "a folder"],
    );
    let plot_fifo = dir.join("plot.svg");
    mkfifo(&plot_fifo);
    run(
        &["--plot", s(&plot_fifo)],
        &out.join("f.####.exr"),
        &["plot.svg", "FIFO"],
    );
    // A link to the FIFO as the stats file.
    let link = dir.join("link.csv");
    std::os::unix::fs::symlink(&plot_fifo, &link).unwrap();
    run(
        &["--stats", s(&link)],
        &out.join("f.####.exr"),
        &["link.csv", "symbolic link", "FIFO"],
    );
    assert!(frames_in(&out).is_empty());

    // A device node (as root: what `-o /dev/full` was), made in the temporary folder.
    let dev = out.join("still.exr");
    if is_root() {
        let made = Command::new("mknod")
            .args([s(&dev), "c", "1", "7"])
            .status()
            .is_ok_and(|s| s.success());
        assert!(made, "mknod failed although running as root");
        let o = subfield(&[
            "render",
            s(&scene),
            "-o",
            s(&dev),
            "--frames",
            "0",
            "--size",
            "16x12",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains("a character device"),
            "{err}"
        );
        use std::os::unix::fs::FileTypeExt;
        let t = std::fs::symlink_metadata(&dev).unwrap().file_type();
        assert!(t.is_char_device(), "the device node was replaced");
        std::fs::remove_file(&dev).unwrap();
    } else {
        eprintln!("SKIPPED: the device-node case needs root (mknod); the FIFO cases ran");
    }

    // The other commands that write: bake, generate (museum and animart), demo, submit.
    let target = dir.join("target.fifo");
    mkfifo(&target);
    refused(
        &["bake", s(&scene), "-o", s(&target)],
        &["target.fifo", "FIFO"],
    );
    refused(
        &["generate", "museum", "-o", s(&target)],
        &["target.fifo", "FIFO"],
    );
    refused(
        &["generate", "animart", "--triangles", "4", "-o", s(&target)],
        &["target.fifo", "FIFO"],
    );
    let aff = dir.join("tiny.aff");
    std::fs::write(&aff, "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 0.1\nresolution 8 8\nl 1 1 1\nf 1 1 1 1 0 0 0 0\np 3\n-1 0 0\n1 0 0\n0 1 0\n").unwrap();
    let glb_fifo = dir.join("t.glb");
    mkfifo(&glb_fifo);
    refused(
        &["convert", s(&aff), "-o", s(&glb_fifo)],
        &["t.glb", "FIFO"],
    );
    let demo = dir.join("demo");
    std::fs::create_dir_all(&demo).unwrap();
    mkfifo(&demo.join("preview.png"));
    refused(&["demo", "-o", s(&demo)], &["preview.png", "FIFO"]);
    assert!(!demo.join("museum.glb").exists());
    let yaml = dir.join("job.yaml");
    mkfifo(&yaml);
    refused(
        &[
            "submit",
            "openjd",
            s(&scene),
            "-o",
            s(&dir.join("farm/f.####.exr")),
            "--template",
            s(&yaml),
        ],
        &["job.yaml", "FIFO"],
    );
    assert!(!dir.join("farm").exists());
    for f in [&target, &glb_fifo, &yaml, &plot_fifo] {
        assert!(is_fifo(f), "{} was replaced", f.display());
    }

    // A link to a regular file is written through: the link stays, its file is the frame.
    let real = dir.join("real.exr");
    std::fs::write(&real, b"old").unwrap();
    let still = dir.join("still.exr");
    std::os::unix::fs::symlink("real.exr", &still).unwrap();
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&still),
        "--frames",
        "1",
        "--size",
        "16x12",
        "--quiet",
    ]);
    assert!(std::fs::symlink_metadata(&still)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::read(&real)
        .unwrap()
        .starts_with(&[0x76, 0x2f, 0x31, 0x01]));
    // A dangling link is refused.
    let dangling = dir.join("dangling.exr");
    std::os::unix::fs::symlink("nowhere/x.exr", &dangling).unwrap();
    refused(
        &[
            "render",
            s(&scene),
            "-o",
            s(&dangling),
            "--frames",
            "1",
            "--size",
            "16x12",
        ],
        &["dangling.exr", "cannot be followed"],
    );
    assert!(!dir.join("nowhere").exists());
    assert!(hidden_in(&dir).is_empty(), "{:?}", hidden_in(&dir));
}

/// Issue 25: `--frames 0..4000000000` held 5 GB after 8 s and had not written frame 0.
/// Under a 1 GiB address-space limit (`ulimit -v`): a range past the documented limit
/// (`MAX_FRAMES`, ten million) is refused at once in one line; a range of ten million
/// frames, the most a render takes, writes frame 0 (its memory does not grow with the
/// frame count: the plan is lazy and the stats are streamed) and is then stopped.
#[test]
fn a_huge_frame_range_costs_nothing_before_frame_0() {
    let dir = temp_dir("huge");
    let scene = write_scene(&dir);
    let limited = |frames: &str, out: &Path| {
        Command::new("bash")
            .args([
                "-c",
                "ulimit -v 1048576 && exec \"$0\" \"$@\"",
                exe(),
                "render",
                s(&scene),
                "-o",
                s(out),
                "--frames",
                frames,
                "--size",
                "16x12",
                "--threads",
                "2",
                "--stats",
                s(&dir.join("stats.csv")),
                "--plot",
                s(&dir.join("plot.svg")),
                "--quiet",
            ])
            .env("MALLOC_ARENA_MAX", "2")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let t = Instant::now();
    let o = limited("0..4000000000", &dir.join("a/f.##########.exr"))
        .wait_with_output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(
        err.trim(),
        "error: --frames \"0..4000000000\": 4000000000 frames, more than the 10000000 a render takes (a typo?)"
    );
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
    assert!(!dir.join("a").exists());

    let out = dir.join("b/f.########.exr");
    let mut child = limited("0..10000000", &out);
    let frame0 = dir.join("b/f.00000000.exr");
    let t = Instant::now();
    while !frame0.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            use std::io::Read;
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut err)
                .unwrap();
            panic!("the render ended ({status}) before frame 0: {err}");
        }
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "no frame 0 after 2 minutes"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    eprintln!("frame 0 of 10,000,000 written after {:?}", t.elapsed());
    // Still running, within its limit, once a few more frames are out.
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the render stopped early"
    );
    child.kill().unwrap();
    let _ = child.wait();
}

/// A small tmpfs mounted for one test (root, where mounting is allowed), unmounted when
/// dropped.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(at: &Path, size: &str) -> Option<Tmpfs> {
        std::fs::create_dir_all(at).unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs", s(at)])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| Tmpfs(at.to_path_buf()))
    }

    fn grow(&self, size: &str) {
        let ok = Command::new("mount")
            .args(["-o", &format!("remount,size={size}"), s(&self.0)])
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "cannot remount {}", self.0.display());
    }

    /// Fills it to the last byte.
    fn fill(&self) {
        let r = std::fs::write(self.0.join("filler"), vec![7u8; 64 << 20]);
        assert!(r.is_err(), "the filler fit");
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

fn render_args(scene: &Path, out: &Path, frames: &str) -> Vec<String> {
    [
        "render",
        s(scene),
        "-o",
        s(out),
        "--frames",
        frames,
        "--size",
        "160x120",
        "--quiet",
    ]
    .iter()
    .map(|a| a.to_string())
    .collect()
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(|a| a.as_str()).collect()
}

/// Issue 25: on a full disk (a 1 MiB tmpfs) the render said only "the frame writer
/// stopped unexpectedly". The error names the frame file and the cause; the frames
/// before it are complete, nothing partial or temporary is left, and `--resume` after
/// space is freed gives the set of an uninterrupted run, byte for byte. The same for
/// the stats, the plot and the preview. Without permission to mount, the same is checked
/// with a file-size limit (`ulimit -f`, `File too large`), and the tmpfs cases are
/// reported as skipped.
#[test]
fn a_full_disk_names_the_file_and_resume_carries_on() {
    let dir = temp_dir("full");
    let scene = write_scene(&dir);
    let reference = dir.join("ref/f.####.exr");
    ok(&strs(&render_args(&scene, &reference, "0..40")));
    let want = frames_in(&dir.join("ref"));
    assert_eq!(want.len(), 40);

    let Some(disk) = Tmpfs::mount(&dir.join("disk"), "1m") else {
        eprintln!("SKIPPED: tmpfs cases (cannot mount here); checking with ulimit -f");
        let out = dir.join("limited/f.####.exr");
        std::fs::create_dir_all(dir.join("limited")).unwrap();
        let mut cmd = vec![
            "-c".to_string(),
            "trap '' XFSZ; ulimit -f 8 && exec \"$0\" \"$@\"".into(),
            exe().into(),
        ];
        cmd.extend(render_args(&scene, &out, "0..40"));
        let o = Command::new("bash").args(&cmd).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(
            err.contains("cannot write frame 0 to") && err.contains("File too large"),
            "{err}"
        );
        assert!(hidden_in(&dir.join("limited")).is_empty());
        let mut resume = render_args(&scene, &out, "0..40");
        resume.push("--resume".into());
        ok(&strs(&resume));
        assert_eq!(frames_in(&dir.join("limited")), want);
        return;
    };
    let out = disk.0.join("f.####.exr");
    let o = subfield(&strs(&render_args(&scene, &out, "0..40")));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("cannot write frame ")
            && err.contains(s(&disk.0))
            && err.contains("No space left on device"),
        "{err}"
    );
    let written = frames_in(&disk.0);
    assert!(
        !written.is_empty() && written.len() < 40,
        "{}",
        written.len()
    );
    // Every frame on the disk is complete and right; the failed one is named.
    for (p, bytes) in &written {
        let (_, b) = want.iter().find(|(q, _)| q == p).unwrap();
        assert_eq!(bytes, b, "{}", p.display());
    }
    let failed = written.len();
    assert!(err.contains(&format!("frame {failed} to ")), "{err}");
    assert!(hidden_in(&disk.0).is_empty(), "{:?}", hidden_in(&disk.0));
    disk.grow("64m");
    let mut resume = render_args(&scene, &out, "0..40");
    resume.push("--resume".into());
    ok(&strs(&resume));
    assert_eq!(frames_in(&disk.0), want);

    // The stats and the plot on a full disk: the frames (elsewhere) are written, the
    // error names the file, and nothing of it is left.
    disk.fill();
    for (flag, name, what) in [
        ("--stats", "s.csv", "the stats"),
        ("--plot", "p.svg", "the plot"),
    ] {
        let mut a = render_args(&scene, &dir.join("other/f.####.exr"), "0..3");
        a.extend([flag.to_string(), s(&disk.0.join(name)).to_string()]);
        let o = subfield(&strs(&a));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(
            err.contains(&format!("cannot write {what} to {}", s(&disk.0.join(name))))
                && err.contains("No space left on device"),
            "{err}"
        );
        assert!(!disk.0.join(name).exists());
        assert!(hidden_in(&disk.0).is_empty(), "{:?}", hidden_in(&disk.0));
    }
    // The preview (the library's option; `render --preview` reaches it).
    let scene_model = subfield::import::load(&scene).unwrap();
    let opts = subfield::render::RenderOptions {
        output: dir.join("lib/f.#.exr"),
        frames: Some(subfield::render::FrameRange { start: 0, end: 2 }.into()),
        width: 16,
        height: 12,
        preview: Some(subfield::render::PreviewOptions {
            frame: None,
            path: disk.0.join("preview.png"),
        }),
        ..Default::default()
    };
    let e = subfield::render::render_sequence(&scene_model, &opts, &mut |_| {}).unwrap_err();
    match &e {
        subfield::render::RenderError::Write { path, file, source } => {
            assert_eq!(path, &disk.0.join("preview.png"));
            assert_eq!(*file, subfield::render::OutputFile::Preview);
            assert_eq!(source.raw_os_error(), Some(28), "{source}");
        }
        other => panic!("{other}"),
    }
    assert!(hidden_in(&disk.0).is_empty());
}

/// Issue 24: Ctrl-C killed the run without a word. Now it stops after the frame in
/// flight, writes nothing partial, says how many frames were written and that
/// `--resume` carries on, and exits with 130; the resumed run completes the set of an
/// uninterrupted run, byte for byte. SIGTERM (how Slurm's `scancel`, its time limit and
/// most farm managers stop a task) and SIGHUP do the same, exiting with 143 and 129.
#[test]
fn a_stopping_signal_stops_after_the_frame_in_flight_and_resume_completes() {
    let dir = temp_dir("ctrl-c");
    let scene = write_scene(&dir);
    let args = |out: &Path| -> Vec<String> {
        let mut a = render_args(&scene, out, "0..48");
        a.extend(["--spp".into(), "2".into()]);
        a.retain(|x| x != "--quiet");
        a
    };
    ok(&strs(&args(&dir.join("full/f.####.exr"))));
    let want = frames_in(&dir.join("full"));
    assert_eq!(want.len(), 48);

    for (signal, code, said) in [
        ("INT", 130, "interrupt: stopping after the frames in flight"),
        ("TERM", 143, "SIGTERM): stopping after the frames in flight"),
        ("HUP", 129, "SIGHUP): stopping after the frames in flight"),
    ] {
        let part = dir.join(format!("part-{signal}"));
        let mut child = Command::new(exe())
            .args(args(&part.join("f.####.exr")))
            .stderr(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .unwrap();
        wait_for_first_frame(&part, &mut child);
        let sent = Command::new("kill")
            .args([format!("-{signal}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(sent.success());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "SIG{signal}: {err}");
        let written = frames_in(&part);
        let n = written.len();
        assert!(n < 48, "all frames were written before SIG{signal}: {err}");
        let last = err.lines().last().unwrap_or_default();
        let frames = if n == 1 { "frame" } else { "frames" };
        assert_eq!(
            last,
            format!(
                "interrupted: {n} {frames} written by this run (0 complete before it), {} left; the same command with --resume carries on",
                48 - n
            ),
            "SIG{signal}: {err}"
        );
        assert!(err.contains(said), "SIG{signal}: {err}");
        assert!(hidden_in(&part).is_empty(), "{:?}", hidden_in(&part));
        for (p, bytes) in &written {
            let (_, b) = want.iter().find(|(q, _)| q == p).unwrap();
            assert_eq!(bytes, b, "{}", p.display());
        }
        let mut resume = args(&part.join("f.####.exr"));
        resume.push("--resume".into());
        let o = ok(&strs(&resume));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(&format!("({n} skipped as complete)")), "{err}");
        assert_eq!(frames_in(&part), want, "SIG{signal}");
    }
}

/// A stopping signal the render inherited as ignored stays ignored: `nohup` (SIGHUP
/// ignored) keeps rendering through a closed terminal. Here the shell ignores SIGHUP
/// (`trap '' HUP`) before it execs the render, and the render finishes every frame (the
/// signal is sent once frame 0 is written, well before frame 47).
#[test]
fn an_inherited_ignored_sighup_stays_ignored() {
    let dir = temp_dir("nohup");
    let scene = write_scene(&dir);
    let part = dir.join("out");
    let mut args = render_args(&scene, &part.join("f.####.exr"), "0..48");
    args.extend(["--spp".into(), "2".into()]);
    args.retain(|x| x != "--quiet");
    let mut line = format!("trap '' HUP; exec '{}'", exe());
    for a in &args {
        line.push_str(&format!(" '{a}'"));
    }
    let mut child = Command::new("sh")
        .args(["-c", &line])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    wait_for_first_frame(&part, &mut child);
    let sent = Command::new("kill")
        .args(["-HUP", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(!err.contains("SIGHUP"), "{err}");
    assert!(err.contains("rendered 48 frames"), "{err}");
    assert_eq!(frames_in(&part).len(), 48, "{err}");
}
