//! `subfield bake` and `subfield inspect` end to end, on a scene written in code: the
//! file opens and traces like an in-memory bake, the split is reported, thread counts
//! give the same bytes, and bad input gives one line, a non-zero exit and no file.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::build::{linear, placed, soup_prim, SceneBuilder};
use glam::{Quat, Vec3};
use subfield::format::{open_psf, scene_hash, OpenOptions};
use subfield::gen::synth::{self, Rng};
use subfield::import;
use subfield::scene::{Animation, ClipSelection, Mesh, Node, Property};
use subfield::{Intersector, Psf, PsfParams, Ray};

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir()
        .join(format!("subfield-cli-bake-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn subfield(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args)
        .output()
        .expect("run subfield")
}

/// A room (static, 1 instance) and a spinning box (dynamic, 1 instance).
fn write_scene(path: &Path) {
    let mut b = SceneBuilder::new();
    let material = b.scene.default_material_index();
    let mesh = |tris: Vec<[Vec3; 3]>| Mesh {
        primitives: vec![soup_prim(tris.into_iter().flatten().collect(), material)],
        ..Default::default()
    };
    let mut rng = Rng::new(3);
    let room = b.add_mesh(mesh(synth::room(&mut rng, 2_000)));
    let cube = b.add_mesh(mesh(synth::box_faces(Vec3::splat(-0.5), Vec3::splat(0.5))));
    let n_room = b.add_node(Node {
        mesh: Some(room),
        ..Default::default()
    });
    let n_cube = b.add_node(Node {
        mesh: Some(cube),
        transform: placed(Vec3::new(0.0, 2.0, 0.0), Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(n_room);
    b.add_root(n_cube);
    let q = Quat::from_rotation_y(1.0);
    b.add_animation(Animation {
        name: Some("spin".into()),
        channels: vec![linear(
            n_cube,
            Property::Rotation,
            vec![0.0, 1.0],
            [Quat::IDENTITY.to_array(), q.to_array()].concat(),
        )],
    });
    import::write_gltf(&b.finish(), path).unwrap();
}

#[test]
fn bake_then_inspect_then_trace() {
    let dir = temp_dir("ok");
    let scene_path = dir.join("scene.glb");
    write_scene(&scene_path);
    let out = dir.join("scene.psf");
    let r = subfield(&[
        "bake",
        scene_path.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    // The split is reported: the room is static, the cube dynamic (12 triangles).
    assert!(
        err.contains("dynamic: 12 triangles in 1 instance"),
        "split not reported: {err}"
    );

    // The file traces exactly as an in-memory bake of the same static triangles.
    let scene = import::load(&scene_path).unwrap();
    let split = scene.split(ClipSelection::All);
    let soup = scene.static_triangles(&split);
    let baked = open_psf(
        &out,
        &OpenOptions {
            expect_scene_hash: Some(scene_hash(&soup.positions)),
        },
    )
    .unwrap();
    let params = PsfParams::for_triangles(soup.len());
    assert_eq!(*baked.psf.params(), params);
    let mem = Psf::build(&soup.positions, &params).unwrap();
    let mut rng = Rng::new(11);
    for _ in 0..2_000 {
        let r = Ray::new(rng.in_box(Vec3::splat(-9.0), Vec3::splat(9.0)), rng.unit());
        assert_eq!(baked.psf.intersect(&r), mem.intersect(&r));
    }

    // inspect: text and JSON.
    // The default is one screen: hashes, sizes, directions and occupancy summed up.
    let r = subfield(&["inspect", out.to_str().unwrap()]);
    assert!(r.status.success());
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(text.lines().count() <= 24, "{text}");
    for needle in [
        "content hash",
        "scene hash",
        &format!("{} triangles", soup.len()),
        "subfields",
        "occupancy:",
        "entries ×",
    ] {
        assert!(text.contains(needle), "{needle}: {text}");
    }
    assert!(!text.contains("entries[6]"), "{text}");
    let r = subfield(&["inspect", out.to_str().unwrap(), "--verbose"]);
    assert!(r.status.success());
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(
        text.contains("scene hash") && text.contains("entries[6]"),
        "{text}"
    );
    let r = subfield(&["inspect", out.to_str().unwrap(), "--json"]);
    assert!(r.status.success());
    let json: serde_json::Value = serde_json::from_slice(&r.stdout).expect("inspect --json");
    assert_eq!(
        json["header"]["triangle_count"].as_u64(),
        Some(soup.len() as u64)
    );
}

#[test]
fn bake_is_byte_identical_across_thread_counts_and_codecs_open() {
    let dir = temp_dir("threads");
    let scene_path = dir.join("scene.glb");
    write_scene(&scene_path);
    for codec in ["zstd", "none"] {
        let mut files = Vec::new();
        for threads in ["1", "2"] {
            let out = dir.join(format!("{codec}-{threads}.psf"));
            let r = subfield(&[
                "bake",
                scene_path.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--codec",
                codec,
                "--threads",
                threads,
                "--levels",
                "2",
                "--tiles",
                "32",
                "--quiet",
            ]);
            assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
            assert!(r.stderr.is_empty(), "--quiet printed");
            files.push(std::fs::read(&out).unwrap());
        }
        assert!(
            files[0] == files[1],
            "{codec}: thread count changed the bytes"
        );
    }
}

#[test]
fn bad_input_gives_one_line_and_no_file() {
    let dir = temp_dir("bad");
    let scene_path = dir.join("scene.glb");
    write_scene(&scene_path);
    let out = dir.join("out.psf");
    let not_gltf = dir.join("notes.glb");
    std::fs::write(&not_gltf, b"hello").unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["bake".into(), dir.join("missing.glb").display().to_string()],
            "missing.glb",
        ),
        (
            vec!["bake".into(), not_gltf.display().to_string()],
            "notes.glb",
        ),
        (
            vec![
                "bake".into(),
                scene_path.display().to_string(),
                "--levels".into(),
                "9".into(),
            ],
            "level 9",
        ),
        (
            vec![
                "bake".into(),
                scene_path.display().to_string(),
                "--tiles".into(),
                "0".into(),
            ],
            "tiles 0",
        ),
    ];
    for (mut args, needle) in cases {
        args.extend(["-o".into(), out.display().to_string()]);
        let a: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        let r = subfield(&a);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success(), "{args:?} succeeded");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote a file");
    }
    // A corrupt .psf: inspect names the file and fails.
    std::fs::write(&out, b"PSF?garbage").unwrap();
    let r = subfield(&["inspect", out.to_str().unwrap()]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("out.psf"));
}

#[test]
fn writers_create_folders_and_check_outputs_first() {
    let dir = temp_dir("folders");
    let scene_path = dir.join("scene.glb");
    write_scene(&scene_path);
    let s = |p: &Path| p.display().to_string();
    let ok = |args: &[String]| {
        let a: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        let r = subfield(&a);
        assert!(
            r.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&r.stderr)
        );
    };
    let psf = dir.join("new/deeper/scene.psf");
    ok(&[
        "bake".into(),
        s(&scene_path),
        "-o".into(),
        s(&psf),
        "-q".into(),
    ]);
    assert!(psf.is_file());
    let aff = dir.join("gen/a/art.aff");
    ok(&[
        "generate".into(),
        "animart".into(),
        "--triangles".into(),
        "10".into(),
        "-o".into(),
        s(&aff),
        "-q".into(),
    ]);
    assert!(aff.is_file());
    let glb = dir.join("conv/b/art.glb");
    ok(&["convert".into(), s(&aff), "-o".into(), s(&glb), "-q".into()]);
    assert!(glb.is_file());
    let museum = dir.join("gen/m/museum.glb");
    ok(&[
        "generate".into(),
        "museum".into(),
        "--static-tris".into(),
        "2000".into(),
        "--dynamic-tris".into(),
        "64".into(),
        "-o".into(),
        s(&museum),
        "-q".into(),
    ]);
    assert!(museum.is_file());

    // Under a file, nothing can be written: refused at once (before baking: no report
    // line, only the error), naming the output.
    let a_file = dir.join("a_file");
    std::fs::write(&a_file, b"x").unwrap();
    let bad = a_file.join("scene.psf");
    for args in [
        vec!["bake".to_string(), s(&scene_path), "-o".into(), s(&bad)],
        vec![
            "convert".into(),
            s(&aff),
            "-o".into(),
            s(&a_file.join("x.glb")),
        ],
        vec![
            "generate".into(),
            "animart".into(),
            "-o".into(),
            s(&a_file.join("x.aff")),
        ],
    ] {
        let a: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        let r = subfield(&a);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success(), "{args:?}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.starts_with("error: ") && err.contains("a_file"),
            "{args:?}: {err}"
        );
    }
}
