//! What rays see when they leave the scene (issue 35): `--background` and
//! `--environment`. A map of coloured blocks is written as a real `.hdr` file; a mirror
//! sphere is rendered with the position and normal AOVs, and every pixel whose reflected
//! direction lands well inside one block must show that block's colour. Camera rays that
//! miss show the map at their own direction, and `--environment-rotation` turns it.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::build::{mesh, mesh_node, placed, soup_prim, SceneBuilder};
use common::exr_read::{channel, read_exr};
use common::render_scene::temp_dir;
use glam::{Quat, Vec3, Vec4};
use subfield::gen::synth::sphere;
use subfield::import;
use subfield::scene::{Falloff, LightDef, LightKind, Material, Node};

const MAP_W: usize = 64;
const MAP_H: usize = 32;
const BLOCK: usize = 8;

/// The colour of block (bx, by) of the test map: every block its own.
fn block_colour(bx: usize, by: usize) -> Vec3 {
    Vec3::new(
        0.1 + bx as f32 * 0.1,
        0.2 + by as f32 * 0.2,
        1.0 + ((bx + by) % 3) as f32,
    )
}

/// Writes the 64x32 block map as a Radiance `.hdr` (RGBE keeps these values exactly:
/// each has a short mantissa).
fn write_map(path: &Path) {
    let px: Vec<image::Rgb<f32>> = (0..MAP_W * MAP_H)
        .map(|i| {
            let c = block_colour((i % MAP_W) / BLOCK, (i / MAP_W) / BLOCK);
            image::Rgb([c.x, c.y, c.z])
        })
        .collect();
    let file = std::fs::File::create(path).unwrap();
    image::codecs::hdr::HdrEncoder::new(file)
        .encode(&px, MAP_W, MAP_H)
        .unwrap();
}

/// The block a world direction looks at, by the convention of docs/IMAGES.md (centre
/// column along +X, u = 0.5 + atan2(z, x)/2π, v from the bottom = 0.5 + elevation/π),
/// turned by `rotation_deg` about +Y; `None` when the direction lies within 1.5 texels
/// of a block's edge (where the bilinear lookup blends two blocks).
fn expected(dir: Vec3, rotation_deg: f32) -> Option<Vec3> {
    let (s, c) = (-rotation_deg.to_radians()).sin_cos();
    let d = Vec3::new(c * dir.x + s * dir.z, dir.y, -s * dir.x + c * dir.z);
    let u = 0.5 + (d.z as f64).atan2(d.x as f64) / std::f64::consts::TAU;
    let v = 0.5 + (d.y as f64).atan2((d.x as f64).hypot(d.z as f64)) / std::f64::consts::PI;
    let x = u * MAP_W as f64;
    let y = (1.0 - v) * MAP_H as f64;
    // Block edges, the wrap seam at u = 0 included (rows clamp, so the top and bottom
    // rows blend with nothing).
    let near_edge = |t: f64| {
        let f = t.rem_euclid(BLOCK as f64);
        !(1.5..=BLOCK as f64 - 1.5).contains(&f)
    };
    if near_edge(x) || (near_edge(y) && y > 1.5 && y < MAP_H as f64 - 1.5) {
        return None;
    }
    let bx = (x.rem_euclid(MAP_W as f64) as usize / BLOCK).min(MAP_W / BLOCK - 1);
    let by = (y as usize / BLOCK).min(MAP_H / BLOCK - 1);
    Some(block_colour(bx, by))
}

/// A mirror sphere of radius 1 at the origin (flat triangles), written as GLB. Its one
/// light is switched off (intensity 0), so no default light puts a highlight on the
/// mirror: what it shows is the environment alone.
fn mirror_sphere_scene(dir: &Path) -> PathBuf {
    let mut b = SceneBuilder::new();
    let off = b.add_light(LightDef {
        name: Some("off".into()),
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity: 0.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let lamp = b.add_node(Node {
        light: Some(off),
        transform: placed(Vec3::new(0.0, 5.0, 0.0), Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(lamp);
    let mirror = b.add_material(Material {
        name: Some("mirror".into()),
        base_color: Vec4::ONE,
        metallic: 1.0,
        roughness: 0.0,
        ..Material::default()
    });
    let tris = sphere(Vec3::ZERO, 1.0, 48, 96);
    let positions: Vec<Vec3> = tris.iter().flatten().copied().collect();
    let m = b.add_mesh(mesh("ball", vec![soup_prim(positions, mirror)]));
    let n = b.add_node(mesh_node("ball", m, Vec3::ZERO));
    b.add_root(n);
    let scene = b.finish();
    let path = dir.join("ball.glb");
    import::write_gltf(&scene, &path).unwrap();
    path
}

fn render(scene: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_subfield"))
        .arg("render")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .args(["--size", "96x96", "--float", "--quiet", "--frames", "0"])
        .args(extra)
        .output()
        .unwrap()
}

struct Frame {
    rgb: Vec<Vec3>,
    p: Vec<Vec3>,
    n: Vec<Vec3>,
    z: Vec<f32>,
}

fn read(path: &Path) -> Frame {
    let (w, h, chans) = read_exr(path);
    assert_eq!((w, h), (96, 96));
    let v3 = |a: &str, b: &str, c: &str| {
        let (x, y, z) = (channel(&chans, a), channel(&chans, b), channel(&chans, c));
        (0..w * h).map(|i| Vec3::new(x[i], y[i], z[i])).collect()
    };
    Frame {
        rgb: v3("R", "G", "B"),
        p: v3("P.X", "P.Y", "P.Z"),
        n: v3("N.X", "N.Y", "N.Z"),
        z: channel(&chans, "Z").to_vec(),
    }
}

const FROM: Vec3 = Vec3::new(0.0, 0.0, 4.0);

/// Checks every pixel of a frame seen from `FROM` looking at the origin with yfov 40°:
/// a mirror hit shows the map along the reflected direction, a miss the map along the
/// camera ray. Returns (mirror pixels checked, miss pixels checked).
fn check(frame: &Frame, rotation: f32) -> (usize, usize) {
    let t = (20.0f32).to_radians().tan();
    let (mut mirrored, mut missed) = (0, 0);
    for y in 0..96 {
        for x in 0..96 {
            let i = y * 96 + x;
            let (dir, what) = if frame.z[i].is_finite() {
                let d = (frame.p[i] - FROM).normalize();
                let n = frame.n[i].normalize();
                (d - 2.0 * d.dot(n) * n, "mirror")
            } else {
                // The camera looks down −Z with +Y up (DESIGN.md §4's pixel mapping).
                let px = (2.0 * (x as f32 + 0.5) / 96.0 - 1.0) * t;
                let py = (1.0 - 2.0 * (y as f32 + 0.5) / 96.0) * t;
                (Vec3::new(px, py, -1.0).normalize(), "miss")
            };
            let Some(want) = expected(dir, rotation) else {
                continue;
            };
            let got = frame.rgb[i];
            assert!(
                (got - want).abs().max_element() <= 0.02 * want.max_element(),
                "pixel ({x}, {y}), a {what} ray along {dir}, rotation {rotation}: got {got}, the map there is {want}"
            );
            if what == "mirror" {
                mirrored += 1;
            } else {
                missed += 1;
            }
        }
    }
    (mirrored, missed)
}

#[test]
fn a_mirror_sphere_shows_the_environment_map_the_right_way_round() {
    let dir = temp_dir("environment-mirror");
    let scene = mirror_sphere_scene(&dir);
    let map = dir.join("blocks.hdr");
    write_map(&map);
    let look = [
        "--look-from",
        "0,0,4",
        "--look-at",
        "0,0,0",
        "--yfov",
        "40",
        "--aov",
        "depth,normal,position",
    ];
    for rotation in [0.0f32, 90.0, -37.5] {
        let out = dir.join(format!("rot{rotation}.exr"));
        let rot = rotation.to_string();
        let mut args = look.to_vec();
        args.extend(["--environment", map.to_str().unwrap()]);
        args.extend(["--environment-rotation", &rot]);
        let o = render(&scene, &out, &args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let (mirrored, missed) = check(&read(&out), rotation);
        // The sphere covers about a fifth of the frame; most of its pixels and of the
        // misses lie inside blocks.
        assert!(
            mirrored > 600 && missed > 2000,
            "checked {mirrored} mirror and {missed} miss pixels"
        );
    }
    // Intensity scales it all.
    let out = dir.join("bright.exr");
    let mut args = look.to_vec();
    args.extend([
        "--environment",
        map.to_str().unwrap(),
        "--environment-intensity",
        "2",
    ]);
    let o = render(&scene, &out, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (once, twice) = (read(&dir.join("rot0.exr")), read(&out));
    for (a, b) in once.rgb.iter().zip(&twice.rgb) {
        assert!((*a * 2.0 - *b).abs().max_element() <= 1e-5 * b.max_element().max(1.0));
    }
}

#[test]
fn a_background_colour_is_what_misses_and_reflections_see() {
    let dir = temp_dir("environment-background");
    let scene = mirror_sphere_scene(&dir);
    let out = dir.join("bg.exr");
    let o = render(
        &scene,
        &out,
        &[
            "--look-from",
            "0,0,4",
            "--look-at",
            "0,0,0",
            "--background",
            "0.25,0.5,1",
            "--aov",
            "depth",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f = {
        let (_, _, chans) = read_exr(&out);
        let (r, g, b, z) = (
            channel(&chans, "R").to_vec(),
            channel(&chans, "G").to_vec(),
            channel(&chans, "B").to_vec(),
            channel(&chans, "Z").to_vec(),
        );
        (r, g, b, z)
    };
    let (mut hits, mut misses) = (0, 0);
    for i in 0..96 * 96 {
        let got = Vec3::new(f.0[i], f.1[i], f.2[i]);
        // Misses see the colour; the mirror reflects it (ambient adds nothing to a
        // metal), except where a reflected ray meets the sphere again (none from outside
        // a convex ball).
        assert!(
            (got - Vec3::new(0.25, 0.5, 1.0)).abs().max_element() < 0.02,
            "pixel {i}: {got}"
        );
        if f.3[i].is_finite() {
            hits += 1;
        } else {
            misses += 1;
        }
    }
    assert!(hits > 600 && misses > 3000);
}

#[test]
fn bad_environment_options_are_one_line_errors() {
    let dir = temp_dir("environment-errors");
    let scene = mirror_sphere_scene(&dir);
    let map = dir.join("blocks.hdr");
    write_map(&map);
    let out = dir.join("x.exr");
    let png = dir.join("sky.png");
    std::fs::write(&png, b"not an image").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--environment", png.to_str().unwrap()], "sky.png"),
        (vec!["--environment", "/nonexistent/sky.hdr"], "sky.hdr"),
        (
            vec![
                "--environment",
                map.to_str().unwrap(),
                "--background",
                "1,1,1",
            ],
            "give one",
        ),
        (vec!["--background", "1,-1,1"], "negative"),
        (vec!["--environment-rotation", "10"], "--environment"),
        (
            vec![
                "--environment",
                map.to_str().unwrap(),
                "--environment-intensity",
                "-1",
            ],
            "--environment-intensity",
        ),
    ];
    for (args, needle) in cases {
        let o = render(&scene, &out, &args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote a frame");
    }
}
