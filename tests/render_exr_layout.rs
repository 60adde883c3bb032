//! `--overscan PX` (a data window larger than the display window) and `--compression
//! zip|piz|none`, through the command line, read back by readers that are not ours:
//! `oiiotool --info -v` (OpenImageIO), OpenEXR's Python bindings and the `exr` crate.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::build::{diffuse, mesh, perspective, placed, SceneBuilder};
use common::exr_read::{channel, read_exr};
use common::render_scene::{quad, temp_dir};
use glam::{Quat, Vec3, Vec4};
use subfield::import;
use subfield::scene::{Falloff, LightDef, LightKind, Node};

const W: usize = 40;
const H: usize = 30;
const YFOV: f32 = 0.8;
const CAMERA_Z: f32 = 5.0;
const OVERSCAN: usize = 6;

fn subfield(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args)
        .output()
        .unwrap()
}

/// The size of a pixel at z = 0 (the plane of the quads), seen from the camera.
fn pixel_size() -> f32 {
    2.0 * CAMERA_Z * (YFOV * 0.5).tan() / H as f32
}

/// A grey backdrop at z = −2 and, at z = 0, a red square wholly outside the image, just
/// beyond its left edge (pixel columns −5 to −1 of the image plane), so only an
/// overscan border shows it; a green square inside the image. A camera at (0, 0, 5)
/// looking down −Z, a point light.
fn write_scene(dir: &Path) -> PathBuf {
    let mut b = SceneBuilder::new();
    let grey = b.add_material(diffuse("grey", Vec4::new(0.5, 0.5, 0.5, 1.0), 1.0));
    let red = b.add_material(diffuse("red", Vec4::new(0.9, 0.05, 0.05, 1.0), 1.0));
    let green = b.add_material(diffuse("green", Vec4::new(0.1, 0.8, 0.1, 1.0), 1.0));
    let px = pixel_size();
    let left_edge = -px * W as f32 * 0.5;
    let quads = [
        (
            "backdrop",
            quad(
                Vec3::new(0.0, 0.0, -2.0),
                Vec3::X * 10.0,
                Vec3::Y * 10.0,
                grey,
            ),
        ),
        (
            "outside",
            quad(
                Vec3::new(left_edge - 3.0 * px, 0.0, 0.0),
                Vec3::X * 2.0 * px,
                Vec3::Y * 5.0 * px,
                red,
            ),
        ),
        (
            "inside",
            quad(
                Vec3::new(0.5, 0.3, 0.0),
                Vec3::X * 0.6,
                Vec3::Y * 0.6,
                green,
            ),
        ),
    ];
    for (name, prim) in quads {
        let m = b.add_mesh(mesh(name, vec![prim]));
        let n = b.add_node(Node {
            name: Some(name.into()),
            mesh: Some(m),
            ..Default::default()
        });
        b.add_root(n);
    }
    let cam = b.add_camera(perspective("cam", YFOV, None, 0.05, None));
    let n = b.add_node(Node {
        camera: Some(cam),
        transform: placed(Vec3::new(0.0, 0.0, CAMERA_Z), Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(n);
    let l = b.add_light(LightDef {
        name: Some("lamp".into()),
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity: 20.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let n = b.add_node(Node {
        light: Some(l),
        transform: placed(Vec3::new(0.0, 1.0, 4.0), Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(n);
    let p = dir.join("scene.glb");
    import::write_gltf(&b.finish(), &p).unwrap();
    p
}

/// Renders frame 0 of `scene` to `out` with the test's size and `extra` flags.
fn render(scene: &Path, out: &Path, extra: &[&str]) {
    let size = format!("{W}x{H}");
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--frames",
        "0",
        "--size",
        &size,
        "-q",
    ];
    args.extend_from_slice(extra);
    let o = subfield(&args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
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

#[test]
fn overscan_extends_the_image_plane_and_keeps_the_image_to_the_bit() {
    let dir = temp_dir("exr-overscan");
    let scene = write_scene(&dir);
    // With a diffuse bounce that sees a background: its directions come from the seeds
    // of the camera's pixels, which the border must not shift.
    let aovs = [
        "--aov",
        "depth,normal,diffuse,emission,cryptomatte",
        "--spp",
        "2",
        "--diffuse-bounces",
        "1",
        "--background",
        "0.2,0.25,0.3",
    ];
    let plain = dir.join("plain.exr");
    render(&scene, &plain, &aovs);
    let wide = dir.join("wide.exr");
    let os = OVERSCAN.to_string();
    let preview = dir.join("wide.png");
    let mut args = aovs.to_vec();
    args.extend(["--overscan", &os, "--preview", preview.to_str().unwrap()]);
    render(&scene, &wide, &args);

    // The windows, as OpenImageIO reads them.
    let info = oiiotool_info(&wide);
    let (dw, dh) = (W + 2 * OVERSCAN, H + 2 * OVERSCAN);
    // `oiiotool` pads the sizes to four places: "  52 x   42".
    assert!(info.contains(&format!("{dw:4} x {dh:4},")), "{info}");
    assert!(
        info.contains(&format!("pixel data origin: x=-{OVERSCAN}, y=-{OVERSCAN}")),
        "{info}"
    );
    assert!(
        info.contains(&format!("full/display size: {W} x {H}")),
        "{info}"
    );
    assert!(info.contains("full/display origin: 0, 0"), "{info}");
    assert!(info.contains(&format!("overscan={OVERSCAN}")), "{info}");

    // Every channel's display-window pixels are the frame without overscan, bit for bit.
    let (pw, ph, pc) = read_exr(&plain);
    let (ww, wh, wc) = read_exr(&wide);
    assert_eq!((pw, ph), (W, H));
    assert_eq!((ww, wh), (dw, dh));
    assert_eq!(
        pc.iter().map(|c| &c.0).collect::<Vec<_>>(),
        wc.iter().map(|c| &c.0).collect::<Vec<_>>()
    );
    for (name, p) in &pc {
        let w = channel(&wc, name);
        for y in 0..H {
            for x in 0..W {
                let (a, b) = (p[y * W + x], w[(y + OVERSCAN) * dw + x + OVERSCAN]);
                assert!(
                    a.to_bits() == b.to_bits(),
                    "{name} at ({x}, {y}): {a} without overscan, {b} with"
                );
            }
        }
    }

    // The red square beyond the left edge is in the border, at its place on the image
    // plane (columns −5..−1), and nowhere in the image.
    let (r, g) = (channel(&wc, "R"), channel(&wc, "G"));
    let row = OVERSCAN + H / 2;
    for col in [-4i32, -2] {
        let i = row * dw + (col + OVERSCAN as i32) as usize;
        assert!(
            r[i] > 0.05 && r[i] > 4.0 * g[i],
            "column {col}: R {} G {}",
            r[i],
            g[i]
        );
        // The square at z = 0, not the backdrop at z = −2 (7 or more away).
        let z = channel(&wc, "Z")[i];
        assert!(
            z > CAMERA_Z && z < CAMERA_Z + 1.5,
            "column {col}: depth {z}"
        );
    }
    let (pr, pg) = (channel(&pc, "R"), channel(&pc, "G"));
    assert!(
        (0..W * H).all(|i| pr[i] <= 2.0 * pg[i]),
        "red inside the image"
    );
    // The border's Cryptomatte names the square (its id is the one of "outside").
    let id = f32::from_bits(subfield::render::crypto_hash("outside"));
    let crypto = channel(&wc, "CryptoObject00.R");
    assert_eq!(crypto[row * dw + OVERSCAN - 3].to_bits(), id.to_bits());

    // The preview is the display window: the image as rendered without overscan.
    let png = image::open(&preview).unwrap().to_rgb8();
    assert_eq!(png.dimensions(), (W as u32, H as u32));
    let plain_preview = dir.join("plain.png");
    render(
        &scene,
        &dir.join("again.exr"),
        &[
            "--aov",
            "depth",
            "--spp",
            "2",
            "--diffuse-bounces",
            "1",
            "--background",
            "0.2,0.25,0.3",
            "--preview",
            plain_preview.to_str().unwrap(),
        ],
    );
    assert!(
        png == image::open(&plain_preview).unwrap().to_rgb8(),
        "the preview shows more than the image"
    );
}

/// The header's compression and every channel's values, read by OpenEXR's bindings.
const READER: &str = r#"
import sys, json, OpenEXR, numpy as np
f = OpenEXR.File(sys.argv[1], separate_channels=True)
h = f.header()
out = {n: [float(x) for x in c.pixels.astype(np.float64).ravel()] for n, c in f.channels().items()}
print(json.dumps({"compression": str(h["compression"]), "channels": out}))
"#;

fn openexr(path: &Path) -> serde_json::Value {
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
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn every_compression_reads_back_with_the_same_pixels() {
    let dir = temp_dir("exr-compression");
    let scene = write_scene(&dir);
    let aovs = ["--aov", "depth,cryptomatte,diffuse", "--overscan", "2"];
    let mut first: Option<serde_json::Value> = None;
    for (codec, python, oiio) in [
        ("zip", "ZIP_COMPRESSION", "zip"),
        ("piz", "PIZ_COMPRESSION", "piz"),
        ("none", "NO_COMPRESSION", "none"),
    ] {
        let out = dir.join(format!("{codec}.exr"));
        let mut args = aovs.to_vec();
        args.extend(["--compression", codec]);
        render(&scene, &out, &args);
        let info = oiiotool_info(&out);
        assert!(
            info.contains(&format!("compression: \"{oiio}\"")),
            "{codec}: {info}"
        );
        let v = openexr(&out);
        assert!(
            v["compression"].as_str().unwrap().ends_with(python),
            "{codec}: {}",
            v["compression"]
        );
        match &first {
            None => first = Some(v["channels"].clone()),
            Some(f) => assert!(f == &v["channels"], "{codec}: other pixels than zip"),
        }
    }
    // Lossless codecs are not in the options string: a resumed run keeps a frame made
    // with another one (its pixels are the same).
    let zip = dir.join("zip.exr");
    let before = std::fs::read(&zip).unwrap();
    let mut args = aovs.to_vec();
    args.extend(["--compression", "piz", "--resume"]);
    render(&scene, &zip, &args);
    assert!(
        std::fs::read(&zip).unwrap() == before,
        "the frame was re-rendered"
    );
}

#[test]
fn dwaa_is_refused_in_one_line() {
    let dir = temp_dir("exr-dwaa");
    let o = subfield(&[
        "render",
        "scene.glb",
        "-o",
        dir.join("f.exr").to_str().unwrap(),
        "--compression",
        "dwaa",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("dwaa") && err.contains("cannot write"),
        "{err}"
    );
    assert!(!dir.join("f.exr").exists());
}
