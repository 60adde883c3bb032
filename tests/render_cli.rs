//! `subfield render` as a program: byte-identical frames whatever the thread count,
//! resume after an interrupted run, shards, stats and plot, and one clear error line
//! with nothing written for every bad input.

mod common;

use common::render_scene;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use render_scene::{files_under, temp_dir, write_scene, write_scene_without_emitters};

fn subfield(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> Output {
    let o = subfield(args);
    assert!(
        o.status.success(),
        "subfield {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    files_under(dir)
        .into_iter()
        .map(|p| {
            let b = std::fs::read(dir.join(&p)).unwrap();
            (p, b)
        })
        .collect()
}

const SIZE: &str = "48x36";
/// `--replay-bytes` for 256 MB of slots: the replay of a still camera's shading, which
/// the default (none: the records alone) does not keep.
const SLOTS: &str = "268435456";
/// Every AOV: frames stay byte-identical across threads and shards with all of them on.
const ALL_AOVS: &str = "depth,normal,albedo,position,motion,cryptomatte";

#[test]
fn frames_do_not_depend_on_the_thread_count() {
    let dir = temp_dir("threads");
    let scene = write_scene(&dir);
    // The same frames into `sub`, with `--threads` when given.
    let render = |sub: &str, threads: Option<&str>| {
        let out = dir.join(format!("{sub}/f.##.exr"));
        let mut args = vec![
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "3..6",
            "--size",
            SIZE,
            "--spp",
            "4",
            "--aov",
            ALL_AOVS,
            "--quiet",
        ];
        args.extend(threads.iter().flat_map(|t| ["--threads", *t]));
        ok(&args);
    };
    render("t1", Some("1"));
    render("t2", Some("2"));
    let a = snapshot(&dir.join("t1"));
    let b = snapshot(&dir.join("t2"));
    assert_eq!(a.len(), 3);
    assert_eq!(a, b, "--threads 1 and --threads 2 wrote different bytes");
    // And a rerun is byte-identical too (nothing varying such as a time stamp).
    render("t1", None);
    assert_eq!(snapshot(&dir.join("t1")), a);
}

/// A render that bakes in memory (on the CPU at level 0, `PsfParams::for_cpu_render`)
/// writes the frames of one that opens the scene's default bake (level 2 here): the
/// point grids and the box tree find the same hits whatever the subfields. The museum
/// at Whitted depth 4: mirrors, glossy floors, glass and moving triangles.
#[test]
fn a_render_baked_in_memory_writes_the_frames_of_the_default_bake() {
    let dir = temp_dir("in_memory");
    let scene = dir.join("museum.glb");
    ok(&[
        "generate",
        "museum",
        "-o",
        s(&scene),
        "--static-tris",
        "3000",
        "--dynamic-tris",
        "500",
        "--frames",
        "40",
        "--quiet",
    ]);
    let psf = dir.join("museum.psf");
    ok(&["bake", s(&scene), "-o", s(&psf), "--quiet"]);
    // Two frames into `sub`, then `extra`.
    let render = |sub: &str, extra: &[&str]| {
        let out = dir.join(format!("{sub}/f.##.exr"));
        let frames = ["--frames", "19..21", "--size", "40x30", "--quiet"];
        let args = [&["render", s(&scene), "-o", s(&out)][..], &frames, extra].concat();
        ok(&args);
    };
    render("file", &["--baked", s(&psf)]);
    render("memory", &[]);
    let a = snapshot(&dir.join("file"));
    assert_eq!(a.len(), 2);
    assert_eq!(a, snapshot(&dir.join("memory")));
}

/// Frame `k` of the render into `dir/sub` (`f.##.exr`).
fn frame_of(dir: &Path, sub: &str, k: u32) -> Vec<u8> {
    std::fs::read(dir.join(format!("{sub}/f.{k:02}.exr"))).unwrap()
}

/// Renders `frames` of `scene` through `camera` (96x72, `--max-depth 2`, `--aov aovs`)
/// into `dir/name` on 2 threads and `dir/name1` on 1, one frame in flight, `dir/name3`
/// with three frames in flight on 2 threads, `dir/namec` in chunks of 1,000 samples (ten
/// rows: eight chunks a frame, the last a short one; a frame is otherwise one chunk), and
/// each frame of `check` alone, and asserts that each of those frames is the same bytes
/// in all five.
fn sequence_is_its_frames_alone(
    dir: &Path,
    scene: &Path,
    camera: (&str, &str),
    frames: &str,
    check: &[u32],
    aovs: &str,
) {
    sequence_is_its_frames_alone_keeping(dir, scene, camera, frames, check, aovs, "0");
}

/// [`sequence_is_its_frames_alone`] with `--replay-bytes keep` on every render: `0` (the
/// default) leaves a still camera's replay no room for slots, so that it keeps only the
/// records of the samples that settle; [`SLOTS`] gives it two levels of slots.
fn sequence_is_its_frames_alone_keeping(
    dir: &Path,
    scene: &Path,
    (name, camera): (&str, &str),
    frames: &str,
    check: &[u32],
    aovs: &str,
    keep: &str,
) {
    let render_cut = |sub: &str, frames: &str, threads: &str, in_flight: &str, chunk: &str| {
        let out = dir.join(format!("{sub}/f.##.exr"));
        ok(&[
            "render",
            "--replay-bytes",
            keep,
            s(scene),
            "-o",
            s(&out),
            "--frames",
            frames,
            "--size",
            "96x72",
            "--camera",
            camera,
            "--max-depth",
            "2",
            "--aov",
            aovs,
            "--threads",
            threads,
            "--frames-in-flight",
            in_flight,
            "--chunk-samples",
            chunk,
            "--quiet",
        ]);
    };
    let render = |sub: &str, frames: &str, threads: &str, in_flight: &str| {
        render_cut(sub, frames, threads, in_flight, "0");
    };
    render(name, frames, "2", "1");
    // Small chunks: the memo's and the replay's slots are found from each chunk's first
    // pixel, and the AOVs written chunk by chunk.
    render_cut(&format!("{name}c"), frames, "2", "2", "1000");
    render(&format!("{name}1"), frames, "1", "1");
    // Three frames at once, each lane's frames three apart (what a lane keeps from its
    // last frame is three frames old), on two threads.
    render(&format!("{name}3"), frames, "2", "3");
    for &k in check {
        let alone = format!("{name}-alone{k}");
        render(&alone, &k.to_string(), "2", "1");
        assert!(
            frame_of(dir, name, k) == frame_of(dir, &alone, k),
            "{name} camera: frame {k} of a sequence differs from the frame rendered alone"
        );
        assert!(
            frame_of(dir, name, k) == frame_of(dir, &format!("{name}1"), k),
            "{name} camera: frame {k} differs between 1 and 2 threads"
        );
        assert!(
            frame_of(dir, name, k) == frame_of(dir, &format!("{name}3"), k),
            "{name} camera: frame {k} differs between one and three frames in flight"
        );
        assert!(
            frame_of(dir, name, k) == frame_of(dir, &format!("{name}c"), k),
            "{name} camera: frame {k} differs when traced in chunks of 1,000 samples"
        );
    }
}

/// A camera that stays put (the side camera) at one sample a pixel: from the second
/// frame on, the camera rays' static hits and the shadow rays' static answers are the
/// ones kept from the frame before, and so are those of the mirror's and the glass's
/// rays two levels down (`--max-depth 2`); only the moving cube is traced again. Every
/// frame must be the bytes it is when rendered alone (nothing kept to reuse), AOVs
/// included, whatever the thread count; and a camera that moves in some frames and stays
/// in others changes nothing either.
#[test]
fn a_still_camera_reuses_static_hits_and_frames_stay_the_same() {
    let dir = temp_dir("memo");
    let scene = write_scene(&dir);
    for camera in [("still", "side camera"), ("moving", "main")] {
        sequence_is_its_frames_alone(&dir, &scene, camera, "0..8", &[0, 1, 4, 7], ALL_AOVS);
    }
    // The cube moves in front of the still camera: the frames are not all one picture.
    assert!(frame_of(&dir, "still", 0) != frame_of(&dir, "still", 7));
}

/// Several frames in flight fill a still camera's memo and replay once: the stretch's
/// first frame renders alone and the other lanes copy what it kept, so no other frame
/// says `fill` in the `--stats` CSV's `kept` column (each lane had filled its own); a
/// camera that moves every frame keeps nothing. The frames are the same bytes as one
/// frame at a time (checked with the copies in `a_still_camera_reuses_static_hits…`).
#[test]
fn frames_in_flight_fill_a_still_camera_once() {
    let dir = temp_dir("fill-once");
    let scene = write_scene(&dir);
    let kept_with = |camera: &str, in_flight: &str, keep: &str| -> Vec<String> {
        let sub = format!("{}-{in_flight}-{keep}", camera.replace(' ', "_"));
        let stats = dir.join(format!("{sub}.csv"));
        ok(&[
            "render",
            s(&scene),
            "-o",
            s(&dir.join(format!("{sub}/f.##.exr"))),
            "--frames",
            "0..7",
            "--size",
            SIZE,
            "--camera",
            camera,
            "--threads",
            "2",
            "--frames-in-flight",
            in_flight,
            "--stats",
            s(&stats),
            "--replay-bytes",
            keep,
            "--quiet",
        ]);
        let csv = std::fs::read_to_string(&stats).unwrap();
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = header
            .iter()
            .position(|h| *h == "kept")
            .expect("a kept column");
        lines
            .map(|l| l.split(',').nth(col).unwrap().to_string())
            .collect()
    };
    // With the replay's slots.
    let kept = |camera: &str, in_flight: &str| kept_with(camera, in_flight, SLOTS);
    let words = |v: &[&str]| v.iter().map(|w| w.to_string()).collect::<Vec<_>>();
    let once = words(&["fill", "reuse", "reuse", "reuse", "reuse", "reuse", "reuse"]);
    for in_flight in ["1", "3", "4"] {
        assert_eq!(
            kept("side camera", in_flight),
            once,
            "{in_flight} in flight"
        );
    }
    let each = words(&["fill", "fill", "reuse", "reuse", "reuse", "reuse", "reuse"]);
    assert_eq!(kept("side camera", "2"), each, "2 in flight");
    assert_eq!(kept("main", "3"), words(&["none"; 7]));
    // Without slots (the default: records alone) two frames in flight fill once too:
    // the copy's records and sums let the other lane settle.
    assert_eq!(
        kept_with("side camera", "2", "0"),
        once,
        "2 in flight, records"
    );
}

/// A still camera at one sample a pixel in a scene without emitters (no random numbers):
/// from the second frame on, the shading of every camera and mirror ray that repeats
/// with the same static hit is replayed from the frame before (`render::replay`), not
/// shaded again (the first frame keeps it, the camera being the same at the next). The point light moves between frames 3 and 6 and stays put before and
/// after, the red cube moves in front of the camera and in the mirror, the glass cube
/// sends two rays a sample. Every frame must be the bytes it is when rendered alone,
/// whatever the thread count.
#[test]
fn a_still_camera_replays_its_shading_and_frames_stay_the_same() {
    let dir = temp_dir("replay");
    let scene = write_scene_without_emitters(&dir);
    // Frame 1 replays what frame 0 kept; 2 what 1 kept.
    let checked = [0, 1, 2, 4, 5, 7, 11];
    sequence_is_its_frames_alone(
        &dir,
        &scene,
        ("seq", "side camera"),
        "0..12",
        &checked,
        "Z,N",
    );
    // The light moves: frames 2 and 7 differ; the cube moves: 7 and 11 differ.
    assert!(frame_of(&dir, "seq", 2) != frame_of(&dir, "seq", 7));
    assert!(frame_of(&dir, "seq", 7) != frame_of(&dir, "seq", 11));
    // With slots, the shading replayed where the rays repeat: the same bytes.
    sequence_is_its_frames_alone_keeping(
        &dir,
        &scene,
        ("rec", "side camera"),
        "0..12",
        &checked,
        "Z,N",
        SLOTS,
    );
    for k in checked {
        assert!(
            frame_of(&dir, "seq", k) == frame_of(&dir, "rec", k),
            "frame {k}"
        );
    }
}

/// A still camera ("still") over a floor with a mirror behind, one point light, and a red
/// cube that jumps between the places `keys` gives (frame numbers at 24 fps, each place
/// held until the next key's frame). The scene's file in `dir`.
fn jumping_cube_scene(dir: &Path, keys: &[(f32, glam::Vec3)]) -> std::path::PathBuf {
    use glam::{Quat, Vec3, Vec4};
    use render_scene::{cube, floor_and_mirror, quad, room_materials};
    use subfield::scene::{Animation, Falloff, LightDef, LightKind, Node, Property};

    use common::build::{diffuse, linear, mesh, perspective, placed, SceneBuilder};

    let mut b = SceneBuilder::new();
    let (grey, mirror) = room_materials(&mut b);
    let red = b.add_material(diffuse("red", Vec4::new(0.8, 0.1, 0.1, 1.0), 0.4));
    let [floor, mirror_quad] = floor_and_mirror(8.0, grey, mirror);
    // Out of sight under the floor: the static bounds hold every place the cube goes,
    // so the scene's extent (part of what the replay keeps to) stays.
    let under = quad(
        Vec3::new(0.0, -1.0, 0.0),
        Vec3::X * 0.5,
        Vec3::Z * 0.5,
        grey,
    );
    let room = b.add_mesh(mesh("room", vec![floor, mirror_quad, under]));
    let cube_mesh = b.add_mesh(mesh("mover", vec![cube(Vec3::splat(0.3), red)]));
    let room = b.add_node(Node {
        name: Some("room".into()),
        mesh: Some(room),
        ..Default::default()
    });
    let mover = b.add_node(Node {
        name: Some("mover".into()),
        mesh: Some(cube_mesh),
        transform: placed(keys[0].1, Quat::IDENTITY),
        ..Default::default()
    });
    let cam = b.add_camera(perspective("still", 0.9, Some(4.0 / 3.0), 0.1, None));
    let cam = b.add_node(Node {
        name: Some("still".into()),
        camera: Some(cam),
        transform: placed(Vec3::new(0.0, 2.0, 4.0), Quat::from_rotation_x(-0.3)),
        ..Default::default()
    });
    let light = b.add_light(LightDef {
        name: Some("bulb".into()),
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity: 60.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let light = b.add_node(Node {
        name: Some("bulb".into()),
        light: Some(light),
        transform: placed(Vec3::new(2.0, 5.0, 1.0), Quat::IDENTITY),
        ..Default::default()
    });
    for n in [room, mover, cam, light] {
        b.add_root(n);
    }
    // Each place held from its frame to just before the next key's (a jump of a tenth
    // of a frame, between frames).
    let f = |k: f32| k / 24.0;
    let mut times = Vec::new();
    let mut places = Vec::new();
    for (i, &(frame, at)) in keys.iter().enumerate() {
        times.push(f(frame));
        places.push(at);
        let until = keys.get(i + 1).map_or(frame + 24.0, |k| k.0);
        times.push(f(until - 0.5));
        places.push(at);
    }
    b.add_animation(Animation {
        name: Some("jumps".into()),
        channels: vec![linear(
            mover,
            Property::Translation,
            times,
            places.iter().flat_map(|v| v.to_array()).collect(),
        )],
    });
    b.scene.fps = Some(24.0);
    let scene = dir.join("jumps.glb");
    subfield::import::write_gltf(&b.finish(), &scene).unwrap();
    scene
}

/// The jumping cube: frames 0 and 1 it hangs between the light and the floor (its
/// shadow on the floor), 2 and 3 under the floor (out of every ray's way), from 4 on
/// below the camera's view, seen only in the mirror. Samples whose kept rays all miss
/// the moving triangles take the last frame's sums whole (`ShadeReplay::settled`): a
/// floor pixel whose shadow ray the cube blocked the frame before must not (its shadow
/// is gone at frame 2), nor a mirror pixel whose reflected ray the cube now meets
/// (frame 4). Every frame must be the bytes it is when rendered alone.
#[test]
fn settled_samples_follow_what_moves_into_and_out_of_their_rays() {
    use glam::Vec3;
    let dir = temp_dir("settled");
    let (a, below, behind) = (
        Vec3::new(1.2, 2.5, 0.5),
        Vec3::new(0.0, -0.5, 0.0),
        Vec3::new(0.0, 0.3, 3.2),
    );
    let scene = jumping_cube_scene(&dir, &[(0.0, a), (2.0, below), (4.0, behind)]);
    sequence_is_its_frames_alone(
        &dir,
        &scene,
        ("jumps", "still"),
        "0..8",
        &[0, 1, 2, 3, 4, 5, 7],
        "Z",
    );
    // The cube's shadow leaves the floor at frame 2 and its image enters the mirror at 4.
    assert!(frame_of(&dir, "jumps", 1) != frame_of(&dir, "jumps", 2));
    assert!(frame_of(&dir, "jumps", 3) != frame_of(&dir, "jumps", 4));
    // With slots as well as the records, the same bytes.
    sequence_is_its_frames_alone_keeping(
        &dir,
        &scene,
        ("jumpr", "still"),
        "0..8",
        &[0, 1, 2, 3, 4, 5, 7],
        "Z",
        SLOTS,
    );
    for k in 0..8 {
        assert!(
            frame_of(&dir, "jumps", k) == frame_of(&dir, "jumpr", k),
            "frame {k}"
        );
    }
    // Both forms settle most samples once a frame has kept them (frame 1 replays what
    // frame 0 kept, but frame 0's sums are not complete until it ends: from frame 1 on,
    // one frame in flight), and none in the first.
    for keep in ["0", SLOTS] {
        let settled = settled_counts(&dir, &scene, "still", "0..8", keep);
        let pixels = 96 * 72;
        assert_eq!(settled[0], 0, "--replay-bytes {keep}: {settled:?}");
        assert!(
            settled[3] > pixels / 2 && settled[7] > pixels / 2,
            "--replay-bytes {keep}: {settled:?}"
        );
    }
}

/// Each frame's `settled` count of the JSON log, `frames` of `scene` through `camera`
/// (96x72, `--max-depth 2`, one frame in flight) with `--replay-bytes keep`.
fn settled_counts(dir: &Path, scene: &Path, camera: &str, frames: &str, keep: &str) -> Vec<u64> {
    let out = dir.join(format!("count{keep}/f.##.exr"));
    let o = ok(&[
        "render",
        s(scene),
        "-o",
        s(&out),
        "--frames",
        frames,
        "--size",
        "96x72",
        "--camera",
        camera,
        "--max-depth",
        "2",
        "--frames-in-flight",
        "1",
        "--threads",
        "2",
        "--replay-bytes",
        keep,
        "--log-format",
        "json",
    ]);
    String::from_utf8_lossy(&o.stderr)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["event"] == "frame")
        .map(|v| v["settled"].as_u64().expect("a settled count"))
        .collect()
}

/// The jumping cube under the floor, in the camera's view for one frame (4; for each
/// of two frames in flight, its lane's third frame, which settles most samples by
/// what the lane kept), then under the floor again. A pixel that saw the cube was not
/// settled and was shaded, its kept shading dropped (a moving hit): what a settled
/// sample's check had kept of it must be dropped too, or the next frame takes the sums
/// that showed the cube (frames 5 and 6 against themselves rendered alone).
#[test]
fn a_pixel_that_saw_a_mover_is_not_settled_after_it_leaves() {
    use glam::Vec3;
    let dir = temp_dir("settled_seen");
    let below = Vec3::new(0.0, -0.5, 0.0);
    // In front of the camera, near it and low: far from the floor's shadow rays.
    let seen = Vec3::new(-0.3, 1.4, 2.6);
    let scene = jumping_cube_scene(&dir, &[(0.0, below), (4.0, seen), (5.0, below)]);
    sequence_is_its_frames_alone(
        &dir,
        &scene,
        ("seen", "still"),
        "0..8",
        &[3, 4, 5, 6, 7],
        "Z",
    );
    assert!(frame_of(&dir, "seen", 3) != frame_of(&dir, "seen", 4));
    assert!(frame_of(&dir, "seen", 4) != frame_of(&dir, "seen", 5));
    assert!(frame_of(&dir, "seen", 3) == frame_of(&dir, "seen", 5));
    // With slots as well: the same bytes.
    sequence_is_its_frames_alone_keeping(
        &dir,
        &scene,
        ("seer", "still"),
        "0..8",
        &[3, 4, 5, 6, 7],
        "Z",
        SLOTS,
    );
    for k in [3, 4, 5, 6, 7] {
        assert!(
            frame_of(&dir, "seen", k) == frame_of(&dir, "seer", k),
            "frame {k}"
        );
    }
}

#[test]
fn resume_completes_an_interrupted_run_and_redoes_broken_frames() {
    let dir = temp_dir("resume");
    let scene = write_scene(&dir);
    let full = dir.join("full/f.####.exr");
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&full),
        "--frames",
        "0..6",
        "--size",
        SIZE,
        "--quiet",
    ]);
    let want = snapshot(&dir.join("full"));
    assert_eq!(want.len(), 6);

    // "Killed" after three frames: only 0..3 exist; frame 1 is truncated, frame 2 is
    // garbage.
    let part = dir.join("part/f.####.exr");
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&part),
        "--frames",
        "0..3",
        "--size",
        SIZE,
        "--quiet",
    ]);
    let f1 = dir.join("part/f.0001.exr");
    let bytes = std::fs::read(&f1).unwrap();
    std::fs::write(&f1, &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(dir.join("part/f.0002.exr"), b"not an exr").unwrap();
    let f0_before = std::fs::metadata(dir.join("part/f.0000.exr"))
        .unwrap()
        .modified()
        .unwrap();
    let o = ok(&[
        "render",
        s(&scene),
        "-o",
        s(&part),
        "--frames",
        "0..6",
        "--size",
        SIZE,
        "--resume",
        // Rounds of three frames at once: the skipped frame's place taken by the next.
        "--frames-in-flight",
        "3",
    ]);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("(1 skipped as complete)"), "{log}");
    assert_eq!(snapshot(&dir.join("part")), want);
    let f0_after = std::fs::metadata(dir.join("part/f.0000.exr"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(f0_before, f0_after, "the complete frame was not rewritten");

    // A frame of another size is not "complete" for this run.
    let o = ok(&[
        "render",
        s(&scene),
        "-o",
        s(&part),
        "--frames",
        "0..6",
        "--size",
        "20x10",
        "--resume",
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("(0 skipped as complete)"));
}

#[test]
fn resume_rerenders_frames_made_with_other_options() {
    let dir = temp_dir("resume-options");
    let scene = write_scene(&dir);
    let out = dir.join("o/f.#.exr");
    let run = |spp: &str, resume: bool| {
        let mut args = vec![
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "0..3",
            "--size",
            "24x18",
            "--spp",
            spp,
        ];
        if resume {
            args.push("--resume");
        }
        String::from_utf8_lossy(&ok(&args).stderr).into_owned()
    };
    run("1", false);
    let spp1 = snapshot(&dir.join("o"));
    // Other options: no frame is complete for this run, every one is rendered again.
    // One broken frame is no finished frame: only the two whole ones are counted as
    // replaced, in one line (issue 35).
    std::fs::write(dir.join("o/f.1.exr"), b"cut short").unwrap();
    let log = run("2", true);
    assert!(log.contains("(0 skipped as complete)"), "{log}");
    let said: Vec<&str> = log.lines().filter(|l| l.contains("again")).collect();
    assert_eq!(
        said,
        ["--resume rendered 2 finished frames again: they were made with other options (the options string in the header differs)"],
        "{log}"
    );
    let spp2 = snapshot(&dir.join("o"));
    assert_eq!(spp2.len(), 3);
    for ((_, a), (_, b)) in spp1.iter().zip(&spp2) {
        assert_ne!(a, b, "an --spp 2 frame is not the --spp 1 one");
    }
    // The same options: all skipped, nothing rewritten.
    let log = run("2", true);
    assert!(log.contains("(3 skipped as complete)"), "{log}");
    assert!(!log.contains("again"), "{log}");
    assert_eq!(snapshot(&dir.join("o")), spp2);
}

#[test]
fn crypto_levels_is_checked() {
    let dir = temp_dir("crypto-levels");
    let scene = write_scene(&dir);
    let out = dir.join("o/f.#.exr");
    let o = subfield(&[
        "render",
        s(&scene),
        "-o",
        s(&out),
        "--aov",
        "cryptomatte",
        "--crypto-levels",
        "0",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--crypto-levels"));
    assert!(!dir.join("o").exists());
}

/// A run really killed (SIGKILL) part-way, then resumed over the whole range, gives the
/// files of an uninterrupted run. The killed run may leave a hidden temporary beside
/// the frame it was writing; the resumed run removes it (where `/proc` shows the
/// writer is gone), so the folder ends up exactly as an uninterrupted run's.
#[test]
fn a_killed_run_resumed_gives_the_same_frames() {
    let dir = temp_dir("kill");
    let scene = write_scene(&dir);
    let args = |out: &Path| -> Vec<String> {
        [
            "render",
            s(&scene),
            "-o",
            s(out),
            "--frames",
            "0..24",
            "--size",
            "160x120",
            "--spp",
            "2",
            "--quiet",
        ]
        .iter()
        .map(|a| a.to_string())
        .collect()
    };
    let full = dir.join("full/f.####.exr");
    ok(&args(&full).iter().map(|a| a.as_str()).collect::<Vec<_>>());
    let visible = |d: &Path| -> Vec<(PathBuf, Vec<u8>)> {
        snapshot(d)
            .into_iter()
            .filter(|(p, _)| !p.to_string_lossy().starts_with('.'))
            .collect()
    };
    let want = visible(&dir.join("full"));
    assert_eq!(want.len(), 24);

    let part = dir.join("part/f.####.exr");
    let mut child = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args(&part))
        .spawn()
        .unwrap();
    // Kill it once a few frames are on disk (or it has finished, on a fast machine).
    let t0 = std::time::Instant::now();
    loop {
        let n = std::fs::read_dir(dir.join("part"))
            .map(|d| d.count())
            .unwrap_or(0);
        if n >= 3 || t0.elapsed().as_secs() > 60 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let _ = child.kill();
    let _ = child.wait();
    let done_before = visible(&dir.join("part")).len();
    eprintln!("killed with {done_before} of 24 frames written");
    // And one stale temporary for sure, as a writer killed mid-file leaves it (the pid
    // is above Linux's largest, so no such process runs; the host is this one).
    let stale = dir.join(format!(
        "part/.f.0005.exr.4194321-0-{}.tmp",
        subfield::atomic::host_id()
    ));
    std::fs::write(&stale, b"half a frame").unwrap();
    let mut resume = args(&part);
    resume.push("--resume".into());
    ok(&resume.iter().map(|a| a.as_str()).collect::<Vec<_>>());
    assert_eq!(
        visible(&dir.join("part")),
        want,
        "killed after {done_before} frames"
    );
    if Path::new("/proc/self").exists() {
        let names: Vec<PathBuf> = want.iter().map(|(p, _)| p.clone()).collect();
        assert_eq!(
            files_under(&dir.join("part")),
            names,
            "a temporary of the killed run is left"
        );
    } else {
        assert!(stale.exists(), "removed without knowing its writer is gone");
    }
}

#[test]
fn shards_together_give_the_full_set() {
    let dir = temp_dir("shards");
    let scene = write_scene(&dir);
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&dir.join("full/f.#.exr")),
        "--frames",
        "2..7",
        "--size",
        SIZE,
        "--spp",
        "2",
        "--aov",
        ALL_AOVS,
        "--quiet",
    ]);
    for shard in ["0/2", "1/2"] {
        ok(&[
            "render",
            s(&scene),
            "-o",
            s(&dir.join("sharded/f.#.exr")),
            "--frames",
            "2..7",
            "--size",
            SIZE,
            "--spp",
            "2",
            "--aov",
            ALL_AOVS,
            "--shard",
            shard,
            "--quiet",
        ]);
        if shard == "0/2" {
            let names: Vec<PathBuf> = files_under(&dir.join("sharded"));
            assert_eq!(names, ["f.2.exr", "f.4.exr", "f.6.exr"].map(PathBuf::from));
        }
    }
    assert_eq!(snapshot(&dir.join("sharded")), snapshot(&dir.join("full")));
}

#[test]
fn stats_plot_and_the_default_range() {
    let dir = temp_dir("stats");
    let scene = write_scene(&dir);
    let psf = dir.join("scene.psf");
    ok(&["bake", s(&scene), "-o", s(&psf), "--quiet"]);
    ok(&[
        "render",
        s(&scene),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("out/f.###.exr")),
        "--size",
        "16x12",
        "--fps",
        "6",
        "--stats",
        s(&dir.join("st/stats.csv")),
        "--plot",
        s(&dir.join("st/plot.svg")),
        "--quiet",
    ]);
    // 1 s of animation at 6 fps: frames 0..=6.
    assert_eq!(files_under(&dir.join("out")).len(), 7);
    let csv = std::fs::read_to_string(dir.join("st/stats.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "frame,time,update_ms,trace_ms,shade_ms,write_ms,primary_rays,shadow_rays,secondary_rays,cpu_ms,threads,kept"
    );
    assert_eq!(lines.len(), 8);
    for (i, l) in lines[1..].iter().enumerate() {
        let f: Vec<&str> = l.split(',').collect();
        assert_eq!(f[0], i.to_string());
        assert!((f[1].parse::<f64>().unwrap() - i as f64 / 6.0).abs() < 1e-6);
        assert_eq!(f[6], "192", "one primary ray a pixel");
        assert!(f[7].parse::<u64>().unwrap() > 0 && f[8].parse::<u64>().unwrap() > 0);
        // The render threads' CPU time (Linux; counted in scheduler ticks, so a frame
        // this small may read 0): at most what its threads could spend.
        if cfg!(target_os = "linux") {
            let cpu: f64 = f[9].parse().unwrap();
            let threads: f64 = f[10].parse().unwrap();
            let wall: f64 = f[2..5].iter().map(|v| v.parse::<f64>().unwrap()).sum();
            assert!(threads >= 1.0 && cpu >= 0.0, "{l}");
            assert!(cpu <= threads * (wall + 10.0), "{l}");
        }
        for v in &f[2..6] {
            assert!(v.parse::<f64>().unwrap() >= 0.0);
        }
        assert!(["none", "fill", "reuse"].contains(&f[11]), "{l}");
    }
    let svg = std::fs::read_to_string(dir.join("st/plot.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains(">trace<") && svg.contains(">frame<"));
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&dir.join("one.exr")),
        "--size",
        "16x12",
        "--frames",
        "2..3",
        "--plot",
        s(&dir.join("plot.png")),
        "--quiet",
    ]);
    assert!(std::fs::read(dir.join("plot.png"))
        .unwrap()
        .starts_with(b"\x89PNG"));

    // A file baked from another static scene is refused.
    let mut other = render_scene::scene();
    other.nodes[0].transform =
        common::build::placed(glam::Vec3::new(0.0, 0.1, 0.0), glam::Quat::IDENTITY);
    let other_path = dir.join("other.glb");
    subfield::import::write_gltf(&other, &other_path).unwrap();
    let o = subfield(&[
        "render",
        s(&other_path),
        "--baked",
        s(&psf),
        "-o",
        s(&dir.join("x/f.#.exr")),
        "--size",
        "8x8",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("re-bake"));
    assert!(!dir.join("x").exists());
}

#[test]
fn bad_input_gives_one_line_and_writes_nothing() {
    let dir = temp_dir("bad");
    let scene = write_scene(&dir);
    let a_file = dir.join("a_file");
    std::fs::write(&a_file, b"x").unwrap();
    let out = dir.join("out");
    let pat = dir.join("out/f.####.exr");
    let (sc, p) = (s(&scene).to_string(), s(&pat).to_string());
    let missing = s(&dir.join("missing.glb")).to_string();
    let under_file = s(&a_file.join("f.#.exr")).to_string();
    let no_hash = s(&dir.join("out/still.exr")).to_string();
    let two_runs = s(&dir.join("out/f.#.#.exr")).to_string();
    let png = s(&dir.join("out/f.####.png")).to_string();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec![&missing, "-o", &p], "missing.glb"),
        (vec![&sc, "-o", &under_file], "a_file"),
        (vec![&sc, "-o", &p, "--frames", "5..2"], "--frames"),
        (vec![&sc, "-o", &p, "--frames", "x..2"], "--frames"),
        (vec![&sc, "-o", &p, "--frames", "0..10,x"], "\"x\""),
        (vec![&sc, "-o", &p, "--frames", "0..10:0"], "step"),
        (
            vec![&sc, "-o", &p, "--frames", "0..4000000000"],
            "more than the 10000000",
        ),
        (vec![&sc, "-o", &png, "--frames", "0..3"], ".exr"),
        (vec![&sc, "-o", &no_hash, "--frames", "1,4"], "'#'"),
        (vec![&sc, "-o", &no_hash, "--frames", "0..3"], "'#'"),
        (vec![&sc, "-o", &no_hash], "'#'"),
        (
            vec![&sc, "-o", &two_runs, "--frames", "0..3"],
            "runs of '#'",
        ),
        (vec![&sc, "-o", &p, "--camera", "nope"], "main, side"),
        (vec![&sc, "-o", &p, "--size", "640"], "--size"),
        (vec![&sc, "-o", &p, "--size", "0x10"], "--size"),
        (vec![&sc, "-o", &p, "--shard", "2/2"], "--shard"),
        (vec![&sc, "-o", &p, "--shard", "1/0"], "--shard"),
        (
            vec![&sc, "-o", &p, "--frames-in-flight", "0"],
            "--frames-in-flight 0",
        ),
        (vec![&sc, "-o", &p, "--animation", "dance"], "dance"),
        (vec![&sc, "-o", &p, "--look-from", "0,0,1"], "--look-at"),
        (
            vec![&sc, "-o", &p, "--look-from", "0,0,1", "--look-at", "0,0,1"],
            "same point",
        ),
        (vec![&sc, "-o", &p, "--aov", "depth,velocity"], "velocity"),
        (vec![&sc, "-o", &p, "--fps", "0"], "--fps"),
        (vec![&sc, "-o", &p, "--plot", "x.pdf"], "--plot"),
        (
            vec![&sc, "-o", &p, "--baked", s(&a_file)],
            "a_file: not a baked subfield file",
        ),
    ];
    for (args, needle) in cases {
        let mut full = vec!["render"];
        full.extend(args.iter().copied());
        if !args.contains(&"--size") {
            full.extend(["--size", "8x8"]);
        }
        let o = subfield(&full);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert_eq!(err.lines().count(), 1, "{args:?}: not one line: {err}");
        assert!(
            err.starts_with("error: ") && err.contains(needle),
            "{args:?}: {err}"
        );
        assert!(!out.exists(), "{args:?} wrote {:?}", files_under(&out));
        assert_eq!(
            files_under(&dir).len(),
            2,
            "{args:?} left files: {:?}",
            files_under(&dir)
        );
    }
}

#[test]
fn negative_numbers_are_values_not_flags() {
    let dir = temp_dir("negative");
    let scene = write_scene(&dir);
    let out = dir.join("neg/f.#.exr");
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&out),
        "--frames",
        "0..1",
        "--size",
        "8x8",
        "--look-from",
        "-2,1.5,-3",
        "--look-at",
        "-0.5,0,0",
        "--up",
        "-0,1,0",
        "--quiet",
    ]);
    assert_eq!(files_under(&dir.join("neg")).len(), 1);
    // A negative value reaches our own check (one line naming the flag), not clap's.
    for (flag, value) in [("--yfov", "-5"), ("--fps", "-24")] {
        let mut args = vec!["render", s(&scene), "-o", s(&out), "--size", "8x8"];
        args.extend(["--look-from", "0,0,3", "--look-at", "0,0,0", flag, value]);
        let o = subfield(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.starts_with("error: ") && err.contains(flag), "{err}");
    }
}

#[test]
fn frame_lists_steps_and_single_frames() {
    let dir = temp_dir("frame_lists");
    let scene = write_scene(&dir);
    let render = |sub: &str, frames: &str| {
        let out = dir.join(format!("{sub}/f.#.exr"));
        ok(&[
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            frames,
            "--size",
            "8x8",
            "--quiet",
        ]);
        files_under(&dir.join(sub))
    };
    assert_eq!(render("one", "5"), [PathBuf::from("f.5.exr")]);
    assert_eq!(
        render("list", "0..7:3,10, 2..4"),
        ["f.0.exr", "f.10.exr", "f.2.exr", "f.3.exr", "f.6.exr"].map(PathBuf::from)
    );
    // A single frame needs no '#'.
    let still = dir.join("still.exr");
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&still),
        "--frames",
        "3",
        "--size",
        "8x8",
        "--quiet",
    ]);
    assert!(still.is_file());
    // Shards split the listed frames by frame number.
    let out = dir.join("shard/f.#.exr");
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&out),
        "--frames",
        "0..7:3",
        "--shard",
        "1/2",
        "--size",
        "8x8",
        "--quiet",
    ]);
    // 0, 3, 6: shard 1/2 has the odd one.
    assert_eq!(files_under(&dir.join("shard")), [PathBuf::from("f.3.exr")]);
}

#[test]
fn frames_past_the_end_warn_once() {
    let dir = temp_dir("past_end");
    let scene = write_scene(&dir);
    // One second of animation at 24 fps: frames 0..=24.
    let run = |frames: &str| {
        let o = ok(&[
            "render",
            s(&scene),
            "-o",
            s(&dir.join("out/f.#.exr")),
            "--frames",
            frames,
            "--size",
            "8x8",
        ]);
        String::from_utf8_lossy(&o.stderr)
            .lines()
            .filter(|l| l.starts_with("warning:") && l.contains("--frames"))
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    let w = run("23..27");
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("past the end") && w[0].contains("frame 24"),
        "{w:?}"
    );
    assert!(run("22..25").is_empty());
}

#[test]
fn cameras_by_index_and_not_with_look_from() {
    let dir = temp_dir("camera_index");
    // The test scene with its cameras and their nodes unnamed.
    let mut b = render_scene::scene();
    for c in &mut b.cameras {
        c.name = None;
    }
    for n in b.nodes.iter_mut().filter(|n| n.camera.is_some()) {
        n.name = None;
    }
    let scene = dir.join("unnamed.glb");
    subfield::import::write_gltf(&b, &scene).unwrap();
    let render = |camera: &str| {
        let out = dir.join(format!("c{camera}.exr"));
        ok(&[
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "0",
            "--size",
            "8x8",
            "--camera",
            camera,
            "--quiet",
        ]);
        std::fs::read(out).unwrap()
    };
    assert_ne!(render("0"), render("1"), "two cameras, one picture");
    let fail = |args: &[&str], needle: &str| {
        let o = subfield(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.starts_with("error: ") && err.contains(needle), "{err}");
    };
    let out = dir.join("x/f.#.exr");
    fail(
        &[
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--camera",
            "2",
            "--size",
            "8x8",
        ],
        "index",
    );
    fail(
        &[
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--camera",
            "0",
            "--look-from",
            "0,0,3",
            "--look-at",
            "0,0,0",
            "--size",
            "8x8",
        ],
        "--camera",
    );
    assert!(!dir.join("x").exists());
}

#[test]
fn threads_zero_is_all_cores_in_every_command() {
    for cmd in ["render", "bake", "demo"] {
        let o = ok(&[cmd, "--help"]);
        let help = String::from_utf8_lossy(&o.stdout);
        assert!(
            help.contains("0 or absent: all cores"),
            "{cmd} --help: {help}"
        );
    }
    let dir = temp_dir("threads0");
    let scene = write_scene(&dir);
    ok(&[
        "render",
        s(&scene),
        "-o",
        s(&dir.join("f.exr")),
        "--frames",
        "0",
        "--size",
        "8x8",
        "--threads",
        "0",
        "--quiet",
    ]);
}

#[test]
fn one_of_a_thing_is_singular() {
    let dir = temp_dir("plural");
    let scene = write_scene(&dir);
    let o = ok(&[
        "render",
        s(&scene),
        "-o",
        s(&dir.join("f.exr")),
        "--frames",
        "2",
        "--size",
        "8x8",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("rendered 1 frame ("), "{err}");
    for wrong in ["1 frames", "1 instances", "1 triangles"] {
        assert!(!err.contains(&format!(" {wrong}")), "{wrong}: {err}");
    }
}
