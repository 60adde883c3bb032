//! Options a render leaves unused or cannot use in full are said, once, before it
//! starts (a contract audit found them silently ignored); and `--threads` has a bound.

mod common;

use common::farm::{s, stderr, subfield};
use common::render_scene::{temp_dir, write_scene};

#[test]
fn options_that_do_nothing_are_warned_and_too_many_threads_refused() {
    let dir = temp_dir("cli-options");
    let scene = write_scene(&dir);
    let out = dir.join("o/f.#.exr");
    let base = [
        "render",
        s(&scene),
        "-o",
        s(&out),
        "--frames",
        "0",
        "--size",
        "8x6",
    ];
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let many = (2 * cores).to_string();
    let mut args = base.to_vec();
    args.extend([
        "--shutter",
        "0",
        "--motion-steps",
        "3",
        "--crypto-levels",
        "4",
        "--threads",
        &many,
    ]);
    let o = subfield(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    for want in [
        "warning: --motion-steps 3 does nothing with --shutter 0",
        "warning: --crypto-levels 4 does nothing without --aov cryptomatte",
        &format!("warning: --threads {many} is more than the {cores} cores"),
    ] {
        assert_eq!(err.matches(want).count(), 1, "{want:?} in {err}");
    }
    // Used as given: no warning.
    let mut args = base.to_vec();
    args.extend(["--shutter", "0.5", "--motion-steps", "3", "--threads", "1"]);
    args.extend(["--aov", "cryptomatte", "--crypto-levels", "4"]);
    let o = subfield(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
    // Past the bound: one line, exit 3, nothing written.
    let dir2 = dir.join("refused");
    let out2 = dir2.join("f.#.exr");
    let o = subfield(&["render", s(&scene), "-o", s(&out2), "--threads", "5000"]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--threads 5000: at most 1024"),
        "{}",
        stderr(&o)
    );
    assert!(!dir2.exists());
    let o = subfield(&[
        "bake",
        s(&scene),
        "-o",
        s(&dir2.join("b.psf")),
        "--threads",
        "5000",
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
}

#[test]
fn generate_refuses_an_output_it_would_misname_and_says_its_minimum() {
    let dir = temp_dir("cli-generate");
    for (args, ok) in [
        (vec!["generate", "museum", "-o", "m.obj"], false),
        (vec!["generate", "museum", "-o", "m.GLB"], true),
        (vec!["generate", "animart", "-o", "a.txt"], false),
        (
            vec!["generate", "animart", "-o", "a.aff", "--triangles", "20"],
            true,
        ),
    ] {
        let mut args = args.clone();
        let out = dir.join(args[3]);
        args[3] = s(&out);
        let o = subfield(&args);
        if ok {
            assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        } else {
            assert_eq!(o.status.code(), Some(3), "{args:?}: {}", stderr(&o));
            assert!(
                stderr(&o).contains("give a file ending in"),
                "{}",
                stderr(&o)
            );
            assert!(!out.exists());
        }
    }
    let o = subfield(&["generate", "museum", "--help"]);
    let help = String::from_utf8_lossy(&o.stdout).replace('\n', " ");
    let least = format!("at least {}", subfield::gen::museum::MIN_STATIC_TRIS);
    assert!(help.contains(&least), "{least:?} in {help}");
}

#[test]
fn a_file_where_an_output_folder_should_be_is_bad_input_named() {
    let dir = temp_dir("cli-folder");
    let scene = write_scene(&dir);
    let file = dir.join("file");
    std::fs::write(&file, b"x").unwrap();
    let out = file.join("sub/f.#.exr");
    let psf = file.join("b.psf");
    for args in [
        vec![
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "0",
            "--size",
            "8x6",
        ],
        vec!["bake", s(&scene), "-o", s(&psf)],
    ] {
        let o = subfield(&args);
        assert_eq!(o.status.code(), Some(3), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.contains(&format!("{} is a file", file.display())),
            "{err}"
        );
        assert!(!err.contains("File exists"), "{err}");
    }
}

#[test]
fn a_scene_of_a_format_not_read_says_which_are() {
    let dir = temp_dir("cli-format");
    let obj = dir.join("t.obj");
    std::fs::write(&obj, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let out = dir.join("o/f.#.exr");
    let o = subfield(&["render", s(&obj), "-o", s(&out), "--frames", "0"]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("a .obj file, which subfield does not read"),
        "{err}"
    );
    assert!(err.contains(".gltf or .glb"), "{err}");
    // A GLB under another name is still read by its bytes.
    let scene = write_scene(&dir);
    let renamed = dir.join("scene.bin");
    std::fs::copy(&scene, &renamed).unwrap();
    let o = subfield(&[
        "render",
        s(&renamed),
        "-o",
        s(&out),
        "--frames",
        "0",
        "--size",
        "8x6",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn a_shard_that_holds_no_frame_says_why() {
    let dir = temp_dir("cli-shard");
    let scene = write_scene(&dir);
    let out = dir.join("o/f.##.exr");
    let run = |shard: &str| {
        subfield(&[
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "1..10:2",
            "--shard",
            shard,
            "--size",
            "8x6",
        ])
    };
    // Frames 1, 3, 5, 7, 9 are all odd: shard 0 of 2 has none of them.
    let o = run("0/2");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: --shard 0/2 holds none of the frames 1..10:2"),
        "{}",
        stderr(&o)
    );
    let o = run("1/2");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("holds none"), "{}", stderr(&o));
}
