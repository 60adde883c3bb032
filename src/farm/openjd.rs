//! Open Job Description (the open specification behind AWS Deadline Cloud): the render
//! as a job template whose one step has a task per chunk of frames. Each task runs
//! `subfield render --frames A..B --resume` with the same staging as a Slurm task, from
//! an embedded bash script, so `openjd run JOB.yaml` or any farm that reads the
//! template renders it, and running it again renders only what is missing.

use std::fmt::Write as _;
use std::path::PathBuf;

use super::shell_quote;

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
}

/// A YAML scalar that needs no thought: a JSON string (YAML 1.2 is a superset of JSON,
/// and PyYAML reads these too).
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
        let _ = writeln!(t, "  script:");
        let _ = writeln!(t, "    embeddedFiles:");
        let _ = writeln!(t, "    - name: task");
        let _ = writeln!(t, "      type: TEXT");
        let _ = writeln!(t, "      runnable: true");
        let _ = writeln!(t, "      data: |");
        for line in self.task_script().lines() {
            let _ = writeln!(t, "        {line}");
        }
        let _ = writeln!(t, "    actions:");
        let _ = writeln!(t, "      onRun:");
        let _ = writeln!(t, "        command: \"{{{{Task.File.task}}}}\"");
        let _ = writeln!(t, "        args:");
        let _ = writeln!(t, "        - \"{{{{Task.Param.Frames}}}}\"");
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
        };
        let t = job.template();
        assert!(
            t.contains("      - \"0..8\"\n      - \"8..12\"\n      - \"20..40:10,47\"\n"),
            "{t}"
        );
        assert!(t.contains("specificationVersion: jobtemplate-2023-09\n"));
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
}
