//! The farm's pieces that need no scheduler: content hashes printed and checked, the
//! node-local stage, a raw bake cut short under a render, two hosts sharing an output
//! folder, `submit`'s refusals, and an Open Job Description template run by `openjd`.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use common::farm::{frames, need, ok, on_path, s, stderr, subfield, temporaries};
use common::render_scene::{temp_dir, write_scene};

const SIZE: &str = "40x30";

fn bake(scene: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["bake", s(scene), "-o", s(out), "--quiet"];
    args.extend_from_slice(extra);
    let o = ok(&args);
    String::from_utf8(o.stdout).unwrap().trim().to_string()
}

#[test]
fn bake_prints_the_content_hash_inspect_reports_and_the_bytes_give() {
    let dir = temp_dir("farm-hash");
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    let printed = bake(&scene, &psf, &[]);
    assert_eq!(printed.len(), 32, "{printed:?}");
    let bytes = std::fs::read(&psf).unwrap();
    assert_eq!(
        printed,
        subfield::format::ContentHash::of(&bytes).to_string()
    );
    let json: serde_json::Value =
        serde_json::from_slice(&ok(&["inspect", s(&psf), "--json"]).stdout).unwrap();
    assert_eq!(json["content_hash"], printed.as_str());
    let text = String::from_utf8(ok(&["inspect", s(&psf)]).stdout).unwrap();
    assert!(text.contains(&format!("content hash {printed}")), "{text}");
    // Another bake of the same scene: the same bytes, so the same hash.
    assert_eq!(bake(&scene, &dir.join("again.psf"), &[]), printed);
    assert_ne!(
        bake(&scene, &dir.join("raw.psf"), &["--codec", "none"]),
        printed
    );
}

#[test]
fn a_render_refuses_a_bake_or_scene_file_of_another_hash_and_writes_nothing() {
    let dir = temp_dir("farm-refuse");
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    let good = bake(&scene, &psf, &[]);
    let wrong = "0123456789abcdef0123456789abcdef";
    let out = dir.join("out/f.##.exr");
    let stage = dir.join("stage");
    for (flag, named) in [
        ("--baked-hash", "baked file"),
        ("--scene-file-hash", "scene file"),
    ] {
        let o = subfield(&[
            "render",
            s(&scene),
            "--baked",
            s(&psf),
            "-o",
            s(&out),
            "--frames",
            "0..2",
            "--size",
            SIZE,
            "--stage-dir",
            s(&stage),
            flag,
            wrong,
        ]);
        let e = stderr(&o);
        assert!(!o.status.success());
        assert_eq!(e.lines().count(), 1, "{e}");
        assert!(e.contains(named) && e.contains(wrong), "{e}");
        assert!(!dir.join("out").exists(), "{flag}: wrote output");
    }
    // The right hash goes through; the stage then holds the bake under its hash.
    let bad_hash = subfield(&[
        "render",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&out),
        "--baked-hash",
        "xyz",
    ]);
    assert!(
        stderr(&bad_hash).contains("is not a content hash"),
        "{}",
        stderr(&bad_hash)
    );
    ok(&[
        "render",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&out),
        "--frames",
        "0..2",
        "--size",
        SIZE,
        "--stage-dir",
        s(&stage),
        "--baked-hash",
        &good,
        "--quiet",
    ]);
    assert!(stage.join(format!("{good}.psf")).is_file());
    assert_eq!(frames(&dir.join("out")).len(), 2);
}

#[test]
fn a_staged_render_equals_a_direct_one_and_a_damaged_cache_is_replaced() {
    let dir = temp_dir("farm-stage");
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    let hash = bake(&scene, &psf, &[]);
    let stage = dir.join("stage");
    let render = |sub: &str, staged: bool| {
        let out = dir.join(format!("{sub}/f.##.exr"));
        let mut args = vec![
            "render",
            s(&scene),
            "--baked",
            s(&psf),
            "-o",
            s(&out),
            "--frames",
            "0..4",
            "--size",
            SIZE,
            "--quiet",
        ];
        if staged {
            args.extend(["--baked-hash", &hash, "--stage-dir", s(&stage)]);
        }
        ok(&args);
        frames(&dir.join(sub))
    };
    let direct = render("direct", false);
    assert_eq!(direct.len(), 4);
    assert_eq!(render("staged", true), direct);
    let cached = stage.join(format!("{hash}.psf"));
    assert_eq!(
        std::fs::read(&cached).unwrap(),
        std::fs::read(&psf).unwrap()
    );
    // The right name, the wrong bytes: replaced before use, the frames unchanged.
    std::fs::remove_file(&cached).unwrap();
    std::fs::write(&cached, b"not the bake").unwrap();
    assert_eq!(render("again", true), direct);
    assert_eq!(
        std::fs::read(&cached).unwrap(),
        std::fs::read(&psf).unwrap()
    );
    assert!(temporaries(&stage).is_empty());
}

#[test]
fn a_raw_bake_truncated_under_a_render_ends_it_with_one_line_not_a_signal() {
    let dir = temp_dir("farm-sigbus");
    let scene = write_scene(&dir);
    let psf = dir.join("raw.psf");
    bake(&scene, &psf, &["--codec", "none"]);
    let out = dir.join("out/f.#####.exr");
    let child = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args([
            "render",
            s(&scene),
            "--baked",
            s(&psf),
            "-o",
            s(&out),
            "--frames",
            "0..20000",
            "--fps",
            "20000",
            // Enough camera rays for a point grid, which the moving camera's frames build
            // anew from the mapped triangles: a render reads the file after its first
            // frame. (At 16x12 every static query goes through the box tree, whose copy
            // is made before the first frame: such a render never reads the file again
            // and finishes with the right frames.)
            "--size",
            "32x24",
            "--quiet",
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Once it is under way, cut the file in place, as `cp other.psf raw.psf` would.
    let t0 = std::time::Instant::now();
    while frames(&dir.join("out")).is_empty() && t0.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    std::fs::File::create(&psf).unwrap();
    let o = child.wait_with_output().unwrap();
    let e = stderr(&o);
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(o.status.signal(), None, "killed by a signal: {e}");
    // An I/O failure (DESIGN.md §4): a retry maps the file anew.
    assert_eq!(o.status.code(), Some(5), "{e}");
    assert!(
        e.contains("raw.psf") && e.contains("truncated or overwritten"),
        "{e}"
    );
}

#[test]
fn hosts_sharing_an_output_folder_remove_only_their_own_dead_temporaries() {
    let dir = temp_dir("farm-hosts");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.##.exr");
    std::fs::create_dir_all(dir.join("out")).unwrap();
    // A pid above Linux's largest: dead on every host.
    let dead = 4_194_304 + 11;
    let a_tmp = dir.join(format!("out/.f.03.exr.{dead}-0-nodea.tmp"));
    let b_tmp = dir.join(format!("out/.f.03.exr.{dead}-0-nodeb.tmp"));
    // Node b's live writer: our own pid is alive here, but it is b's number, not ours.
    let b_live = dir.join(format!("out/.f.02.exr.{}-0-nodeb.tmp", std::process::id()));
    for p in [&a_tmp, &b_tmp, &b_live] {
        std::fs::write(p, b"half a frame").unwrap();
    }
    let run_as = |host: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
            .env("SUBFIELD_HOSTNAME", host)
            .args([
                "render",
                s(&scene),
                "-o",
                s(&out),
                "--frames",
                "0..4",
                "--size",
                SIZE,
                "--resume",
                "--quiet",
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    };
    run_as("nodea");
    assert!(!a_tmp.exists(), "node a's dead temporary is left");
    assert!(
        b_tmp.exists() && b_live.exists(),
        "node a removed node b's temporaries"
    );
    run_as("nodeb");
    assert!(!b_tmp.exists(), "node b's dead temporary is left");
    if Path::new("/proc/self").exists() {
        // Node b cannot see node a's processes, but this pid runs here, so b keeps it.
        assert!(b_live.exists());
    }
    assert_eq!(frames(&dir.join("out")).len(), 4);
}

#[test]
fn submit_refuses_bad_input_with_one_line_and_submits_nothing() {
    let dir = temp_dir("farm-submit-bad");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.##.exr");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["--tasks".into(), "0".into()], "--tasks 0"),
        (
            vec!["--cpus-per-task".into(), "0".into()],
            "--cpus-per-task 0",
        ),
        (vec!["--shard".into(), "0/2".into()], "--shard"),
        (
            vec!["--baked".into(), s(&dir.join("missing.psf")).into()],
            "missing.psf",
        ),
    ];
    for (extra, want) in cases {
        let mut args: Vec<String> = ["submit", "slurm", s(&scene), "-o", s(&out)]
            .iter()
            .map(|x| x.to_string())
            .collect();
        args.extend(extra);
        args.push("--dry-run".into());
        let refs: Vec<&str> = args.iter().map(|a| a.as_str()).collect();
        let o = subfield(&refs);
        let e = stderr(&o);
        assert!(!o.status.success(), "{refs:?}");
        assert_eq!(e.lines().count(), 1, "{refs:?}: {e}");
        assert!(e.contains(want), "{refs:?}: {e}");
        assert!(o.stdout.is_empty(), "{refs:?} printed a script");
    }
    // A scene that does not exist.
    let o = subfield(&[
        "submit",
        "slurm",
        s(&dir.join("nope.glb")),
        "-o",
        s(&out),
        "--dry-run",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("nope.glb"),
        "{}",
        stderr(&o)
    );
    // No sbatch on the PATH: one line, and no job files written.
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .env("PATH", "/nonexistent")
        .args(["submit", "slurm", s(&scene), "-o", s(&out)])
        .output()
        .unwrap();
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("sbatch is not on the PATH"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(!dir.join("out").exists(), "job files written");
}

#[test]
fn a_dry_run_prints_a_script_naming_both_hashes_and_the_missing_shards() {
    let dir = temp_dir("farm-dry");
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    let hash = bake(&scene, &psf, &[]);
    let out = dir.join("out/f.##.exr");
    // Frames 0..8 with 4 shards; shard 1's frames (1, 5) already rendered, with the
    // options of the submission (a frame made with others is not complete).
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&out),
        "--frames",
        "0..8",
        "--size",
        SIZE,
        "--look-from=-1,2,6",
        "--look-at",
        "0,0,0",
        "--shard",
        "1/4",
        "--quiet",
    ]);
    let o = ok(&[
        "submit",
        "slurm",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&out),
        "--frames",
        "0..8",
        "--size",
        SIZE,
        "--tasks",
        "4",
        "--look-from=-1,2,6",
        "--look-at",
        "0,0,0",
        "--frames-in-flight",
        "2",
        "--dry-run",
    ]);
    let script = String::from_utf8(o.stdout).unwrap();
    assert!(script.contains("#SBATCH --array=0,2-3\n"), "{script}");
    // Not an option of the pixels (the shards' frames above stay complete), but the
    // tasks render with it.
    assert!(script.contains("--frames-in-flight=2"), "{script}");
    assert!(script.contains(&format!("--baked-hash={hash}")), "{script}");
    let scene_hash = subfield::format::hash_file(&scene).unwrap().to_string();
    assert!(
        script.contains(&format!("--scene-file-hash={scene_hash}")),
        "{script}"
    );
    assert!(script.contains("--look-from=-1,2,6"), "{script}");
    assert!(
        script.contains("--shard \"${SLURM_ARRAY_TASK_ID}/4\""),
        "{script}"
    );
    // Nothing written by a dry run.
    assert!(!dir.join("out/f.slurm.sh").exists());

    // A frame list goes to every task as planned; tasks default to its frame count.
    let o = ok(&[
        "submit",
        "slurm",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("list/f.##.exr")),
        "--frames",
        "20..50:10, 3",
        "--size",
        SIZE,
        "--dry-run",
    ]);
    let script = String::from_utf8(o.stdout.clone()).unwrap();
    assert!(script.contains("--frames=20..50:10,3"), "{script}");
    // Frames 3, 20, 30, 40 by k % 4 would be shards 3, 0, 2, 0: one task of four with
    // nothing to do; by k % 6 they are 3, 2, 0, 4, a frame a task.
    assert!(
        script.contains("--shard \"${SLURM_ARRAY_TASK_ID}/6\""),
        "{script}"
    );
    assert!(script.contains("#SBATCH --array=0,2-4\n"), "{script}");
    assert!(
        stderr(&o).contains("note: 4 tasks as 6 shards"),
        "{}",
        stderr(&o)
    );

    // Every other frame on two tasks: four shards, two of them with five frames each
    // (by k % 2 every frame was shard 0's); sbatch's own options named in the script.
    let o = ok(&[
        "submit",
        "slurm",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("step/f.##.exr")),
        "--frames",
        "0..20:2",
        "--size",
        SIZE,
        "--tasks",
        "2",
        "--dry-run",
        "--",
        "--mem=4G",
    ]);
    let script = String::from_utf8(o.stdout).unwrap();
    assert!(
        script.contains("--shard \"${SLURM_ARRAY_TASK_ID}/4\""),
        "{script}"
    );
    assert!(script.contains("#SBATCH --array=0,2\n"), "{script}");
    assert!(script.contains("(sbatch --mem=4G FILE)"), "{script}");
}

#[test]
fn an_openjd_template_run_by_openjd_gives_the_frames_of_a_local_render() {
    if !need(
        "an_openjd_template_run_by_openjd_gives_the_frames_of_a_local_render",
        on_path("openjd"),
        "openjd (pip install openjd-cli)",
    ) {
        return;
    }
    let dir = temp_dir("farm-openjd");
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    bake(&scene, &psf, &[]);
    let frames_of = |sub: &str| frames(&dir.join(sub));
    ok(&[
        "render",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("local/f.##.exr")),
        "--frames",
        "0..10",
        "--size",
        SIZE,
        "--quiet",
    ]);
    let job = dir.join("job/render.yaml");
    let stage = dir.join("stage");
    let farm_out = dir.join("farm/f.##.exr");
    let submit = |extra: &[&str]| {
        let mut args = vec![
            "submit",
            "openjd",
            s(&scene),
            "--baked",
            s(&psf),
            "-o",
            s(&farm_out),
            "--frames",
            "0..10",
            "--size",
            SIZE,
            "--template",
            s(&job),
        ];
        args.extend_from_slice(extra);
        ok(&args)
    };
    submit(&["--chunk", "4", "--stage-dir", s(&stage), "--quiet"]);
    let text = std::fs::read_to_string(&job).unwrap();
    assert!(
        text.contains("\"0..4\"") && text.contains("\"8..10\""),
        "{text}"
    );
    let run = Command::new("openjd")
        .arg("run")
        .arg(&job)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "openjd run failed: {}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    // The tasks saw OPENJD_SESSION_WORKING_DIR and printed the progress lines openjd
    // reads: each chunk reaches 100 %, and the status names the frame.
    let log = String::from_utf8_lossy(&run.stdout);
    assert_eq!(log.matches("openjd_progress: 100.0").count(), 3, "{log}");
    assert!(
        log.contains("openjd_status: frame 2 of 2 (number 9)"),
        "{log}"
    );
    assert_eq!(frames_of("farm"), frames_of("local"));
    assert_eq!(frames_of("farm").len(), 10);
    assert!(temporaries(&dir.join("farm")).is_empty());
    // Everything is there: writing the template again has nothing to do.
    let again = submit(&[]);
    assert!(
        stderr(&again).contains("nothing to submit"),
        "{}",
        stderr(&again)
    );
}

/// `openjd` with its arguments; the output when it succeeds.
fn openjd(args: &[&str]) -> Output {
    let o = Command::new("openjd").args(args).output().unwrap();
    assert!(
        o.status.success(),
        "openjd {args:?} failed: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// The `parameterValues` of a bundle's `parameter_values.yaml` as the JSON map `openjd
/// run --job-param` takes (our YAML quotes every value as a JSON string).
fn bundle_params(bundle: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(bundle.join("parameter_values.yaml")).unwrap();
    let mut map = serde_json::Map::new();
    let mut name = None;
    for l in text.lines() {
        if let Some(n) = l.strip_prefix("- name: ") {
            name = Some(n.to_string());
        } else if let Some(v) = l.strip_prefix("  value: ") {
            let v: serde_json::Value = serde_json::from_str(v).unwrap();
            map.insert(name.take().unwrap(), v);
        }
    }
    serde_json::Value::Object(map)
}

/// Issue 40: a Deadline Cloud job bundle. `openjd check` accepts its template (PATH job
/// parameters with their data flow, a CHUNK[INT] frame parameter of the TASK_CHUNKING
/// extension); `openjd run` with its parameter values renders the frames of a local
/// render, and so does a run whose path-mapping rules move the scene, the bake and the
/// output to other folders (as a farm's workers see them).
#[test]
fn a_job_bundle_runs_under_openjd_with_and_without_path_mapping() {
    if !need(
        "a_job_bundle_runs_under_openjd_with_and_without_path_mapping",
        on_path("openjd"),
        "openjd (pip install openjd-cli)",
    ) {
        return;
    }
    let dir = temp_dir("farm-bundle");
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    let scene = write_scene(&input);
    let psf = input.join("scene.psf");
    bake(&scene, &psf, &[]);
    ok(&[
        "render",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("local/f.##.exr")),
        "--frames",
        "0..6",
        "--size",
        SIZE,
        "--quiet",
    ]);
    let bundle = dir.join("bundle");
    ok(&[
        "submit",
        "openjd",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("out/f.##.exr")),
        "--frames",
        "0..6",
        "--size",
        SIZE,
        "--bundle",
        s(&bundle),
        "--frame-seconds",
        "0.5",
        "--chunk-seconds",
        "2",
        "--stage-dir",
        s(&dir.join("stage")),
        "--quiet",
    ]);
    let template = bundle.join("template.yaml");
    let text = std::fs::read_to_string(&template).unwrap();
    for want in [
        "- TASK_CHUNKING\n",
        "type: CHUNK[INT]\n",
        "range: \"0-5\"\n",
        "defaultTaskCount: 4\n",
        "targetRuntimeSeconds: 2\n",
        "rangeConstraint: CONTIGUOUS\n",
        "dataFlow: OUT\n",
    ] {
        assert!(text.contains(want), "{want:?} not in\n{text}");
    }
    assert!(!text.contains("amount.worker.gpu"), "{text}");
    let assets = std::fs::read_to_string(bundle.join("asset_references.yaml")).unwrap();
    assert!(
        assets.contains(s(&psf)) && assets.contains(s(&dir.join("out"))),
        "{assets}"
    );
    openjd(&["check", s(&template)]);
    let params = bundle_params(&bundle);
    assert_eq!(params["SceneFile"], s(&scene));
    let params_file = dir.join("params.json");
    std::fs::write(&params_file, params.to_string()).unwrap();
    let job_param = format!("file://{}", params_file.display());

    // The inputs moved, and the output folder elsewhere: path mapping finds them.
    let moved = dir.join("moved");
    std::fs::create_dir_all(moved.join("in")).unwrap();
    for f in ["scene.glb", "scene.psf"] {
        std::fs::rename(input.join(f), moved.join("in").join(f)).unwrap();
    }
    let rules = serde_json::json!({
        "version": "pathmapping-1.0",
        "path_mapping_rules": [
            {"source_path_format": "POSIX", "source_path": s(&input), "destination_path": s(&moved.join("in"))},
            {"source_path_format": "POSIX", "source_path": s(&dir.join("out")), "destination_path": s(&moved.join("out"))},
        ],
    });
    let rules_file = dir.join("rules.json");
    std::fs::write(&rules_file, rules.to_string()).unwrap();
    openjd(&[
        "run",
        s(&template),
        "--job-param",
        &job_param,
        "--path-mapping-rules",
        &format!("file://{}", rules_file.display()),
    ]);
    assert!(!dir.join("out").exists());
    assert_eq!(frames(&moved.join("out")), frames(&dir.join("local")));
    assert_eq!(frames(&moved.join("out")).len(), 6);

    // Back where the parameter values say: the plain run.
    for f in ["scene.glb", "scene.psf"] {
        std::fs::rename(moved.join("in").join(f), input.join(f)).unwrap();
    }
    let run = openjd(&["run", s(&template), "--job-param", &job_param]);
    let log = String::from_utf8_lossy(&run.stdout);
    assert!(log.contains("openjd_progress: 100.0"), "{log}");
    assert_eq!(frames(&dir.join("out")), frames(&dir.join("local")));
    assert!(temporaries(&dir.join("out")).is_empty());

    // --measure renders the first missing frame here (the local render's bytes), times
    // it, and leaves the rest to the bundle, in chunks filling the default 600 s.
    let bundle2 = dir.join("bundle2");
    let o = ok(&[
        "submit",
        "openjd",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("measured/f.##.exr")),
        "--frames",
        "0..6",
        "--size",
        SIZE,
        "--bundle",
        s(&bundle2),
        "--measure",
    ]);
    assert!(
        stderr(&o).contains("rendered frame 0 here to measure it"),
        "{}",
        stderr(&o)
    );
    let text = std::fs::read_to_string(bundle2.join("template.yaml")).unwrap();
    assert!(text.contains("range: \"1-5\"\n"), "{text}");
    assert!(text.contains("targetRuntimeSeconds: 600\n"), "{text}");
    assert_eq!(
        frames(&dir.join("measured")),
        frames(&dir.join("local"))[..1].to_vec()
    );
}

/// Issue 37: GPUs asked of the farm. `submit slurm --gpus-per-task N` asks Slurm for
/// them (`--gres=gpu:N`) and renders with `--device gpu`; `submit openjd --device gpu`
/// states a GPU as a host requirement in the template and in the bundle's, which
/// `openjd check` accepts. Nothing here renders, so no GPU is needed.
#[test]
fn gpu_jobs_ask_the_farm_for_gpus() {
    let dir = temp_dir("farm-gpu");
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    bake(&scene, &psf, &[]);
    let common = |out: &str| -> Vec<String> {
        [
            s(&scene),
            "--baked",
            s(&psf),
            "-o",
            s(&dir.join(out).join("f.##.exr")),
            "--frames",
            "0..4",
            "--size",
            SIZE,
            "--quiet",
        ]
        .iter()
        .map(|x| x.to_string())
        .collect()
    };
    let mut args = vec!["submit".to_string(), "slurm".into()];
    args.extend(common("slurm"));
    args.extend(["--gpus-per-task".into(), "2".into(), "--dry-run".into()]);
    let o = ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let script = String::from_utf8(o.stdout).unwrap();
    assert!(script.contains("#SBATCH --gres=gpu:2\n"), "{script}");
    assert!(script.contains("--device=gpu"), "{script}");
    // Without GPUs asked for, neither.
    let mut args = vec!["submit".to_string(), "slurm".into()];
    args.extend(common("slurm"));
    args.push("--dry-run".into());
    let o = ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let script = String::from_utf8(o.stdout).unwrap();
    assert!(
        !script.contains("gres") && !script.contains("--device"),
        "{script}"
    );

    let template = dir.join("job.yaml");
    let bundle = dir.join("bundle");
    let mut args = vec!["submit".to_string(), "openjd".into()];
    args.extend(common("openjd"));
    args.extend([
        "--device".into(),
        "gpu".into(),
        "--template".into(),
        s(&template).into(),
        "--bundle".into(),
        s(&bundle).into(),
    ]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    for t in [template, bundle.join("template.yaml")] {
        let text = std::fs::read_to_string(&t).unwrap();
        assert!(
            text.contains(
                "hostRequirements:\n    amounts:\n    - name: amount.worker.gpu\n      min: 1\n"
            ),
            "{text}"
        );
        assert!(text.contains("--device=gpu"), "{text}");
        if on_path("openjd") {
            let o = Command::new("openjd")
                .arg("check")
                .arg(&t)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        }
    }
}
