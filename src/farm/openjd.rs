//! Open Job Description (the open specification behind AWS Deadline Cloud): the render
//! as a job template whose one step has a task per chunk of frames. Each task runs
//! `subfield render --frames A..B --resume` with the same staging as a Slurm task, from
//! an embedded bash script, so `openjd run JOB.yaml` or any farm that reads the
//! template renders it, and running it again renders only what is missing.
//!
//! [`JobBundle`] is the same work as the folder AWS Deadline Cloud submits
//! (`deadline bundle submit DIR`): a template whose scene, bake and output folder are
//! `PATH` job parameters with their data flow (so the farm's job attachments carry them
//! and its path mapping moves them), frames as one `CHUNK[INT]` task parameter
//! (the `TASK_CHUNKING` extension: the scheduler cuts contiguous chunks and may size them
//! to a target run time), the parameter values, and the asset references.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::{shell_quote, FarmError};

/// A job template, ready to be written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OpenJdJob {
    pub name: String,
    /// One task per chunk, each as `--frames` spells it (`A..B`, B exclusive; or a list
    /// such as `0..40:10,47`).
    pub chunks: Vec<String>,
    /// The task's render command without `--frames` and `--stage-dir`.
    pub command: Vec<String>,
    /// The node-local stage; `None`: `$SUBFIELD_STAGE_DIR`, else `$TMPDIR/subfield-stage`.
    pub stage_dir: Option<PathBuf>,
    /// The render needs a GPU (`--device gpu`): stated as a host requirement.
    pub gpu: bool,
}

/// The step's host requirements when a task needs a GPU: at least one, in the amount
/// capability Open Job Description names for it (`amount.worker.gpu`).
fn gpu_requirement(t: &mut String) {
    let _ = writeln!(t, "  hostRequirements:");
    let _ = writeln!(t, "    amounts:");
    let _ = writeln!(t, "    - name: amount.worker.gpu");
    let _ = writeln!(t, "      min: 1");
}

/// A YAML scalar that needs no thought: a JSON string (YAML 1.2 is a superset of JSON,
/// and PyYAML reads these too).
/// A step's `script`: the task's bash script embedded as the file `task`, run with the
/// values `args` names (`{{Task.Param.Frames}}` …) as its arguments.
fn step_script(t: &mut String, script: &str, args: &[String]) {
    let _ = writeln!(t, "  script:");
    let _ = writeln!(t, "    embeddedFiles:");
    let _ = writeln!(t, "    - name: task");
    let _ = writeln!(t, "      type: TEXT");
    let _ = writeln!(t, "      runnable: true");
    let _ = writeln!(t, "      data: |");
    for line in script.lines() {
        let _ = writeln!(t, "        {line}");
    }
    let _ = writeln!(t, "    actions:");
    let _ = writeln!(t, "      onRun:");
    let _ = writeln!(t, "        command: \"{{{{Task.File.task}}}}\"");
    let _ = writeln!(t, "        args:");
    for a in args {
        let _ = writeln!(t, "        - \"{{{{{a}}}}}\"");
    }
}

fn yaml_str(s: &str) -> String {
    serde_json::Value::String(s.to_string()).to_string()
}

impl OpenJdJob {
    /// The template (`specificationVersion: jobtemplate-2023-09`).
    pub fn template(&self) -> String {
        let mut t = String::new();
        let _ = writeln!(
            t,
            "# Written by `subfield submit openjd` ({} {}): one task per chunk of frames,",
            env!("CARGO_PKG_NAME"),
            env!("CARGO_PKG_VERSION")
        );
        let _ = writeln!(
            t,
            "# each `subfield render --frames A..B --resume` from the bake staged by content hash."
        );
        let _ = writeln!(t, "# Run it locally with `openjd run THIS_FILE`.");
        let _ = writeln!(t, "specificationVersion: jobtemplate-2023-09");
        let _ = writeln!(t, "name: {}", yaml_str(&self.name));
        let _ = writeln!(t, "steps:");
        let _ = writeln!(t, "- name: render");
        let _ = writeln!(t, "  parameterSpace:");
        let _ = writeln!(t, "    taskParameterDefinitions:");
        let _ = writeln!(t, "    - name: Frames");
        let _ = writeln!(t, "      type: STRING");
        let _ = writeln!(t, "      range:");
        for c in &self.chunks {
            let _ = writeln!(t, "      - {}", yaml_str(c));
        }
        if self.gpu {
            gpu_requirement(&mut t);
        }
        step_script(&mut t, &self.task_script(), &["Task.Param.Frames".into()]);
        t
    }

    /// The bash script each task runs with its chunk as `$1`.
    fn task_script(&self) -> String {
        let mut s = String::from("#!/bin/bash\nset -eu\n");
        match &self.stage_dir {
            Some(d) => {
                let _ = writeln!(s, "stage={}", shell_quote(&d.to_string_lossy()));
            }
            None => s.push_str("stage=\"${SUBFIELD_STAGE_DIR:-${TMPDIR:-/tmp}/subfield-stage}\"\n"),
        }
        s.push_str("echo \"subfield: frames $1 on $(hostname)\"\nexec");
        for a in &self.command {
            s.push(' ');
            s.push_str(&shell_quote(a));
        }
        s.push_str(" --frames \"$1\" --stage-dir \"$stage\"\n");
        s
    }
}

/// The task parameter's name in a bundle's template: a chunk of frames, `A-B` or `A`.
const CHUNK_PARAM: &str = "Frames";

/// A Deadline Cloud job bundle (see the module's docs): the files `deadline bundle
/// submit` reads, and `openjd run` runs (`--job-param` from `parameter_values.yaml`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JobBundle {
    pub name: String,
    /// The frames to render, ascending, each once (those still missing).
    pub frames: Vec<u32>,
    /// Frames in a chunk until the scheduler has measured a task (`defaultTaskCount`).
    pub chunk: u32,
    /// The run time a chunk should take, seconds (`targetRuntimeSeconds`; the
    /// scheduler may then resize chunks); `None`: fixed chunks.
    pub target_seconds: Option<u32>,
    /// The `subfield` binary the tasks run.
    pub exe: String,
    /// The job parameters' values: the scene, the bake and the output folder.
    pub scene: PathBuf,
    pub baked: PathBuf,
    pub output_dir: PathBuf,
    /// The output pattern's file name (`frame.####.exr`), inside the output folder.
    pub pattern_name: String,
    /// The render's flags after the scene, the bake and the output (content hashes,
    /// `--resume`, the look), each one word.
    pub flags: Vec<String>,
    /// The node-local stage; `None`: `$SUBFIELD_STAGE_DIR`, else `$TMPDIR/subfield-stage`.
    pub stage_dir: Option<PathBuf>,
    pub gpu: bool,
}

impl JobBundle {
    /// The frames as an Open Job Description range expression (`0-9,12,20-23`).
    pub fn range_expr(&self) -> String {
        super::frame_runs(&self.frames)
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

    /// `template.yaml`.
    pub fn template(&self) -> String {
        let mut t = String::new();
        let _ = writeln!(
            t,
            "# Written by `subfield submit openjd --bundle` ({} {}): a Deadline Cloud job bundle",
            env!("CARGO_PKG_NAME"),
            env!("CARGO_PKG_VERSION")
        );
        let _ = writeln!(
            t,
            "# (`deadline bundle submit THIS_FOLDER`); locally: `openjd run template.yaml --job-param file://params.yaml`"
        );
        let _ = writeln!(t, "specificationVersion: jobtemplate-2023-09");
        let _ = writeln!(t, "extensions:");
        let _ = writeln!(t, "- TASK_CHUNKING");
        let _ = writeln!(t, "name: {}", yaml_str(&self.name));
        let _ = writeln!(t, "parameterDefinitions:");
        for (name, kind, flow, what) in [
            (
                "SceneFile",
                "FILE",
                "IN",
                "The scene (.glb, .gltf, .usd*, .aff, .nff)",
            ),
            (
                "BakedFile",
                "FILE",
                "IN",
                "The baked static part (.psf); tasks refuse any other bytes",
            ),
            (
                "OutputDir",
                "DIRECTORY",
                "OUT",
                "The folder the frames are written to",
            ),
        ] {
            let _ = writeln!(t, "- name: {name}");
            let _ = writeln!(t, "  type: PATH");
            let _ = writeln!(t, "  objectType: {kind}");
            let _ = writeln!(t, "  dataFlow: {flow}");
            let _ = writeln!(t, "  description: {}", yaml_str(what));
        }
        let _ = writeln!(t, "steps:");
        let _ = writeln!(t, "- name: render");
        let _ = writeln!(t, "  parameterSpace:");
        let _ = writeln!(t, "    taskParameterDefinitions:");
        let _ = writeln!(t, "    - name: {CHUNK_PARAM}");
        let _ = writeln!(t, "      type: CHUNK[INT]");
        let _ = writeln!(t, "      range: {}", yaml_str(&self.range_expr()));
        let _ = writeln!(t, "      chunks:");
        let _ = writeln!(t, "        defaultTaskCount: {}", self.chunk.max(1));
        if let Some(s) = self.target_seconds {
            let _ = writeln!(t, "        targetRuntimeSeconds: {s}");
        }
        // `--frames A..B` takes a run of frames: chunks must not have gaps.
        let _ = writeln!(t, "        rangeConstraint: CONTIGUOUS");
        if self.gpu {
            gpu_requirement(&mut t);
        }
        step_script(
            &mut t,
            &self.task_script(),
            &[
                format!("Task.Param.{CHUNK_PARAM}"),
                "Param.SceneFile".into(),
                "Param.BakedFile".into(),
                "Param.OutputDir".into(),
            ],
        );
        t
    }

    /// The bash script a task runs: `$1` its chunk (`A-B` or `A`), `$2` the scene, `$3`
    /// the bake, `$4` the output folder, as the farm mapped them.
    fn task_script(&self) -> String {
        let mut s = String::from("#!/bin/bash\nset -eu\n");
        match &self.stage_dir {
            Some(d) => {
                let _ = writeln!(s, "stage={}", shell_quote(&d.to_string_lossy()));
            }
            None => s.push_str("stage=\"${SUBFIELD_STAGE_DIR:-${TMPDIR:-/tmp}/subfield-stage}\"\n"),
        }
        // A chunk is an OpenJD range expression (`3-5`, `7`, `0-20:10,47`), inclusive;
        // `--frames` spells the same set `3..6`, `7`, `0..21:10,47`.
        s.push_str(concat!(
            "frames=\"\"\n",
            "IFS=, read -ra items <<< \"$1\"\n",
            "for it in \"${items[@]}\"; do\n",
            "  step=\"\"\n",
            "  case \"$it\" in *:*) step=\":${it#*:}\"; it=\"${it%%:*}\" ;; esac\n",
            "  case \"$it\" in *-*) it=\"${it%-*}..$(( ${it#*-} + 1 ))\" ;; esac\n",
            "  frames=\"${frames:+$frames,}$it$step\"\n",
            "done\n",
        ));
        s.push_str("echo \"subfield: frames $frames on $(hostname)\"\n");
        let _ = write!(
            s,
            "exec {} render \"$2\" --baked=\"$3\" --output=\"$4\"/{}",
            shell_quote(&self.exe),
            shell_quote(&self.pattern_name)
        );
        for a in &self.flags {
            s.push(' ');
            s.push_str(&shell_quote(a));
        }
        s.push_str(" --frames \"$frames\" --stage-dir \"$stage\"\n");
        s
    }

    /// `parameter_values.yaml`, as `deadline bundle submit` reads it.
    pub fn parameter_values(&self) -> String {
        let mut t = String::from("parameterValues:\n");
        for (name, path) in [
            ("SceneFile", &self.scene),
            ("BakedFile", &self.baked),
            ("OutputDir", &self.output_dir),
        ] {
            let _ = writeln!(t, "- name: {name}");
            let _ = writeln!(t, "  value: {}", yaml_str(&path.to_string_lossy()));
        }
        t
    }

    /// `asset_references.yaml`: what job attachments upload (the scene and the bake) and
    /// download (the output folder).
    pub fn asset_references(&self) -> String {
        let p = |p: &Path| yaml_str(&p.to_string_lossy());
        let mut t = String::from("assetReferences:\n  inputs:\n    filenames:\n");
        let _ = writeln!(t, "    - {}", p(&self.scene));
        let _ = writeln!(t, "    - {}", p(&self.baked));
        t.push_str("    directories: []\n  outputs:\n    directories:\n");
        let _ = writeln!(t, "    - {}", p(&self.output_dir));
        t.push_str("  referencedPaths: []\n");
        t
    }

    /// Writes the three files into `dir` (created), each atomically.
    pub fn write(&self, dir: &Path) -> Result<(), FarmError> {
        std::fs::create_dir_all(dir).map_err(|e| FarmError::io(dir, e))?;
        for (name, text) in [
            ("template.yaml", self.template()),
            ("parameter_values.yaml", self.parameter_values()),
            ("asset_references.yaml", self.asset_references()),
        ] {
            let path = dir.join(name);
            crate::atomic::write_atomically(&path, text.as_bytes())
                .map_err(|e| FarmError::io(&path, e))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn template_lists_the_chunks_and_embeds_a_valid_script() {
        let job = OpenJdJob {
            name: "subfield render frame".into(),
            chunks: vec!["0..8".into(), "8..12".into(), "20..40:10,47".into()],
            command: vec!["/opt/subfield".into(), "render".into(), "a b.glb".into()],
            stage_dir: Some("/scratch/stage".into()),
            gpu: true,
        };
        let t = job.template();
        assert!(
            t.contains("      - \"0..8\"\n      - \"8..12\"\n      - \"20..40:10,47\"\n"),
            "{t}"
        );
        assert!(t.contains("specificationVersion: jobtemplate-2023-09\n"));
        assert!(
            t.contains("    - name: amount.worker.gpu\n      min: 1\n"),
            "{t}"
        );
        let script = job.task_script();
        assert!(script.contains("'a b.glb' --frames \"$1\" --stage-dir \"$stage\""));
        assert!(script.contains("stage=/scratch/stage\n"));
        let ok = std::process::Command::new("bash")
            .arg("-n")
            .arg("-c")
            .arg(&script)
            .status()
            .unwrap();
        assert!(ok.success());
    }

    /// The task script turns each chunk the scheduler hands it into the `--frames` the
    /// render reads (run with a stand-in for the binary that prints its arguments).
    #[test]
    fn a_bundle_task_renders_its_chunk() {
        let b = JobBundle {
            name: "n".into(),
            frames: vec![0, 1, 2, 3, 7, 9, 10],
            chunk: 2,
            target_seconds: Some(60),
            exe: "echo".into(),
            scene: "/a/s.glb".into(),
            baked: "/a/s.psf".into(),
            output_dir: "/a/out".into(),
            pattern_name: "f.##.exr".into(),
            flags: vec!["--resume".into()],
            stage_dir: Some("/st".into()),
            gpu: false,
        };
        assert_eq!(b.range_expr(), "0-3,7,9-10");
        let t = b.template();
        assert!(t.contains("extensions:\n- TASK_CHUNKING\n"), "{t}");
        assert!(t.contains("targetRuntimeSeconds: 60\n"), "{t}");
        assert!(!t.contains("amount.worker.gpu"), "{t}");
        for (chunk, frames) in [
            ("3-5", "3..6"),
            ("7", "7"),
            ("10-10", "10..11"),
            ("0-20:10,47", "0..21:10,47"),
        ] {
            let out = std::process::Command::new("bash")
                .arg("-c")
                .arg(b.task_script())
                .args(["task", chunk, "/m/s.glb", "/m/s.psf", "/m/out"])
                .output()
                .unwrap();
            assert!(out.status.success());
            let said = String::from_utf8_lossy(&out.stdout);
            assert!(
                said.contains(&format!(
                    "render /m/s.glb --baked=/m/s.psf --output=/m/out/f.##.exr --resume --frames {frames} --stage-dir /st"
                )),
                "{chunk}: {said}"
            );
        }
    }
}
