//! `subfield render --device gpu` as a program: the frames equal `--device cpu`'s pixel
//! for pixel and channel for channel (the GPU's hits are the CPU's to the bit, and
//! shading is the CPU's), the header names the device so `--resume` re-renders frames
//! made on the other one, `auto` without a discrete GPU traces on the CPU and says so,
//! and `gpu` without any adapter fails in one line and writes nothing.
//!
//! Needs a GPU adapter (lavapipe in CI): tests/common/gpu.rs.

mod common;

use std::process::Command;

use common::exr_read::read_exr;
use common::farm::{ok, s};
use common::render_scene::{files_under, temp_dir, write_scene};

fn contains(hay: &[u8], needle: &str) -> bool {
    hay.windows(needle.len()).any(|w| w == needle.as_bytes())
}

#[test]
fn gpu_frames_equal_cpu_frames() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-vs-cpu");
    let scene = write_scene(&dir);
    // The same frames on `device` into `folder`, with `extra` flags.
    let render = |device: &str, folder: &str, extra: &[&str]| {
        let out = dir.join(format!("{folder}/f.##.exr"));
        let mut args = vec![
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "2..5",
            "--size",
            "40x30",
            "--spp",
            "2",
            "--aov",
            "depth,normal,albedo,position,motion",
            "--float",
            "--device",
            device,
            "--quiet",
        ];
        args.extend_from_slice(extra);
        ok(&args);
    };
    render("cpu", "cpu", &[]);
    render("gpu", "gpu", &[]);
    let frames = files_under(&dir.join("cpu"));
    assert_eq!(frames.len(), 3);
    for f in &frames {
        let (a, b) = (dir.join("cpu").join(f), dir.join("gpu").join(f));
        let (wa, ha, ca) = read_exr(&a);
        let (wb, hb, cb) = read_exr(&b);
        assert_eq!((wa, ha), (wb, hb));
        assert_eq!(ca.len(), cb.len());
        for ((na, va), (nb, vb)) in ca.iter().zip(&cb) {
            assert_eq!(na, nb);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(va), bits(vb), "{}: channel {na} differs", f.display());
        }
        // The header names the device that traced.
        assert!(contains(&std::fs::read(&a).unwrap(), "device=cpu"));
        assert!(contains(&std::fs::read(&b).unwrap(), "device=gpu"));
    }

    // --resume over the CPU's frames with --device gpu re-renders them (other options).
    render("gpu", "cpu", &["--resume"]);
    for f in &frames {
        let bytes = std::fs::read(dir.join("cpu").join(f)).unwrap();
        assert!(
            contains(&bytes, "device=gpu"),
            "{} not re-rendered",
            f.display()
        );
    }
}

#[test]
fn auto_without_a_discrete_gpu_traces_on_the_cpu() {
    let Some(dev) = common::gpu::device() else {
        return;
    };
    let dir = temp_dir("gpu-auto");
    let scene = write_scene(&dir);
    let out = dir.join("f.#.exr");
    let o = ok(&[
        "render",
        s(&scene),
        "-o",
        s(&out),
        "--frames",
        "0",
        "--size",
        "16x12",
        "--device",
        "auto",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    let want = if dev.is_discrete() {
        "tracing on: gpu"
    } else {
        "tracing on: cpu"
    };
    assert!(err.contains(want), "stderr: {err}");
}

/// No Vulkan driver to be found (the loader pointed at none): one line naming what was
/// looked for and how to install a driver, a failure status, no frame written.
#[test]
fn gpu_without_an_adapter_fails_in_one_line() {
    let dir = temp_dir("gpu-none");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.#.exr");
    // The Vulkan loader pointed at no driver.
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args([
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "0",
            "--device",
            "gpu",
        ])
        .env("VK_ICD_FILENAMES", "/nonexistent.json")
        .env("VK_DRIVER_FILES", "/nonexistent.json")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| !l.contains("XDG_RUNTIME_DIR"))
        .collect();
    assert_eq!(lines.len(), 1, "stderr: {err}");
    assert!(
        lines[0].contains("Vulkan adapter") && lines[0].contains("mesa-vulkan-drivers"),
        "stderr: {err}"
    );
    assert!(!dir.join("out").exists(), "something was written");
}

/// `subfield demo --device gpu` without an adapter fails in the same one line before it
/// writes its scene and bake: the folder it was given stays empty.
#[test]
fn demo_on_a_gpu_without_an_adapter_writes_nothing() {
    let dir = temp_dir("gpu-demo-none");
    let out = dir.join("demo");
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(["demo", "-o", s(&out), "--device", "gpu", "--frames", "0"])
        .env("VK_ICD_FILENAMES", "/nonexistent.json")
        .env("VK_DRIVER_FILES", "/nonexistent.json")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("Vulkan adapter"), "stderr: {err}");
    assert!(!out.exists(), "the demo wrote into {}", out.display());
}
