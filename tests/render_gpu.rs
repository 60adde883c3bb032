//! `subfield render --device gpu` as a program: the frames equal `--device cpu`'s pixel
//! for pixel and channel for channel when shading stays on the CPU
//! (`SUBFIELD_GPU_SHADING=cpu`: the GPU's hits are the CPU's to the bit; the GPU frame
//! path's shading is held to a bound in tests/gpu_frames.rs), the header names the device so `--resume` re-renders frames
//! made on the other one, `auto` without a discrete GPU traces on the CPU and says so,
//! and `gpu` without any adapter fails in one line and writes nothing.
//!
//! Needs a GPU adapter (lavapipe in CI): tests/common/gpu.rs.

mod common;

use std::path::Path;
use std::process::Command;

use common::exr_read::read_exr;
use common::farm::{ok, ok_with, s};
use common::render_scene::{files_under, temp_dir, write_scene};

fn contains(hay: &[u8], needle: &str) -> bool {
    hay.windows(needle.len()).any(|w| w == needle.as_bytes())
}

/// Renders `scene`'s frames 2..5 at 40x30 on `device` into `dir/folder` with `extra`,
/// shading on the CPU (`SUBFIELD_GPU_SHADING=cpu`).
fn render_on(dir: &Path, scene: &Path, device: &str, folder: &str, extra: &[&str]) {
    let out = dir.join(format!("{folder}/f.##.exr"));
    let mut args = vec![
        "render",
        s(scene),
        "-o",
        s(&out),
        "--frames",
        "2..5",
        "--size",
        "40x30",
        "--device",
        device,
        "--quiet",
    ];
    args.extend_from_slice(extra);
    // Traced on the GPU, shaded on the CPU (the diagnostic switch, docs/GPU.md).
    ok_with(&args, &[("SUBFIELD_GPU_SHADING", "cpu")]);
}

/// Every frame in `dir/a` is channel for channel, bit for bit, the one in `dir/b`; how
/// many there are.
fn same_frames(dir: &Path, a: &str, b: &str, what: &str) -> usize {
    let frames = files_under(&dir.join(a));
    for f in &frames {
        let (wa, ha, ca) = read_exr(&dir.join(a).join(f));
        let (wb, hb, cb) = read_exr(&dir.join(b).join(f));
        assert_eq!((wa, ha), (wb, hb), "{what}");
        assert_eq!(ca.len(), cb.len(), "{what}");
        for ((na, va), (nb, vb)) in ca.iter().zip(&cb) {
            assert_eq!(na, nb, "{what}");
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(va),
                bits(vb),
                "{what}: {}: channel {na} differs",
                f.display()
            );
        }
    }
    frames.len()
}

#[test]
fn gpu_frames_equal_cpu_frames() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-vs-cpu");
    let scene = write_scene(&dir);
    let extra = [
        "--spp",
        "2",
        "--aov",
        "depth,normal,albedo,position,motion",
        "--float",
    ];
    render_on(&dir, &scene, "cpu", "cpu", &extra);
    render_on(&dir, &scene, "gpu", "gpu", &extra);
    assert_eq!(same_frames(&dir, "cpu", "gpu", "AOVs"), 3);
    for f in &files_under(&dir.join("cpu")) {
        // The header names the device that traced.
        assert!(contains(
            &std::fs::read(dir.join("cpu").join(f)).unwrap(),
            "device=cpu"
        ));
        assert!(contains(
            &std::fs::read(dir.join("gpu").join(f)).unwrap(),
            "device=gpu"
        ));
    }

    // --resume over the CPU's frames with --device gpu re-renders them (other options).
    let mut resumed = extra.to_vec();
    resumed.push("--resume");
    render_on(&dir, &scene, "gpu", "cpu", &resumed);
    for f in &files_under(&dir.join("cpu")) {
        let bytes = std::fs::read(dir.join("cpu").join(f)).unwrap();
        assert!(
            contains(&bytes, "device=gpu"),
            "{} not re-rendered",
            f.display()
        );
    }
}

/// The rest of the shading model with tracing on the GPU (an unused material keeps the
/// scene off the GPU frame path: shading on the CPU): motion blur, the light-path passes
/// and Cryptomatte, diffuse bounces, an environment map, overscan and exposure, glossy
/// sampling with several samples a pixel. The frames are the CPU's to the bit.
#[test]
fn every_shading_feature_renders_the_cpus_frames_with_gpu_tracing() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("gpu-features");
    let scene = write_scene(&dir);
    // A 4x2 Radiance map, flat scanlines (RGBE: these values are exact).
    let map = dir.join("sky.hdr");
    let mut hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n".to_vec();
    for k in 0..8u8 {
        hdr.extend_from_slice(&[64 + 16 * k, 128, 200 - 8 * k, 129]);
    }
    std::fs::write(&map, hdr).unwrap();
    let features: [(&str, Vec<&str>); 5] = [
        (
            "blur",
            vec!["--shutter", "0.5", "--motion-steps", "3", "--spp", "3"],
        ),
        (
            "passes",
            vec![
                "--aov",
                "diffuse,specular,transmission,emission,cryptomatte",
            ],
        ),
        ("bounces", vec!["--diffuse-bounces", "1", "--spp", "2"]),
        (
            "environment",
            vec!["--environment", s(&map), "--max-depth", "2"],
        ),
        (
            "overscan",
            vec!["--overscan", "3", "--exposure", "1.5", "--spp", "4"],
        ),
    ];
    for (name, extra) in &features {
        let (cpu, gpu) = (format!("{name}-cpu"), format!("{name}-gpu"));
        render_on(&dir, &scene, "cpu", &cpu, extra);
        render_on(&dir, &scene, "gpu", &gpu, extra);
        assert_eq!(same_frames(&dir, &cpu, &gpu, name), 3, "{name}");
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

/// `SUBFIELD_GPU_SHADING` takes `cpu` or `gpu`; anything else is one line naming it,
/// before anything is read or written.
#[test]
fn a_bad_gpu_shading_switch_is_one_line() {
    let dir = temp_dir("gpu-shading-switch");
    let scene = write_scene(&dir);
    let out = dir.join("f.#.exr");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(["render", s(&scene), "-o", s(&out), "--frames", "0"])
        .env("SUBFIELD_GPU_SHADING", "maybe")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("SUBFIELD_GPU_SHADING=maybe: expected cpu or gpu"),
        "{err}"
    );
    assert!(!dir.join("f.0.exr").exists());
}
