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
    let params = PsfParams::for_scene(soup.len(), scene.has_parallel_light());
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

/// A scene for `--quality high`: a few hundred triangles, bunched at one end of a long
/// box (where a grid sized for the whole box serves the default poorly), a camera
/// looking at them and a point light.
fn write_tuning_scene(path: &Path) {
    use common::build::perspective;
    use subfield::scene::{Falloff, LightDef, LightKind, Material};
    let mut b = SceneBuilder::new();
    let mut rng = Rng::new(7);
    let mut tris = synth::soup(&mut rng, 400, Vec3::splat(-1.0), Vec3::splat(1.0), 0.15);
    // The long box's floor: two triangles from x = -1 to x = 30.
    let (a, c) = (Vec3::new(-1.0, -1.2, -1.0), Vec3::new(30.0, -1.2, 1.0));
    tris.push([a, Vec3::new(c.x, a.y, a.z), c]);
    tris.push([a, c, Vec3::new(a.x, a.y, c.z)]);
    let material = b.add_material(Material::default());
    let mesh = b.add_mesh(Mesh {
        primitives: vec![soup_prim(tris.into_iter().flatten().collect(), material)],
        ..Default::default()
    });
    let n_mesh = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    let cam = b.add_camera(perspective("view", 0.8, Some(4.0 / 3.0), 0.01, None));
    let n_cam = b.add_node(Node {
        camera: Some(cam),
        transform: placed(Vec3::new(0.3, 0.2, 4.0), Quat::IDENTITY),
        ..Default::default()
    });
    let light = b.add_light(LightDef {
        name: Some("lamp".into()),
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity: 10.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let n_light = b.add_node(Node {
        light: Some(light),
        transform: placed(Vec3::new(1.0, 3.0, 2.0), Quat::IDENTITY),
        ..Default::default()
    });
    for n in [n_mesh, n_cam, n_light] {
        b.add_root(n);
    }
    import::write_gltf(&b.finish(), path).unwrap();
}

fn bake_high(scene: &Path, out: &Path, threads: &str) -> Output {
    subfield(&[
        "bake",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--quality",
        "high",
        "--threads",
        threads,
    ])
}

#[test]
fn quality_high_is_byte_identical_across_threads_and_its_record_round_trips() {
    let dir = temp_dir("quality");
    let scene_path = dir.join("scene.glb");
    write_tuning_scene(&scene_path);
    let (one, two) = (dir.join("one.psf"), dir.join("two.psf"));
    let r1 = bake_high(&scene_path, &one, "1");
    let err = String::from_utf8_lossy(&r1.stderr);
    assert!(r1.status.success(), "{err}");
    // Progress on stderr: the sample, the trials, the choice.
    for needle in ["sample rays", "trial  1:", "tuning: tiles", "chose level"] {
        assert!(err.contains(needle), "{needle}: {err}");
    }
    let r2 = bake_high(&scene_path, &two, "2");
    assert!(
        r2.status.success(),
        "{}",
        String::from_utf8_lossy(&r2.stderr)
    );
    let bytes = std::fs::read(&one).unwrap();
    assert!(
        bytes == std::fs::read(&two).unwrap(),
        "thread count changed the bytes"
    );
    // The same content hash on stdout.
    assert_eq!(r1.stdout, r2.stdout);

    // What the file records is what the bake chose and measured: the header's bake
    // record, the tracer's parameters, and `inspect --json` agree.
    let baked = open_psf(&one, &OpenOptions::default()).unwrap();
    let rec = baked.header.bake;
    assert_eq!(rec.quality, subfield::psf::Quality::High);
    let tuned = *baked.psf.tuning().expect("a tuned file records its tuning");
    assert!(tuned.trials > 1 && tuned.sample_rays > 0, "{tuned:?}");
    assert!(tuned.cost <= tuned.default_cost, "{tuned:?}");
    assert_eq!(rec.bsp(), *baked.psf.bsp_params());
    let r = subfield(&["inspect", one.to_str().unwrap(), "--json"]);
    assert!(r.status.success());
    let json: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    let b = &json["header"]["bake"];
    assert_eq!(b["quality"], "high");
    assert_eq!(b["leaf"].as_u64(), Some(rec.leaf as u64));
    assert_eq!(b["flat_max"].as_u64(), Some(rec.flat_max as u64));
    assert_eq!(b["trials"].as_u64(), Some(tuned.trials as u64));
    assert_eq!(b["sample_rays"].as_u64(), Some(tuned.sample_rays));
    assert_eq!(b["cost"].as_u64(), Some(tuned.cost));
    assert_eq!(b["default_cost"].as_u64(), Some(tuned.default_cost));
    assert_eq!(
        json["header"]["level"].as_u64(),
        Some(baked.psf.params().level as u64)
    );
    assert_eq!(
        json["header"]["tiles"].as_u64(),
        Some(baked.psf.params().tiles as u64)
    );
    // The summary says so too.
    let r = subfield(&["inspect", one.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(text.contains("bake: quality high"), "{text}");

    // A default bake records a default bake.
    let plain = dir.join("plain.psf");
    let r = subfield(&[
        "bake",
        scene_path.to_str().unwrap(),
        "-o",
        plain.to_str().unwrap(),
        "-q",
    ]);
    assert!(r.status.success());
    let d = open_psf(&plain, &OpenOptions::default()).unwrap();
    assert_eq!(d.header.bake, subfield::format::BakeRecord::default_bake());
    assert!(d.psf.tuning().is_none());

    // The tuned file traces as the default one does (exactness does not depend on the
    // parameters).
    let mut rng = Rng::new(5);
    for _ in 0..2_000 {
        let r = Ray::new(rng.in_box(Vec3::splat(-3.0), Vec3::splat(3.0)), rng.unit());
        assert_eq!(baked.psf.intersect(&r), d.psf.intersect(&r));
    }
}

#[test]
fn quality_high_costs_no_more_than_the_default_on_its_sample() {
    let dir = temp_dir("quality-cost");
    let scene_path = dir.join("scene.glb");
    write_tuning_scene(&scene_path);
    let scene = import::load(&scene_path).unwrap();
    let split = scene.split(ClipSelection::All);
    let tris = scene.static_triangles(&split).positions;
    let auto = PsfParams::for_scene(tris.len(), scene.has_parallel_light());
    let default = Psf::build(&tris, &auto).unwrap();
    let rays = subfield::render::tuning_rays(&scene, &default);
    // The camera's primary rays and the point light's shadow rays mostly go through
    // point grids, as in a render; the mirror rays off the soup pass no point and are
    // left to the parallel subfields.
    assert!(rays.len() >= 1 << 16, "{}", rays.len());
    assert!(rays.point as usize >= 1 << 15, "{} point", rays.point);
    assert!(rays.traced() > 0 && rays.traced() < rays.point as usize);
    // Classified alike by any default bake of the scene.
    let again = subfield::render::tuning_rays(&scene, &Psf::build(&tris, &auto).unwrap());
    assert_eq!(
        (again.point, &again.closest, &again.any),
        (rays.point, &rays.closest, &rays.any)
    );
    let (psf, tuning) = subfield::psf::tune(&tris, auto, &rays, &|_| {}).unwrap();
    // The costs are what measuring gives, independently of the search: the default's,
    // and the chosen bake's, each with the point grids' rays at the default's mean cost
    // a traced ray.
    use subfield::psf::tune::{cost, measure, point_charge};
    let measured = measure(&default, &rays);
    assert_eq!(measured.rays as usize, rays.traced());
    let point = point_charge(&rays, &measured);
    assert_eq!(tuning.point_cost, point);
    assert_eq!(
        point,
        rays.point * cost(&measured) / rays.traced() as u64,
        "{measured:?}"
    );
    let default_cost = cost(&measured) + point;
    assert_eq!(tuning.record.default_cost, default_cost);
    assert_eq!(tuning.record.cost, cost(&measure(&psf, &rays)) + point);
    assert_eq!(tuning.record.sample_rays, rays.len() as u64);
    assert_eq!(
        (*psf.params(), *psf.bsp_params()),
        (tuning.chosen.params, tuning.chosen.bsp)
    );
    // No costlier than the default, and no trial kept is much cheaper than the choice.
    assert!(tuning.record.cost <= default_cost, "{:?}", tuning.record);
    let least = tuning.trials.iter().map(|t| t.cost).min().unwrap();
    assert!(tuning.record.cost as f64 <= least as f64 * 1.01 + 1.0);
    // On this scene (most triangles in a corner of a long box) the default's grid is
    // poor: the tuned bake does measurably less work on the rays left to the parallel
    // subfields, and less over the whole sample (where the point grids' share, the
    // same for every bake, dilutes the gain).
    let traced = cost(&measure(&psf, &rays));
    assert!(
        (traced as f64) < 0.95 * cost(&measured) as f64,
        "{traced} against {measured:?}"
    );
    assert!(tuning.record.cost < default_cost, "{:?}", tuning.record);
    // Same input, same choice.
    let (_, again) = subfield::psf::tune(&tris, auto, &rays, &|_| {}).unwrap();
    assert_eq!(again.record, tuning.record);
    assert_eq!(again.chosen, tuning.chosen);
}

#[test]
fn a_bad_quality_is_one_clear_line_and_no_file() {
    let dir = temp_dir("quality-bad");
    let scene_path = dir.join("scene.glb");
    write_tuning_scene(&scene_path);
    let out = dir.join("out.psf");
    let s = scene_path.to_str().unwrap();
    let o = out.to_str().unwrap();
    for (args, needles) in [
        (
            vec!["bake", s, "-o", o, "--quality", "ultra"],
            vec!["ultra", "default or high"],
        ),
        (
            vec!["bake", s, "-o", o, "--quality", "high", "--tiles", "8"],
            vec!["--quality high", "--tiles"],
        ),
        (
            vec!["bake", s, "-o", o, "--quality", "high", "--levels", "2"],
            vec!["--quality high", "--levels"],
        ),
    ] {
        let r = subfield(&args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success(), "{args:?} succeeded");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {n}: {err}");
        }
        assert!(!out.exists(), "{args:?} wrote a file");
    }
}
