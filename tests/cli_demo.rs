//! `subfield demo` end to end at a small size: the scene, the baked file, the frames,
//! the preview, the stats and the plot are all written, and the frames are the ones a
//! plain `subfield render` of the written scene gives from the same baked file.

use std::path::PathBuf;
use std::process::Command;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir()
        .join(format!("subfield-cli-demo-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn subfield(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args)
        .output()
        .expect("run subfield")
}

#[test]
fn demo_writes_everything_and_matches_render() {
    let dir = temp_dir("demo");
    let d = dir.to_str().unwrap();
    // Three frames at once: the bytes of `render` one at a time (below).
    let r = subfield(&[
        "demo",
        "-o",
        d,
        "--frames",
        "10..13",
        "--size",
        "64x48",
        "--frames-in-flight",
        "3",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    for f in [
        "museum.glb",
        "museum.psf",
        "frame.0010.exr",
        "frame.0011.exr",
        "frame.0012.exr",
        "preview.png",
        "stats.csv",
        "plot.svg",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    assert!(!dir.join("frame.0013.exr").exists());
    let csv = std::fs::read_to_string(dir.join("stats.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    let png = image::open(dir.join("preview.png")).unwrap();
    assert_eq!((png.width(), png.height()), (64, 48));

    // The same frame through `render` from the written scene and baked file.
    let again = dir.join("again.####.exr");
    let r = subfield(&[
        "render",
        dir.join("museum.glb").to_str().unwrap(),
        "--baked",
        dir.join("museum.psf").to_str().unwrap(),
        "-o",
        again.to_str().unwrap(),
        "--frames",
        "11..12",
        "--size",
        "64x48",
        "--frames-in-flight",
        "1",
        "--quiet",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(
        std::fs::read(dir.join("frame.0011.exr")).unwrap()
            == std::fs::read(dir.join("again.0011.exr")).unwrap(),
        "demo and render disagree on frame 11"
    );

    // Bad flags: one line, non-zero, nothing new written.
    let bad = temp_dir("bad");
    for flags in [["--frames", "5..2"], ["--frames-in-flight", "0"]] {
        let mut args = vec!["demo", "-o", bad.to_str().unwrap()];
        args.extend(flags);
        let r = subfield(&args);
        assert!(!r.status.success());
        let e = String::from_utf8_lossy(&r.stderr);
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        assert!(e.contains(flags[0]), "{e}");
        assert_eq!(std::fs::read_dir(&bad).unwrap().count(), 0);
    }
}
