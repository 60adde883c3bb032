//! The EXR header attributes and the position, motion and Cryptomatte AOVs, on scenes
//! built in code, read back with independent readers: `oiiotool --info -v`
//! (OpenImageIO) and OpenEXR's own Python bindings.

mod common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::build::{diffuse, linear, mesh, perspective, placed, SceneBuilder};
use common::render_scene::{quad, temp_dir};
use glam::{Quat, Vec2, Vec3, Vec4};
use serde_json::Value;
use subfield::import;
use subfield::render::{self, Aovs, FrameRange, RenderOptions};
use subfield::scene::{Animation, ClipSelection, Node, Property, Scene, TriangleSoup};
use subfield::{BruteForce, Intersector, Ray};

const W: usize = 64;
const H: usize = 48;
const YFOV: f32 = 0.8;
const FPS: f32 = 24.0;
/// Units a second the slider (or the camera) moves along +X.
const SPEED: f32 = 0.48;
const CAMERA_AT: Vec3 = Vec3::new(0.0, 0.0, 5.0);

/// A backdrop at z = −2, a quad that may slide along +X ("slider", left) and a still
/// quad ("still", right) at z = 0, seen by a camera at (0, 0, 5) looking down −Z that
/// may slide along +X too.
fn scene(dir: &Path, slider_moves: bool, camera_moves: bool) -> PathBuf {
    let mut b = SceneBuilder::new();
    let wall = b.add_material(diffuse("wall", Vec4::new(0.5, 0.5, 0.5, 1.0), 0.9));
    let paint = b.add_material(diffuse("paint", Vec4::new(0.8, 0.2, 0.1, 1.0), 0.9));
    let blue = b.add_material(diffuse("blue paint", Vec4::new(0.1, 0.2, 0.8, 1.0), 0.9));
    let square = |name: &str, centre: Vec3, half: f32, m: u32| {
        mesh(name, vec![quad(centre, Vec3::X * half, Vec3::Y * half, m)])
    };
    let back = b.add_mesh(square("back", Vec3::new(0.0, 0.0, -2.0), 10.0, wall));
    let left = b.add_mesh(square("left", Vec3::new(-1.0, 0.0, 0.0), 0.5, paint));
    let right = b.add_mesh(square("right", Vec3::new(1.0, 0.0, 0.0), 0.5, blue));
    let cam = b.add_camera(perspective("cam", YFOV, None, 0.1, None));
    let node =
        |b: &mut SceneBuilder, name: &str, mesh: Option<usize>, camera: Option<usize>, at: Vec3| {
            let n = b.add_node(Node {
                name: Some(name.into()),
                mesh,
                camera,
                transform: placed(at, Quat::IDENTITY),
                ..Default::default()
            });
            b.add_root(n);
            n
        };
    node(&mut b, "backdrop", Some(back), None, Vec3::ZERO);
    let slider = node(&mut b, "slider", Some(left), None, Vec3::ZERO);
    node(&mut b, "still", Some(right), None, Vec3::ZERO);
    let camera = node(&mut b, "camera", None, Some(cam), CAMERA_AT);
    let slide = |node: usize, from: Vec3| {
        linear(
            node,
            Property::Translation,
            vec![0.0, 1.0],
            [from.to_array(), (from + Vec3::X * SPEED).to_array()].concat(),
        )
    };
    let mut channels = Vec::new();
    if slider_moves {
        channels.push(slide(slider, Vec3::ZERO));
    }
    if camera_moves {
        channels.push(slide(camera, CAMERA_AT));
    }
    if !channels.is_empty() {
        b.add_animation(Animation {
            name: Some("slide".into()),
            channels,
        });
    }
    b.scene.fps = Some(FPS);
    let p = dir.join("scene.glb");
    import::write_gltf(&b.finish(), &p).unwrap();
    p
}

fn quiet(_: render::RenderEvent<'_>) {}

/// Renders `frame` of `scene` with `aovs` to `dir/f.#.exr` and returns its path.
fn render_frame(dir: &Path, scene: &Scene, frame: u32, spp: u32, aovs: Aovs) -> PathBuf {
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
        spp,
        aovs,
        ..Default::default()
    };
    render::render_sequence(scene, &opts, &mut quiet).unwrap();
    dir.join(format!("f.{frame}.exr"))
}

/// The header (matrices as 4×4 lists, rationals as [num, den]) and every channel
/// (non-finite values as null) of an EXR, read by OpenEXR's Python bindings.
const READER: &str = r#"
import sys, json, fractions, OpenEXR, numpy as np
f = OpenEXR.File(sys.argv[1], separate_channels=True)
def conv(v):
    if isinstance(v, fractions.Fraction):
        return [v.numerator, v.denominator]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, tuple) and all(isinstance(x, float) for x in v):
        return list(v)
    if isinstance(v, (str, int, float)):
        return v
    return str(v)
head = {k: conv(v) for k, v in f.header().items()}
chans = {}
for name, ch in f.channels().items():
    a = ch.pixels.astype(np.float64).ravel()
    chans[name] = [float(x) if np.isfinite(x) else None for x in a]
print(json.dumps({"header": head, "channels": chans}))
"#;

struct Exr {
    header: serde_json::Map<String, Value>,
    channels: HashMap<String, Vec<f32>>,
}

fn openexr(path: &Path) -> Exr {
    let o = Command::new("python3")
        .args(["-c", READER])
        .arg(path)
        .output()
        .expect("python3");
    assert!(
        o.status.success(),
        "OpenEXR's Python bindings (installed by .ci/run): {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let channels = v["channels"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, vals)| {
            let vals = vals
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().map_or(f32::INFINITY, |f| f as f32))
                .collect();
            (k.clone(), vals)
        })
        .collect();
    Exr {
        header: v["header"].as_object().unwrap().clone(),
        channels,
    }
}

impl Exr {
    fn ch(&self, name: &str) -> &[f32] {
        self.channels
            .get(name)
            .unwrap_or_else(|| panic!("no channel {name}"))
    }

    fn text(&self, key: &str) -> &str {
        self.header[key]
            .as_str()
            .unwrap_or_else(|| panic!("no text attribute {key}"))
    }

    /// A 4×4 matrix attribute as OpenEXR stores it (row-vector convention).
    fn matrix(&self, key: &str) -> [[f32; 4]; 4] {
        let rows = self.header[key].as_array().unwrap();
        let mut m = [[0.0; 4]; 4];
        for (i, r) in rows.iter().enumerate() {
            for (j, x) in r.as_array().unwrap().iter().enumerate() {
                m[i][j] = x.as_f64().unwrap() as f32;
            }
        }
        m
    }
}

/// `[x y z 1] · M`, divided by `w`.
fn row_transform(m: &[[f32; 4]; 4], p: Vec3) -> Vec3 {
    let v = [p.x, p.y, p.z, 1.0];
    let mut out = [0.0f32; 4];
    for (j, o) in out.iter_mut().enumerate() {
        *o = (0..4).map(|i| v[i] * m[i][j]).sum();
    }
    Vec3::new(out[0], out[1], out[2]) / out[3]
}

fn oiiotool_info(path: &Path) -> String {
    let o = Command::new("oiiotool")
        .args(["--info", "-v"])
        .arg(path)
        .output()
        .expect("oiiotool (Debian's openimageio-tools, installed by .ci/run)");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn ppu(depth: f32) -> f32 {
    // Pixels per world unit across the view at `depth` (square pixels, yfov vertical).
    H as f32 / (2.0 * depth * (YFOV * 0.5).tan())
}

#[test]
fn header_attributes_have_the_right_values() {
    let dir = temp_dir("aov-header");
    let scene = import::load(&scene(&dir, true, true)).unwrap();
    let aovs = Aovs {
        position: true,
        cryptomatte: true,
        ..Default::default()
    };
    let frame = 6;
    let path = render_frame(&dir, &scene, frame, 1, aovs);
    let exr = openexr(&path);
    assert_eq!(exr.header["framesPerSecond"], serde_json::json!([24, 1]));
    assert_eq!(exr.text("software"), render::software());
    assert_eq!(exr.text("software"), "subfield 0.1.0");
    // Linear Rec.709 primaries with a D65 white (DESIGN.md §4): red, green, blue, white.
    let chroma: Vec<f64> = exr.header["chromaticities"]
        .as_array()
        .expect("a chromaticities attribute")
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let rec709 = [0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290];
    assert_eq!(chroma.len(), 8, "{chroma:?}");
    for (got, want) in chroma.iter().zip(rec709) {
        assert!((got - want).abs() < 1e-6, "{chroma:?}");
    }
    // ... and by name, as OpenEXR 3.4's colour interop id.
    assert_eq!(exr.text("colorInteropID"), "lin_rec709_scene");
    let options = exr.text("subfield/options");
    for part in [
        "size=64x48",
        "spp=1",
        "max-depth=4",
        "pixel=half",
        "fps=24",
        "aov=position,cryptomatte",
        "crypto-levels=6",
    ] {
        assert!(options.contains(part), "{part} in {options}");
    }
    // The camera is where the animation puts it at frame 6: worldToCamera maps it to
    // the origin (the camera looks down −Z, so a point ahead has negative z).
    let cam_pos = CAMERA_AT + Vec3::X * SPEED * frame as f32 / FPS;
    let w2c = exr.matrix("worldToCamera");
    assert!(row_transform(&w2c, cam_pos).length() < 1e-5);
    let ahead = row_transform(&w2c, cam_pos - Vec3::Z * 3.0);
    assert!(
        (ahead - Vec3::new(0.0, 0.0, -3.0)).length() < 1e-5,
        "{ahead}"
    );
    // A point seen at a pixel (its P) projects through worldToNDC into that pixel.
    let ndc = exr.matrix("worldToNDC");
    let (px, py) = (px_of(&exr, 12, 30), px_of(&exr, 50, 9));
    for ((x, y), p) in [((12, 30), px), ((50, 9), py)] {
        let n = row_transform(&ndc, p);
        let pixel = Vec2::new((n.x + 1.0) * 0.5 * W as f32, (1.0 - n.y) * 0.5 * H as f32);
        assert!(
            (pixel - Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).length() < 1e-3,
            "pixel ({x}, {y}) projects to {pixel}"
        );
    }
    // OpenImageIO sees the same attributes.
    let info = oiiotool_info(&path);
    for line in [
        "framesPerSecond: 24/1".to_string(),
        "software: \"subfield 0.1.0\"".to_string(),
        format!("subfield/options: \"{options}\""),
        "worldToCamera: ".to_string(),
        "worldToNDC: ".to_string(),
        "chromaticities: 0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3127, 0.329".to_string(),
        "colorInteropID: \"lin_rec709_scene\"".to_string(),
        format!(
            "cryptomatte/{}/name: \"CryptoObject\"",
            render::crypto_key("CryptoObject")
        ),
    ] {
        assert!(info.contains(&line), "{line} in:\n{info}");
    }
    // No time stamp: the same frame rendered again is the same bytes.
    let a = std::fs::read(&path).unwrap();
    let again = render_frame(&dir.join("again"), &scene, frame, 1, aovs);
    assert_eq!(a, std::fs::read(again).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

fn px_of(exr: &Exr, x: usize, y: usize) -> Vec3 {
    let i = y * W + x;
    Vec3::new(exr.ch("P.X")[i], exr.ch("P.Y")[i], exr.ch("P.Z")[i])
}

/// Every triangle of the shown scene at `t`.
fn all_triangles(scene: &Scene, t: f32) -> Vec<[Vec3; 3]> {
    let all = scene.split(ClipSelection::All);
    let mut tris = scene.static_triangles(&all).positions;
    let mut d = TriangleSoup::new();
    scene.dynamic_triangles_at(&all, t, &mut d);
    tris.extend(d.positions);
    tris
}

#[test]
fn position_is_the_brute_force_hit_point() {
    let dir = temp_dir("aov-position");
    let scene = import::load(&scene(&dir, true, true)).unwrap();
    let frame = 5;
    let t = frame as f32 / FPS;
    let path = render_frame(
        &dir,
        &scene,
        frame,
        4,
        Aovs {
            position: true,
            ..Default::default()
        },
    );
    let exr = openexr(&path);
    let tris = all_triangles(&scene, t);
    let bf = BruteForce::new(&tris);
    let origin = CAMERA_AT + Vec3::X * SPEED * t;
    let (tan, aspect) = ((YFOV * 0.5).tan(), W as f32 / H as f32);
    let mut hits = 0;
    for y in 0..H {
        for x in 0..W {
            let cx = (2.0 * (x as f32 + 0.5) / W as f32 - 1.0) * aspect * tan;
            let cy = (1.0 - 2.0 * (y as f32 + 0.5) / H as f32) * tan;
            let r = Ray::new(origin, Vec3::new(cx, cy, -1.0));
            let got = px_of(&exr, x, y);
            match bf.intersect(&r) {
                None => assert_eq!(got, Vec3::ZERO, "({x}, {y}) misses"),
                Some(h) => {
                    hits += 1;
                    let want = r.at(h.t);
                    assert!(
                        (got - want).length() < 1e-4,
                        "({x}, {y}): P {got}, brute {want}"
                    );
                }
            }
        }
    }
    assert_eq!(hits, W * H, "the backdrop fills the view");
    let _ = std::fs::remove_dir_all(&dir);
}

/// What the centre ray of a pixel sees, from its P: the backdrop, the slider or the
/// still quad.
#[derive(Debug, PartialEq)]
enum Seen {
    Backdrop,
    Slider,
    Still,
}

fn seen(p: Vec3) -> Seen {
    if (p.z + 2.0).abs() < 1e-3 {
        Seen::Backdrop
    } else if p.x < 0.0 {
        Seen::Slider
    } else {
        Seen::Still
    }
}

fn motion_case(name: &str, slider_moves: bool, camera_moves: bool, check: impl Fn(Seen) -> Vec2) {
    let dir = temp_dir(name);
    let scene = import::load(&scene(&dir, slider_moves, camera_moves)).unwrap();
    let path = render_frame(
        &dir,
        &scene,
        3,
        1,
        Aovs {
            position: true,
            motion: true,
            ..Default::default()
        },
    );
    let exr = openexr(&path);
    let mut count = HashMap::new();
    for y in 0..H {
        for x in 0..W {
            let i = y * W + x;
            let got = Vec2::new(exr.ch("motion.X")[i], exr.ch("motion.Y")[i]);
            let what = seen(px_of(&exr, x, y));
            *count.entry(format!("{what:?}")).or_insert(0) += 1;
            let want = check(what);
            assert!(
                (got - want).length() < 2e-3,
                "{name}: pixel ({x}, {y}): motion {got}, want {want}"
            );
        }
    }
    assert!(count.len() == 3, "{name}: every part in view: {count:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn motion_of_a_sliding_quad_is_its_distance_in_pixels() {
    let step = SPEED / FPS;
    motion_case("aov-motion-quad", true, false, |s| match s {
        Seen::Slider => Vec2::new(step * ppu(5.0), 0.0),
        _ => Vec2::ZERO,
    });
}

#[test]
fn motion_is_zero_where_nothing_moves() {
    motion_case("aov-motion-still", false, false, |_| Vec2::ZERO);
}

#[test]
fn motion_follows_the_camera_alone() {
    let step = SPEED / FPS;
    motion_case("aov-motion-camera", false, true, |s| match s {
        Seen::Backdrop => Vec2::new(-step * ppu(7.0), 0.0),
        _ => Vec2::new(-step * ppu(5.0), 0.0),
    });
}

/// Cryptomatte ids and coverages of pixel `i` in `kind` (`CryptoObject`…): (id, coverage)
/// per rank.
fn ranks(exr: &Exr, kind: &str, i: usize) -> Vec<(f32, f32)> {
    let mut out = Vec::new();
    for layer in 0.. {
        let name = format!("{kind}{layer:02}");
        if !exr.channels.contains_key(&format!("{name}.R")) {
            break;
        }
        for (id, cov) in [("R", "G"), ("B", "A")] {
            let c = |ch: &str| exr.ch(&format!("{name}.{ch}"))[i];
            out.push((c(id), c(cov)));
        }
    }
    out
}

#[test]
fn cryptomatte_ids_follow_the_manifest_and_edges_sum_to_one() {
    let dir = temp_dir("aov-crypto");
    let scene = import::load(&scene(&dir, true, false)).unwrap();
    let path = render_frame(
        &dir,
        &scene,
        0,
        4,
        Aovs {
            position: true,
            cryptomatte: true,
            ..Default::default()
        },
    );
    let exr = openexr(&path);
    // Three layers of each kind for the default 6 ranks.
    for kind in ["CryptoObject", "CryptoMaterial"] {
        for layer in 0..3 {
            for c in ["R", "G", "B", "A"] {
                exr.ch(&format!("{kind}{layer:02}.{c}"));
            }
        }
        assert!(!exr.channels.contains_key(&format!("{kind}03.R")));
    }
    let manifest = |kind: &str| -> HashMap<String, u32> {
        let key = render::crypto_key(kind);
        assert_eq!(exr.text(&format!("cryptomatte/{key}/name")), kind);
        assert_eq!(
            exr.text(&format!("cryptomatte/{key}/hash")),
            "MurmurHash3_32"
        );
        assert_eq!(
            exr.text(&format!("cryptomatte/{key}/conversion")),
            "uint32_to_float32"
        );
        let m: HashMap<String, String> =
            serde_json::from_str(exr.text(&format!("cryptomatte/{key}/manifest"))).unwrap();
        m.into_iter()
            .map(|(k, v)| (k, u32::from_str_radix(&v, 16).unwrap()))
            .collect()
    };
    let objects = manifest("CryptoObject");
    let materials = manifest("CryptoMaterial");
    assert_eq!(objects.len(), 3, "{objects:?}");
    assert_eq!(objects["slider"], render::crypto_hash("slider"));
    assert_eq!(materials["blue paint"], render::crypto_hash("blue paint"));
    let mut edges = 0;
    for y in 0..H {
        for x in 0..W {
            let i = y * W + x;
            let (object, material) = match seen(px_of(&exr, x, y)) {
                Seen::Backdrop => ("backdrop", "wall"),
                Seen::Slider => ("slider", "paint"),
                Seen::Still => ("still", "blue paint"),
            };
            for (kind, names, name) in [
                ("CryptoObject", &objects, object),
                ("CryptoMaterial", &materials, material),
            ] {
                let r = ranks(&exr, kind, i);
                assert_eq!(r.len(), 6);
                let sum: f32 = r.iter().map(|(_, c)| c).sum();
                // The backdrop fills the view: every sample has an id.
                assert!((sum - 1.0).abs() < 1e-6, "({x}, {y}) {kind}: {r:?}");
                // Ranked by coverage.
                assert!(r.windows(2).all(|w| w[0].1 >= w[1].1), "{r:?}");
                let id = f32::from_bits(names[name]);
                if r[0].1 < 1.0 {
                    edges += 1;
                    assert!(r[1].1 > 0.0);
                } else {
                    // Wholly inside one object: its id (the one the centre ray sees).
                    assert_eq!(r[0].0.to_bits(), id.to_bits(), "({x}, {y}) {kind}");
                }
            }
        }
    }
    assert!(edges > 10, "pixels on an edge: {edges}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_still_frame_has_the_same_channels_as_a_moving_one() {
    // Channel count is fixed by the options (not by what a frame shows).
    let dir = temp_dir("aov-channels");
    let scene = import::load(&scene(&dir, true, false)).unwrap();
    let aovs = Aovs::all();
    let a = openexr(&render_frame(&dir, &scene, 0, 1, aovs));
    let b = openexr(&render_frame(&dir, &scene, 20, 1, aovs));
    let mut na: Vec<_> = a.channels.keys().cloned().collect();
    let mut nb: Vec<_> = b.channels.keys().cloned().collect();
    na.sort();
    nb.sort();
    assert_eq!(na, nb);
    assert_eq!(na, render::channel_names(aovs));
    let _ = std::fs::remove_dir_all(&dir);
}
