//! Issue 40: exit codes that tell a farm whether to retry, one test per class through
//! the binary (DESIGN.md §4): 2 usage, 3 bad input, 4 a bake of another scene, 5 an I/O
//! or resource failure, 143 / 130 a stopping signal with the frames written so far
//! intact; and `--log-format json`, whose every stderr line is a JSON object and whose
//! frame events carry the content hash of the files on disk.

mod common;

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::farm::{frames, s, stderr, subfield};
use common::render_scene::{scene, temp_dir, write_scene};
use serde_json::Value;

fn code(o: &Output) -> Option<i32> {
    o.status.code()
}

fn render_args<'a>(scene: &'a Path, out: &'a Path, frames: &'a str) -> Vec<&'a str> {
    vec![
        "render",
        s(scene),
        "-o",
        s(out),
        "--frames",
        frames,
        "--size",
        "48x36",
        "--quiet",
    ]
}

/// Every stderr line parsed as JSON (a line that is not JSON fails the test).
fn events(o: &Output) -> Vec<Value> {
    stderr(o)
        .lines()
        .map(|l| {
            serde_json::from_str::<Value>(l)
                .unwrap_or_else(|e| panic!("not a JSON line ({e}): {l:?}\n{}", stderr(o)))
        })
        .collect()
}

#[test]
fn a_bad_flag_is_a_usage_error_2() {
    let o = subfield(&["render", "x.glb", "-o", "f.exr", "--no-such-flag"]);
    assert_eq!(code(&o), Some(2), "{}", stderr(&o));
    // A flag without its value is syntax too.
    let o = subfield(&["render", "x.glb", "-o", "f.exr", "--spp"]);
    assert_eq!(code(&o), Some(2), "{}", stderr(&o));
    assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
}

#[test]
fn a_value_a_flag_cannot_take_is_bad_input_3_whichever_flag() {
    // Not a number, a negative count, not one of the choices, refused by the flag's
    // own parser: each an option value, as the library's checks (`--spp 0`) are.
    for extra in [
        &["--spp", "many"][..],
        &["--max-depth", "-1"],
        &["--overscan", "-1"],
        &["--fps", "abc"],
        &["--device", "bogus"],
        &["--compression", "dwaa"],
        &["--size", "-5x10"],
        &["--background", "-1,0,0"],
        &["--threads", "100000"],
    ] {
        let mut args = vec!["render", "x.glb", "-o", "f.exr"];
        args.extend(extra);
        let o = subfield(&args);
        assert_eq!(code(&o), Some(3), "{extra:?}: {}", stderr(&o));
        let line = stderr(&o);
        assert_eq!(line.lines().count(), 1, "{line}");
        assert!(
            line.starts_with("error: ") && !line.contains("error: error"),
            "{line}"
        );
    }
    // Reported as any error is: a JSON event with --log-format json, and openjd_fail
    // on stdout for Open Job Description, though clap found it before parsing.
    let o = subfield(&[
        "render",
        "x.glb",
        "-o",
        "f.exr",
        "--log-format",
        "json",
        "--progress",
        "openjd",
        "--fps",
        "abc",
    ]);
    assert_eq!(code(&o), Some(3), "{}", stderr(&o));
    let ev = events(&o);
    assert_eq!(ev.len(), 1, "{}", stderr(&o));
    assert_eq!(ev[0]["event"], "error");
    assert_eq!(ev[0]["exit_code"], 3);
    assert!(
        String::from_utf8_lossy(&o.stdout).starts_with("openjd_fail: "),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
}

#[test]
fn bad_input_is_3_and_writes_nothing() {
    let dir = temp_dir("exit-3");
    let broken = dir.join("broken.glb");
    std::fs::write(&broken, b"glTF\x02\x00\x00\x00 this is not a GLB").unwrap();
    let out = dir.join("out/f.#.exr");
    for args in [
        render_args(&broken, &out, "0"),
        render_args(&dir.join("missing.glb"), &out, "0"),
        vec!["bake", s(&broken), "-o", s(&dir.join("b.psf"))],
        vec!["inspect", s(&broken)],
    ] {
        let o = subfield(&args);
        assert_eq!(code(&o), Some(3), "{args:?}: {}", stderr(&o));
        assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
    }
    // A bad option value, found by the library (--spp 0) and by the command line
    // (--look-from without --look-at).
    let good = write_scene(&dir);
    for extra in [["--spp", "0"], ["--look-from", "1,2,3"]] {
        let mut args = render_args(&good, &out, "0");
        args.extend(extra);
        let o = subfield(&args);
        assert_eq!(code(&o), Some(3), "{extra:?}: {}", stderr(&o));
    }
    assert!(!dir.join("out").exists());
}

#[test]
fn a_bake_of_another_scene_is_a_hash_mismatch_4() {
    let dir = temp_dir("exit-4");
    let scene_a = write_scene(&dir);
    // The same scene with every vertex moved: another static part, another scene hash.
    let mut other = scene();
    for m in &mut other.meshes {
        for p in &mut m.primitives {
            for v in &mut p.positions {
                *v *= 1.5;
            }
        }
    }
    let scene_b = dir.join("other.glb");
    subfield::import::write_gltf(&other, &scene_b).unwrap();
    let psf_b = dir.join("other.psf");
    let o = subfield(&["bake", s(&scene_b), "-o", s(&psf_b), "--quiet"]);
    assert_eq!(code(&o), Some(0), "{}", stderr(&o));
    let out = dir.join("out/f.#.exr");
    let mut args = render_args(&scene_a, &out, "0");
    args.extend(["--baked", s(&psf_b)]);
    let o = subfield(&args);
    assert_eq!(code(&o), Some(4), "{}", stderr(&o));
    assert!(stderr(&o).contains("re-bake"), "{}", stderr(&o));
    // A staged bake whose content hash is not the job's: 4 as well.
    let stage = dir.join("stage");
    let mut args = render_args(&scene_b, &out, "0");
    args.extend([
        "--baked",
        s(&psf_b),
        "--baked-hash",
        "0123456789abcdef0123456789abcdef",
        "--stage-dir",
        s(&stage),
    ]);
    let o = subfield(&args);
    assert_eq!(code(&o), Some(4), "{}", stderr(&o));
    assert!(!dir.join("out").exists());
}

/// Root ignores file permissions, so a read-only folder is no test here. A file-size
/// limit (`ulimit -f`, as a quota is) makes the frame's write fail with EFBIG (`File too
/// large`) once SIGXFSZ is ignored: a resource failure, which another node or a later
/// try can get past. In JSON the error event carries the exit code and the class.
#[test]
fn a_failed_write_is_a_resource_failure_5() {
    let dir = temp_dir("exit-5");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.##.exr");
    let mut args = render_args(&scene, &out, "0..3");
    args.extend(["--log-format", "json"]);
    let o = Command::new("bash")
        .arg("-c")
        .arg("trap '' XFSZ; ulimit -f 1 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_subfield"))
        .args(&args)
        .output()
        .unwrap();
    assert_eq!(code(&o), Some(5), "{}", stderr(&o));
    let ev = events(&o);
    let last = ev.last().unwrap();
    assert_eq!(last["event"], "error", "{last}");
    assert_eq!(last["exit_code"], 5, "{last}");
    assert_eq!(last["class"], "resource", "{last}");
    assert!(
        last["message"].as_str().unwrap().contains("File too large"),
        "{last}"
    );
    assert!(frames(&dir.join("out")).is_empty());
}

/// No GPU here (the Vulkan loader pointed at no driver): `--device gpu` is a resource
/// failure, 5, since another machine may have one; the frame is not written.
#[cfg(feature = "gpu")]
#[test]
fn no_gpu_adapter_is_a_resource_failure_5() {
    let dir = temp_dir("exit-5-gpu");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.#.exr");
    let mut args = render_args(&scene, &out, "0");
    args.extend(["--device", "gpu"]);
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(&args)
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .output()
        .unwrap();
    assert_eq!(code(&o), Some(5), "{}", stderr(&o));
    assert!(stderr(&o).contains("no GPU adapter"), "{}", stderr(&o));
    assert!(frames(&dir.join("out")).is_empty());
}

/// SIGTERM (a farm stopping a task) and SIGINT (Ctrl-C) stop the render after the frame
/// in flight with 143 and 130; the frames written are whole (each is the frame of an
/// uninterrupted run, byte for byte), and the JSON log ends with an `interrupted` event
/// that says as much.
#[test]
fn a_stopping_signal_exits_with_128_plus_it_and_keeps_whole_frames() {
    let dir = temp_dir("exit-signal");
    let scene = write_scene(&dir);
    let full = dir.join("full/f.##.exr");
    let mut args = render_args(&scene, &full, "0..40");
    args.extend(["--spp", "4"]);
    let o = subfield(&args);
    assert_eq!(code(&o), Some(0), "{}", stderr(&o));
    let want = frames(&dir.join("full"));
    for (signal, exit) in [("TERM", 143), ("INT", 130)] {
        let part = dir.join(format!("part-{signal}"));
        let out = part.join("f.##.exr");
        let mut args = render_args(&scene, &out, "0..40");
        args.extend(["--log-format", "json", "--spp", "4"]);
        let mut child = Command::new(env!("CARGO_BIN_EXE_subfield"))
            .args(&args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let t = Instant::now();
        while frames(&part).is_empty() {
            assert!(t.elapsed() < Duration::from_secs(120), "no frame written");
            assert!(child.try_wait().unwrap().is_none(), "ended before frame 0");
            std::thread::sleep(Duration::from_millis(2));
        }
        let sent = Command::new("kill")
            .args([format!("-{signal}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(sent.success());
        let o = child.wait_with_output().unwrap();
        assert_eq!(code(&o), Some(exit), "SIG{signal}: {}", stderr(&o));
        let got = frames(&part);
        assert!(!got.is_empty() && got.len() < 40, "{}", got.len());
        for (name, bytes) in &got {
            let (_, b) = want.iter().find(|(n, _)| n == name).unwrap();
            assert!(
                bytes == b,
                "SIG{signal}: {name} differs from the uninterrupted run's"
            );
        }
        // Every line an event, the signal's own (written by its handler) among them; the
        // last, the interruption with the code the process exits with.
        let ev = events(&o);
        assert!(
            ev.iter()
                .any(|e| e["event"] == "signal" && e["signal"] == format!("SIG{signal}")),
            "{}",
            stderr(&o)
        );
        let last = ev.last().unwrap();
        assert_eq!(last["event"], "interrupted", "{last}");
        assert_eq!(last["exit_code"], exit, "{last}");
        assert_eq!(last["written"], got.len(), "{last}");
    }
}

/// `--log-format json`: every stderr line is a JSON object; the start names the options
/// and the frames, each frame event's hash is the content hash of the file on disk, a
/// skipped frame says so, and the end counts both.
#[test]
fn the_json_log_is_one_object_a_line_and_its_hashes_are_the_files() {
    let dir = temp_dir("json-log");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.##.exr");
    let mut args = render_args(&scene, &out, "0..3");
    args.retain(|a| *a != "--quiet");
    args.extend(["--log-format", "json"]);
    let o = subfield(&args);
    assert_eq!(code(&o), Some(0), "{}", stderr(&o));
    let ev = events(&o);
    let start = ev.iter().find(|e| e["event"] == "start").unwrap();
    assert_eq!(start["frames"], serde_json::json!([0, 1, 2]), "{start}");
    assert!(
        start["options"].as_str().unwrap().contains("spp"),
        "{start}"
    );
    assert_eq!(start["device"], "cpu", "{start}");
    let frame_events: Vec<&Value> = ev.iter().filter(|e| e["event"] == "frame").collect();
    assert_eq!(frame_events.len(), 3);
    for f in &frame_events {
        let path = Path::new(f["path"].as_str().unwrap());
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(
            f["hash"].as_str().unwrap(),
            subfield::format::ContentHash::of(&bytes).to_string(),
            "{f}"
        );
        assert!(f["times_ms"]["trace"].as_f64().unwrap() >= 0.0, "{f}");
        assert!(f["rays"]["primary"].as_u64().unwrap() >= 48 * 36, "{f}");
        assert!(f["peak_memory_bytes"].as_u64().unwrap() > 1 << 20, "{f}");
        assert!(
            ["none", "fill", "reuse"].contains(&f["kept"].as_str().unwrap()),
            "{f}"
        );
    }
    let end = ev.last().unwrap();
    assert_eq!(end["event"], "end", "{end}");
    assert_eq!(end["rendered"], 3, "{end}");
    // Resumed over one more frame: three skipped (with their hashes), one rendered.
    let mut again = render_args(&scene, &out, "0..4");
    again.extend(["--log-format", "json", "--resume"]);
    let o = subfield(&again);
    assert_eq!(code(&o), Some(0), "{}", stderr(&o));
    let ev = events(&o);
    let skipped = ev
        .iter()
        .filter(|e| e["event"] == "frame" && e["skipped"] == true)
        .count();
    assert_eq!(skipped, 3);
    let end = ev.last().unwrap();
    assert_eq!(
        (end["rendered"].clone(), end["skipped"].clone()),
        (1.into(), 3.into())
    );
    // A bad input in JSON: one error event with its class, nothing else on stderr.
    let mut bad = render_args(&scene, &out, "0");
    bad.extend(["--log-format", "json", "--spp", "0"]);
    let o = subfield(&bad);
    assert_eq!(code(&o), Some(3));
    let ev = events(&o);
    assert_eq!(ev.len(), 1, "{}", stderr(&o));
    assert_eq!(ev[0]["class"], "bad-input");
}

/// `--progress openjd` prints the lines Open Job Description reads on stdout: progress
/// after each frame up to 100, the frame in the status, and `openjd_fail:` on error.
#[test]
fn openjd_progress_lines_on_stdout() {
    let dir = temp_dir("openjd-lines");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.##.exr");
    let mut args = render_args(&scene, &out, "0..4");
    args.extend(["--progress", "openjd"]);
    let o = subfield(&args);
    assert_eq!(code(&o), Some(0), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let progress: Vec<f64> = text
        .lines()
        .filter_map(|l| l.strip_prefix("openjd_progress: "))
        .map(|p| p.parse().unwrap())
        .collect();
    assert_eq!(progress, [25.0, 50.0, 75.0, 100.0], "{text}");
    assert!(
        text.contains("openjd_status: frame 4 of 4 (number 3)"),
        "{text}"
    );
    // Without the flag or the environment, none of them.
    let plain = subfield(&render_args(&scene, &dir.join("plain/f.##.exr"), "0..2"));
    assert!(!String::from_utf8_lossy(&plain.stdout).contains("openjd_"));
    // Under an Open Job Description session (its variable set), and on error.
    let mut bad = render_args(&scene, &out, "0");
    bad.extend(["--spp", "0"]);
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(&bad)
        .env("OPENJD_SESSION_WORKING_DIR", s(&dir))
        .output()
        .unwrap();
    assert_eq!(code(&o), Some(3));
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let fail = text
        .lines()
        .find_map(|l| l.strip_prefix("openjd_fail: "))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(fail.contains("--spp 0"), "{fail}");
}

/// A long sequence's `start` event says its frames as `frame_set` and `frame_count` and
/// leaves the list out beyond 10,000 (it was one line of 79 MB for 10 million frames).
#[test]
fn the_json_start_of_a_long_sequence_does_not_list_every_frame() {
    use std::io::BufRead;
    let dir = temp_dir("json-long");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.######.exr");
    let mut args = render_args(&scene, &out, "0..20000");
    args.retain(|a| *a != "--quiet");
    args.extend(["--log-format", "json"]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(&args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let start = loop {
        let line = lines.next().expect("no start event").unwrap();
        let v: Value = serde_json::from_str(&line).unwrap();
        if v["event"] == "start" {
            break v;
        }
    };
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(start["frame_set"], "0..20000", "{start}");
    assert_eq!(start["frame_count"], 20000, "{start}");
    assert!(start.get("frames").is_none(), "{start}");
}
