//! USD simulation caches (issue 39), checked against Pixar's own library: the scenes are
//! written by `tests/usd/make_scenes.py` with usd-core, which also evaluates every frame
//! itself (`GetPointsAttr().Get(t)`, `ComputeLocalToWorldTransform(t)`). Here the
//! camera's rays are cast against those triangles by brute force and the depth compared
//! with the rendered Z AOV. Without usd-core (`pip install usd-core`) the tests skip on a
//! developer's machine and fail under CI (`.ci/run` installs it).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use common::exr_read::{channel, read_exr};
use common::render_scene::temp_dir;
use glam::{Mat4, Vec3};
use serde_json::Value;
use subfield::import;
use subfield::render::{self, Aovs, FrameRange, LookAt, PixelType, RenderOptions};
use subfield::scene::{ClipSelection, Scene, TriangleSoup};
use subfield::{BruteForce, Intersector, Ray};

const W: usize = 90;
const H: usize = 60;

/// The scenes, written once per test run; `None` (skipped) without usd-core outside CI.
fn scenes() -> Option<&'static Path> {
    static DIR: OnceLock<Option<PathBuf>> = OnceLock::new();
    DIR.get_or_init(|| {
        let has_pxr = Command::new("python3")
            .args(["-c", "import pxr.Usd"])
            .status()
            .is_ok_and(|s| s.success());
        if !common::farm::need(
            "usd_scenes",
            has_pxr,
            "usd-core (python3 -m pip install usd-core)",
        ) {
            return None;
        }
        let dir = std::env::temp_dir().join(format!("subfield-usd-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/usd/make_scenes.py");
        let out = Command::new("python3")
            .arg(&script)
            .arg(&dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "make_scenes.py failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        Some(dir)
    })
    .as_deref()
}

fn quiet(_: render::RenderEvent<'_>) {}

/// The Z AOV of `frame`, rendered at W x H.
fn render_depth(scene: &Scene, dir: &Path, frame: u32) -> Vec<f32> {
    let opts = RenderOptions {
        output: dir.join("f.#.exr"),
        frames: Some(
            FrameRange {
                start: frame,
                end: frame + 1,
            }
            .into(),
        ),
        width: W as u32,
        height: H as u32,
        aovs: Aovs {
            depth: true,
            ..Default::default()
        },
        ..Default::default()
    };
    render::render_sequence(scene, &opts, &mut quiet).unwrap();
    let (w, h, chans) = read_exr(&dir.join(format!("f.{frame}.exr")));
    assert_eq!((w, h), (W, H));
    channel(&chans, "Z").to_vec()
}

/// usd-core's world, in our axes and metres: `metersPerUnit`, and Z up turned to Y up
/// (`(x, y, z) → (x, z, −y)`).
fn to_ours(reference: &Value) -> Mat4 {
    let m = reference["metersPerUnit"].as_f64().unwrap() as f32;
    let turn = match reference["upAxis"].as_str().unwrap() {
        "Z" => Mat4::from_cols_array(&[
            1.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, -1.0, 0.0, //
            0.0, 1.0, 0.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        ]),
        _ => Mat4::IDENTITY,
    };
    Mat4::from_scale(Vec3::splat(m)) * turn
}

fn floats(v: &Value) -> Vec<f32> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect()
}

/// The reference triangles of one frame, in our world.
fn reference_triangles(reference: &Value, frame: u32) -> Vec<[Vec3; 3]> {
    let conv = to_ours(reference);
    let t = floats(&reference["frames"][frame.to_string()]["triangles"]);
    t.chunks_exact(9)
        .map(|c| {
            let p = |k: usize| conv.transform_point3(Vec3::new(c[k], c[k + 1], c[k + 2]));
            [p(0), p(3), p(6)]
        })
        .collect()
}

/// Depth per pixel by brute force, from usd-core's camera and triangles of `frame`:
/// pixel centres, the vertical aperture over the focal length giving the field of view,
/// the image W x H (the apertures' aspect), depth the distance to the hit.
fn reference_depth(reference: &Value, frame: u32) -> Vec<f32> {
    let f = &reference["frames"][frame.to_string()];
    let tris = reference_triangles(reference, frame);
    let cam = &f["camera"];
    // USD's row-vector matrix read column-major is the column-vector matrix.
    let m: Vec<f32> = floats(&cam["matrix"]);
    let world = to_ours(reference) * Mat4::from_cols_slice(&m);
    let origin = world.transform_point3(Vec3::ZERO);
    let tan = (cam["verticalAperture"].as_f64().unwrap()
        / (2.0 * cam["focalLength"].as_f64().unwrap())) as f32;
    let aspect = W as f32 / H as f32;
    let bf = BruteForce::new(&tris);
    let mut out = Vec::with_capacity(W * H);
    for y in 0..H {
        for x in 0..W {
            let cx = (2.0 * (x as f32 + 0.5) / W as f32 - 1.0) * aspect * tan;
            let cy = (1.0 - 2.0 * (y as f32 + 0.5) / H as f32) * tan;
            let dir = world.transform_vector3(Vec3::new(cx, cy, -1.0)).normalize();
            let r = Ray::new(origin, dir);
            out.push(bf.intersect(&r).map_or(f32::INFINITY, |h| h.t));
        }
    }
    out
}

/// Pixels whose depth differs (a hit against a miss, or more than 0.1 % apart).
fn pixels_off(got: &[f32], want: &[f32]) -> usize {
    got.iter()
        .zip(want)
        .filter(|(&g, &w)| {
            if g.is_finite() != w.is_finite() {
                return true;
            }
            g.is_finite() && (g - w).abs() > 1e-3 * w
        })
        .count()
}

/// Renders `frames` of `name` and compares each with usd-core's evaluation: at most
/// 0.1 % of the pixels off, and something hit.
fn agrees(name: &str, frames: &[u32]) -> Scene {
    let dir = scenes().unwrap();
    let scene = import::load(&dir.join(format!("{name}.usda"))).unwrap();
    let reference: Value =
        serde_json::from_slice(&std::fs::read(dir.join(format!("{name}.json"))).unwrap()).unwrap();
    let out = temp_dir(&format!("usd-{name}"));
    for &frame in frames {
        let got = render_depth(&scene, &out, frame);
        let want = reference_depth(&reference, frame);
        let hits = want.iter().filter(|z| z.is_finite()).count();
        assert!(
            hits > W * H / 10,
            "{name} frame {frame}: the view shows the scene ({hits} hits)"
        );
        let off = pixels_off(&got, &want);
        assert!(
            off * 1000 <= W * H,
            "{name} frame {frame}: {off} of {} pixels off the usd-core reference",
            W * H
        );
    }
    let _ = std::fs::remove_dir_all(&out);
    scene
}

#[test]
fn shattering_cache_agrees_with_usd_core() {
    if scenes().is_none() {
        return;
    }
    let scene = agrees("shatter", &[1, 4, 8]);
    // The default frames are the stage's startTimeCode..endTimeCode, at its rate.
    assert_eq!(scene.fps, Some(24.0));
    assert_eq!(scene.time_range, Some((1.0 / 24.0, 8.0 / 24.0)));
    // The ground is static; the debris (time-sampled points) and the spinner's cube
    // (time-sampled xformOps on its parent) move.
    let split = scene.split(ClipSelection::All);
    let s = split.summary();
    assert_eq!((s.static_triangles, s.dynamic_instances), (2, 2), "{s}");
    // Z up turned into Y up, centimetres into metres: the ground (12 m square at z = 0
    // in the file) lies at y = 0, spanning x and z; the camera is above it. (Depth alone
    // would not see the turn: the whole world turns with the camera.)
    let ground = scene.static_triangles(&split);
    let (lo, hi) = ground.bounds().unwrap();
    assert!(lo.y.abs() < 1e-6 && hi.y.abs() < 1e-6, "{lo} {hi}");
    assert!(
        (hi.x - lo.x - 12.0).abs() < 1e-4 && (hi.z - lo.z - 12.0).abs() < 1e-4,
        "{lo} {hi}"
    );
    let cam = scene.camera_at(split.selection, 1.0 / 24.0, None).unwrap();
    assert!(cam.position.y > 4.0, "{}", cam.position);
    // The shards fly apart: their spread grows by half from the first frame to the last.
    let debris = scene
        .nodes
        .iter()
        .position(|n| n.name.as_deref() == Some("/World/Debris"))
        .unwrap() as u32;
    let spread = |frame: f32| {
        let mut soup = TriangleSoup::new();
        scene.dynamic_triangles_at(&split, frame / 24.0, &mut soup);
        let mut corners = soup
            .positions
            .iter()
            .zip(&soup.node)
            .filter(|(_, &n)| n == debris)
            .flat_map(|(t, _)| t.iter().copied());
        let first = corners.next().unwrap();
        let (lo, hi) = corners.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
        (hi - lo).length()
    };
    assert!(
        spread(8.0) > 1.5 * spread(1.0),
        "{} vs {}",
        spread(8.0),
        spread(1.0)
    );
}

#[test]
fn changing_topology_agrees_and_carries_velocities() {
    if scenes().is_none() {
        return;
    }
    let scene = agrees("fluid", &[1, 2, 5, 8]);
    let split = scene.split(ClipSelection::All);
    let mut soup = TriangleSoup::new();
    let mut counts = Vec::new();
    for f in [1.0, 2.0, 5.0, 8.0] {
        scene.dynamic_triangles_at(&split, f / 24.0, &mut soup);
        counts.push(soup.len());
    }
    // 2 + f quads at frame f, two triangles each.
    assert_eq!(counts, [6, 8, 14, 20]);
    // The motion AOV's next frame: frame 2's triangles carried by their velocities
    // (0, 1.2, 0) units a second to frame 3, not frame 3's other triangles.
    let mut now = TriangleSoup::new();
    scene.dynamic_triangles_at(&split, 2.0 / 24.0, &mut now);
    let mut next = TriangleSoup::new();
    scene.dynamic_triangles_carried(&split, 3.0 / 24.0, 2.0 / 24.0, &mut next);
    assert_eq!(next.len(), now.len());
    for (a, b) in now.positions.iter().zip(&next.positions) {
        for k in 0..3 {
            let d = b[k] - a[k];
            assert!((d - Vec3::new(0.0, 0.05, 0.0)).length() < 1e-5, "{d}");
        }
    }
}

#[test]
fn value_clips_render_as_the_one_file() {
    let Some(dir) = scenes() else {
        return;
    };
    let one = import::load(&dir.join("shatter.usda")).unwrap();
    let clips = import::load(&dir.join("clips/shot.usda")).unwrap();
    let out = temp_dir("usd-clips");
    for frame in [1, 4, 8] {
        let a = render_depth(&one, &out.join("one"), frame);
        let b = render_depth(&clips, &out.join("clips"), frame);
        assert_eq!(
            pixels_off(&a, &b),
            0,
            "frame {frame}: the clips differ from the one file"
        );
        assert!(a.iter().any(|z| z.is_finite()));
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// Broken inputs: one line naming the file (and the prim and attribute where there is
/// one); no panic.
#[test]
fn bad_inputs_fail_with_one_line() {
    let Some(dir) = scenes() else {
        return;
    };
    let bad = dir.join("bad");
    let cases: &[(&str, &[&str])] = &[
        (
            "indices.usda",
            &["/World/Broken.faceVertexIndices", "7", "out of range"],
        ),
        ("syntax.usda", &["syntax.usda"]),
        ("truncated.usdc", &["truncated.usdc"]),
        // The USD reader panics on it (a length that overflows its allocation): an
        // error like the others, naming the prim being read.
        ("overflow.usdc", &["/World/Sheet", "probably damaged"]),
        ("cycle_a.usda", &["cycle"]),
        ("missing.usda", &["nowhere.usda"]),
        (
            "inner/outside.usda",
            &["outside_target.usda", "leaves the scene's folder"],
        ),
    ];
    for (file, needles) in cases {
        let path = bad.join(file);
        let e = match import::load(&path) {
            Ok(_) => panic!("{file}: read without error"),
            Err(e) => e.to_string(),
        };
        assert!(!e.contains('\n'), "{file}: not one line: {e}");
        assert!(
            e.contains(&path.display().to_string()),
            "{file}: names no file: {e}"
        );
        for n in *needles {
            assert!(e.contains(n), "{file}: {e:?} does not say {n:?}");
        }
    }
}

/// The command line on a broken file: a failure, one line, no frame written.
#[test]
fn render_of_a_broken_file_writes_nothing() {
    let Some(dir) = scenes() else {
        return;
    };
    let out = temp_dir("usd-bad-cli");
    let run = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .arg("render")
        .arg(dir.join("bad/indices.usda"))
        .arg("-o")
        .arg(out.join("f.#.exr"))
        .output()
        .unwrap();
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("/World/Broken.faceVertexIndices"), "{err}");
    assert_eq!(
        std::fs::read_dir(&out).unwrap().count(),
        0,
        "wrote something"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// `subfield render PATH`, which must fail: its exit code and its error message, the
/// one line it writes on stderr (asserted to be one line; with `json`, an `error` event
/// whose `exit_code` is the process's, and its `message`; else the line after
/// `error: `). No backtrace is asked for (the default panic report would add lines);
/// the command is given 60 s.
fn render_error(path: &Path, out: &Path, json: bool) -> (Option<i32>, String) {
    render_error_within(path, out, json, None)
}

/// [`render_error`], the command run with its address space limited to `kib` KiB
/// (`ulimit -v`) where given.
fn render_error_within(
    path: &Path,
    out: &Path,
    json: bool,
    kib: Option<u64>,
) -> (Option<i32>, String) {
    let bin = env!("CARGO_BIN_EXE_subfield");
    let mut cmd = match kib {
        Some(kib) => {
            let mut sh = Command::new("sh");
            sh.args(["-c", &format!("ulimit -v {kib} && exec \"$0\" \"$@\""), bin]);
            sh
        }
        None => Command::new(bin),
    };
    cmd.arg("render")
        .arg(path)
        .arg("-o")
        .arg(out.join("f.#.exr"))
        .env_remove("RUST_BACKTRACE")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    if json {
        cmd.args(["--log-format", "json"]);
    }
    let mut child = cmd.spawn().unwrap();
    let clock = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if clock.elapsed().as_secs() > 60 {
            let _ = child.kill();
            panic!("{}: still reading after 60 s", path.display());
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let run = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr).into_owned();
    let code = run.status.code();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(
        lines.len(),
        1,
        "{} (json {json}): not one line: {err}",
        path.display()
    );
    let message = if json {
        let v: Value = serde_json::from_str(lines[0]).unwrap();
        assert_eq!(v["event"], "error", "{err}");
        assert_eq!(v["exit_code"].as_i64(), code.map(i64::from), "{err}");
        v["message"].as_str().unwrap().to_string()
    } else {
        lines[0]
            .strip_prefix("error: ")
            .unwrap_or_else(|| panic!("not an error line: {err}"))
            .to_string()
    };
    assert!(
        message.starts_with(&path.display().to_string()),
        "names another file: {message}"
    );
    (code, message)
}

/// The command on a `.usdc` whose array length is corrupt: one line naming the file and
/// an exit code, in text and as a JSON event; no panic's report, no frame. The USD
/// reader panics on a length past what a length can address (bad input, 3); a length
/// beyond what the file's bytes can decode to is refused before it is allocated (bad
/// input, 3: without the command allocator's bound, `big.usdc` took 6 GiB and seconds
/// before the reader's own error, which does not say "corrupt array length"); one
/// within that bound but beyond the memory the process may have is out of memory (5:
/// the allocator's failure is an error line, not an abort), here under a 768 MiB limit.
#[test]
fn a_corrupt_array_length_is_one_line_and_an_exit_code() {
    let Some(dir) = scenes() else {
        return;
    };
    let out = temp_dir("usd-corrupt-cli");
    let damaged = "the file is probably damaged (a corrupt array length)";
    for (file, code, says, kib) in [
        ("overflow.usdc", 3, "probably damaged", None),
        ("huge.usdc", 3, damaged, None),
        ("big.usdc", 3, damaged, None),
        // 1.5 times its own bound (240 KB: 8,192 times that): refused only where the
        // root layer, which the reader opens twice, counts once.
        ("wide.usdc", 3, damaged, None),
        (
            "short.usdc",
            5,
            "out of memory while reading it",
            Some(768 << 10),
        ),
    ] {
        for json in [false, true] {
            let path = dir.join("bad").join(file);
            let (got, message) = render_error_within(&path, &out, json, kib);
            assert_eq!(got, Some(code), "{file} (json {json}): {message}");
            assert!(message.contains(says), "{file}: {message}");
        }
    }
    // Within the bound and without a limit, the reader's own error (the file is too
    // short for the length): the bound refuses only what no file of this size holds.
    let (got, message) = render_error(&dir.join("bad").join("short.usdc"), &out, false);
    assert_eq!(got, Some(3), "{message}");
    assert!(!message.contains(damaged), "{message}");
    assert_eq!(
        std::fs::read_dir(&out).unwrap().count(),
        0,
        "wrote something"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// A prim name from the file with a line break in it (the USD reader accepts a quoted
/// name with any characters, and such a name can send its traversal into recursion
/// without end; found by the fuzz target) is refused naming its line, escaped, in one
/// line. Written here as text: no usd-core needed.
#[test]
fn a_name_with_a_line_break_stays_one_line() {
    let dir = temp_dir("usd-name-break");
    let path = dir.join("broken.usda");
    std::fs::write(
        &path,
        "#usda 1.0\n\ndef Xform \"World\"\n{\n    def Mesh \"Sh\n urface\"\n    {\n        \
         int[] faceVertexCounts = [3]\n        int[] faceVertexIndices = [0, 1, 7]\n        \
         point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]\n    }\n}\n",
    )
    .unwrap();
    let e = match import::load(&path) {
        Ok(_) => panic!("read without error"),
        Err(e) => e.to_string(),
    };
    assert!(!e.contains('\n'), "not one line: {e:?}");
    assert!(
        e.contains("line 5: the prim name \"Sh\\n urface\" is not a name"),
        "{e:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Malformed scene paths and names that send the USD reader (`openusd` 0.6) into
/// recursion or a loop without end (found by the fuzz target): a relationship's target
/// `<r }>`, a connection's `<}>` (both overflowed the stack), an xformOp name that is no
/// attribute name (`xformOp:t}`: the reader spun for minutes). Each is one line naming
/// the file and where, exit 3, at once (the command is given 60 s).
#[test]
fn paths_that_never_resolve_are_refused_at_once() {
    let dir = temp_dir("usd-endless-paths");
    let mesh =
        "int[] faceVertexCounts = [3]\n        int[] faceVertexIndices = [0, 1, 2]\n        \
                point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]";
    let head = "#usda 1.0\ndef \"W\"\n{\n    def Mesh \"Pl\" (apiSchemas = [\"MaterialBindingAPI\"])\n    {\n";
    let cases = [
        (
            "binding.usda",
            format!("{head}        {mesh}\n        rel material:binding = <r }}>\n    }}\n}}\n"),
            "line 9: the path <r }> is not a scene path",
        ),
        (
            "connection.usda",
            format!(
                "{head}        {mesh}\n        rel material:binding = </W/M>\n    }}\n    \
                 def Material \"M\"\n    {{\n        token outputs:surface.connect = <}}>\n    }}\n}}\n"
            ),
            "line 13: the path <}> is not a scene path",
        ),
        (
            "xformop.usda",
            format!(
                "{head}        {mesh}\n        double3 xformOp:translate = (0, 0, 1)\n        \
                 uniform token[] xformOpOrder = [\"xformOp:t}}\"]\n    }}\n}}\n"
            ),
            "/W/Pl.xformOpOrder: \"xformOp:t}\" is not an attribute name",
        ),
    ];
    for (file, text, says) in cases {
        let path = dir.join(file);
        std::fs::write(&path, text).unwrap();
        let (code, message) = render_error(&path, &dir.join("out"), false);
        assert_eq!(code, Some(3), "{file}: {message}");
        assert!(
            message.contains(says),
            "{file}: {message:?} does not say {says:?}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// 100,000 nested prims: the USD reader's parser recurses once a level and overflows
/// the stack (8 MB); the command says so in one line naming the file, exit 3, not an
/// abort (`cli::guard`).
#[test]
fn nesting_beyond_the_stack_is_one_line() {
    let dir = temp_dir("usd-deep");
    let path = dir.join("deep.usda");
    let n = 100_000;
    let mut text = String::from("#usda 1.0\n");
    for i in 0..n {
        text.push_str(&format!("def \"P{i}\" {{\n"));
    }
    text.push_str(&"}\n".repeat(n));
    std::fs::write(&path, text).unwrap();
    for json in [false, true] {
        let (code, message) = render_error(&path, &dir.join("out"), json);
        assert_eq!(code, Some(3), "json {json}: {message}");
        assert!(
            message.contains("reading it overflowed the stack"),
            "{message}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn usdz_package_renders_as_the_file() {
    let Some(dir) = scenes() else {
        return;
    };
    let one = import::load(&dir.join("shatter.usda")).unwrap();
    let packed = import::load(&dir.join("shatter.usdz")).unwrap();
    let out = temp_dir("usd-usdz");
    let a = render_depth(&one, &out.join("usda"), 4);
    let b = render_depth(&packed, &out.join("usdz"), 4);
    assert_eq!(pixels_off(&a, &b), 0, "the package differs from the file");
    let _ = std::fs::remove_dir_all(&out);
}

/// UsdPreviewSurface inputs and a diffuseColor texture onto the model's material; sphere
/// and distant lights in the model's units (docs/INPUTS.md): luminance
/// `intensity · 2^exposure` nits, over 683, times `π r²` (sphere) or `π sin²(angle/2)`
/// (distant).
#[test]
fn preview_surface_materials_and_lights() {
    let Some(dir) = scenes() else {
        return;
    };
    let scene = import::load(&dir.join("looks.usda")).unwrap();
    let material_of = |name: &str| {
        let node = scene
            .nodes
            .iter()
            .find(|n| n.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no node {name}"));
        let mesh = &scene.meshes[node.mesh.unwrap()];
        &scene.materials[mesh.primitives[0].material as usize]
    };
    let plain = material_of("/World/Plain");
    assert_eq!(plain.base_color, glam::Vec4::new(0.8, 0.2, 0.1, 1.0));
    assert_eq!((plain.metallic, plain.roughness), (0.25, 0.75));
    assert_eq!(plain.emissive, Vec3::new(0.5, 0.25, 0.0));
    assert!(plain.base_color_texture.is_none());
    let textured = material_of("/World/Textured");
    let t = textured.base_color_texture.expect("a diffuseColor texture");
    let img = &scene.images[scene.textures[t.texture as usize].image as usize];
    assert_eq!((img.width, img.height), (4, 4));
    // The top-left texel is blue, its neighbour red (the script's checker).
    assert_eq!(&img.rgba8[..8], &[0, 0, 255, 255, 255, 0, 0, 255]);
    // st (0, 0) is the image's bottom-left corner: v = 1 in the model.
    let uvs = scene.meshes[1].primitives[0].uvs.as_ref().unwrap();
    assert_eq!(uvs[0], glam::Vec2::new(0.0, 1.0));

    let light = |name: &str| {
        scene
            .lights
            .iter()
            .find(|l| l.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no light {name}"))
    };
    let bulb = light("/World/Bulb");
    let want = 1000.0 * 2.0 * std::f64::consts::PI * 0.1 * 0.1 / 683.0;
    assert!(
        (f64::from(bulb.intensity) - want).abs() < 1e-6 * want,
        "{}",
        bulb.intensity
    );
    assert_eq!(bulb.color, Vec3::new(1.0, 0.5, 0.25));
    let sun = light("/World/Sun");
    let s = (0.53f64.to_radians() * 0.5).sin();
    let want = 50000.0 * std::f64::consts::PI * s * s / 683.0;
    assert!(
        (f64::from(sun.intensity) - want).abs() < 1e-5 * want,
        "{}",
        sun.intensity
    );
}

/// Rect and disk lights as emitting cards (docs/INPUTS.md): the card's material has the
/// light's radiance, `intensity · 2^exposure · color / 683` (over the area with
/// `normalize`), a camera below sees that radiance, and the card's back is dark.
#[test]
fn rect_and_disk_lights_are_emitting_cards() {
    let Some(dir) = scenes() else {
        return;
    };
    let scene = import::load(&dir.join("area.usda")).unwrap();
    let emission = |name: &str| {
        let node = scene
            .nodes
            .iter()
            .find(|n| n.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no node {name}"));
        let mesh = &scene.meshes[node.mesh.expect("the light's card")];
        let m = &scene.materials[mesh.primitives[0].material as usize];
        assert!(!m.double_sided, "{name}: emits from its front only");
        (
            m.emissive * m.emissive_strength,
            mesh.primitives[0].triangles.len(),
        )
    };
    // 683 nits × 2^1 × (1, 0.5, 0.25) / 683.
    let (panel, tris) = emission("/World/Panel");
    assert_eq!(tris, 2);
    assert!(
        (panel - Vec3::new(2.0, 1.0, 0.5)).abs().max_element() < 1e-6,
        "{panel}"
    );
    // 100 nits normalised by the fan's area (32 triangles of radius 0.5).
    let (spot, tris) = emission("/World/Spot");
    let n = subfield::import::USD_DISK_SEGMENTS;
    assert_eq!(tris, n as usize);
    let area = 0.5 * f64::from(n) * 0.25 * (std::f64::consts::TAU / f64::from(n)).sin();
    let want = (100.0 / 683.0 / area) as f32;
    assert!(
        (spot - Vec3::splat(want)).abs().max_element() < 1e-5 * want,
        "{spot} vs {want}"
    );

    // Seen in the pixels: the centre pixel of a camera under each light, and over the
    // panel (its back).
    let out = temp_dir("usd-area");
    let centre = |name: &str, from: Vec3, at: Vec3| -> Vec3 {
        let opts = RenderOptions {
            output: out.join(format!("{name}.#.exr")),
            frames: Some(FrameRange { start: 0, end: 1 }.into()),
            width: 9,
            height: 9,
            pixel_type: PixelType::Float,
            look_at: Some(LookAt {
                from,
                at,
                up: Vec3::Z,
                yfov_deg: 20.0,
            }),
            ..Default::default()
        };
        render::render_sequence(&scene, &opts, &mut quiet).unwrap();
        let (w, _, chans) = read_exr(&out.join(format!("{name}.0.exr")));
        let i = 4 * w + 4;
        Vec3::new(
            channel(&chans, "R")[i],
            channel(&chans, "G")[i],
            channel(&chans, "B")[i],
        )
    };
    let below = centre("below", Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.0, 2.0, 0.0));
    assert!(
        (below - panel).abs().max_element() < 1e-3,
        "under the panel: {below}"
    );
    let disk = centre("disk", Vec3::new(5.0, 0.5, 0.0), Vec3::new(5.0, 2.0, 0.0));
    assert!(
        (disk - spot).abs().max_element() < 1e-3 * want,
        "under the disk: {disk}"
    );
    let above = centre("above", Vec3::new(0.0, 3.5, 0.0), Vec3::new(0.0, 2.0, 0.0));
    assert!(above.max_element() < 1e-3, "the panel's back: {above}");
    let _ = std::fs::remove_dir_all(&out);
}
