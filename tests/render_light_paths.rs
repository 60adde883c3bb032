//! The light-path AOVs (`--aov diffuse,specular,transmission,emission`): on scenes built
//! in code, the four passes add up to `R G B` in every pixel (to half-float rounding for
//! a half beauty, to float addition order for `--float`), each pass is where its light
//! is and nothing is where there is none. Read back by OpenEXR's own Python bindings
//! (and the `exr` crate for the byte-level checks).

mod common;

use std::collections::HashMap;
use std::f32::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;

use common::build::{diffuse, mesh, perspective, placed, SceneBuilder};
use common::render_scene::{cube, quad, temp_dir};
use glam::{Quat, Vec3, Vec4};
use subfield::import;
use subfield::render::{
    self, Aovs, EnvironmentMap, FrameRange, MotionBlur, PixelType, RenderOptions, ShadingOptions,
};
use subfield::scene::{Falloff, LightDef, LightKind, Material, Node, Scene};

const W: usize = 48;
const H: usize = 36;
const YFOV: f32 = 0.9;
const CAMERA_AT: Vec3 = Vec3::new(0.0, 1.0, 6.0);
const PASSES: [&str; 4] = ["diffuse", "specular", "transmission", "emission"];

/// Where a world point is seen: the pixel (column, row) of the camera at `CAMERA_AT`
/// looking down −Z (square pixels, `YFOV` vertical).
fn pixel_of(p: Vec3) -> (usize, usize) {
    let c = p - CAMERA_AT;
    let t = (YFOV * 0.5).tan();
    let sx = c.x / -c.z / (t * W as f32 / H as f32);
    let sy = c.y / -c.z / t;
    (
        ((sx + 1.0) * 0.5 * W as f32) as usize,
        ((1.0 - sy) * 0.5 * H as f32) as usize,
    )
}

/// A floor, and on it from left to right: a mirror, a polished (GGX) metal panel, a
/// glass block and a diffuse block, an emissive panel above; a point, a spot and a
/// directional light. With `only_diffuse`, every surface is a rough dielectric
/// (roughness 1: no glint, no reflection ray), nothing emits, and the one light is a
/// point light.
fn write_scene(dir: &Path, only_diffuse: bool) -> PathBuf {
    let mut b = SceneBuilder::new();
    let grey = diffuse("grey", Vec4::new(0.6, 0.6, 0.6, 1.0), 1.0);
    let pick = |m: Material| if only_diffuse { grey.clone() } else { m };
    let floor = b.add_material(grey.clone());
    let mirror = b.add_material(pick(Material {
        name: Some("mirror".into()),
        base_color: Vec4::new(0.9, 0.9, 0.9, 1.0),
        metallic: 1.0,
        roughness: 0.0,
        ..Material::default()
    }));
    let glossy = b.add_material(pick(Material {
        name: Some("glossy".into()),
        base_color: Vec4::new(0.9, 0.7, 0.4, 1.0),
        metallic: 1.0,
        roughness: 0.25,
        ..Material::default()
    }));
    let glass = b.add_material(pick(Material {
        name: Some("glass".into()),
        base_color: Vec4::ONE,
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        ior: 1.5,
        ..Material::default()
    }));
    let paint = b.add_material(diffuse("paint", Vec4::new(0.2, 0.5, 0.8, 1.0), 1.0));
    let lamp = b.add_material(pick(Material {
        name: Some("lamp".into()),
        base_color: Vec4::new(0.1, 0.1, 0.1, 1.0),
        metallic: 0.0,
        roughness: 1.0,
        emissive: Vec3::new(1.0, 0.8, 0.6),
        emissive_strength: 2.0,
        ..Material::default()
    }));
    let meshes = [
        (
            "floor",
            quad(Vec3::ZERO, Vec3::X * 6.0, Vec3::NEG_Z * 6.0, floor),
        ),
        (
            "mirror",
            quad(
                Vec3::new(-1.8, 0.7, 0.0),
                Vec3::X * 0.5,
                Vec3::Y * 0.7,
                mirror,
            ),
        ),
        (
            "glossy",
            quad(
                Vec3::new(-0.6, 0.7, 0.0),
                Vec3::X * 0.5,
                Vec3::Y * 0.7,
                glossy,
            ),
        ),
        ("glass", {
            let mut c = cube(Vec3::new(0.5, 0.6, 0.3), glass);
            c.positions
                .iter_mut()
                .for_each(|p| *p += Vec3::new(0.6, 0.6, 0.5));
            c
        }),
        ("paint", {
            let mut c = cube(Vec3::splat(0.4), paint);
            c.positions
                .iter_mut()
                .for_each(|p| *p += Vec3::new(1.8, 0.4, 0.0));
            c
        }),
        (
            "lamp",
            quad(
                Vec3::new(0.0, 2.2, -0.5),
                Vec3::X * 0.6,
                Vec3::Y * 0.25,
                lamp,
            ),
        ),
    ];
    for (name, prim) in meshes {
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
        name: Some("camera".into()),
        camera: Some(cam),
        transform: placed(CAMERA_AT, Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(n);
    let mut lights = vec![(
        LightKind::Point,
        Vec3::new(1.0, 3.0, 3.0),
        Quat::IDENTITY,
        2.0,
    )];
    if !only_diffuse {
        lights.push((
            LightKind::Spot {
                inner_cone_angle: 0.3,
                outer_cone_angle: 0.6,
            },
            Vec3::new(-1.0, 3.0, 1.5),
            Quat::from_rotation_x(-FRAC_PI_2),
            3.0,
        ));
        lights.push((
            LightKind::Directional,
            Vec3::ZERO,
            Quat::from_rotation_x(-0.7),
            0.8,
        ));
    }
    for (i, (kind, at, turn, intensity)) in lights.into_iter().enumerate() {
        let l = b.add_light(LightDef {
            name: Some(format!("light{i}")),
            kind,
            color: Vec3::ONE,
            intensity,
            range: None,
            falloff: Falloff::InverseSquare,
        });
        let n = b.add_node(Node {
            light: Some(l),
            transform: placed(at, turn),
            ..Default::default()
        });
        b.add_root(n);
    }
    let p = dir.join("scene.glb");
    import::write_gltf(&b.finish(), &p).unwrap();
    p
}

/// A 4x2 sky: blue above, warm at the horizon, every texel its own.
fn sky() -> Arc<EnvironmentMap> {
    let texels = vec![
        Vec3::new(0.3, 0.5, 0.9),
        Vec3::new(0.35, 0.55, 0.95),
        Vec3::new(0.25, 0.45, 0.85),
        Vec3::new(0.3, 0.5, 1.0),
        Vec3::new(0.9, 0.7, 0.5),
        Vec3::new(0.8, 0.7, 0.6),
        Vec3::new(0.85, 0.65, 0.5),
        Vec3::new(0.9, 0.75, 0.55),
    ];
    Arc::new(EnvironmentMap::from_texels(4, 2, texels, 30.0, 1.0, 0x5c1))
}

fn light_paths() -> Aovs {
    Aovs {
        diffuse: true,
        specular: true,
        transmission: true,
        emission: true,
        ..Default::default()
    }
}

/// Renders frame 0 of `scene` to `dir/NAME.exr` and returns the path.
fn render(dir: &Path, name: &str, scene: &Scene, opts: RenderOptions) -> PathBuf {
    let opts = RenderOptions {
        output: dir.join(format!("{name}.exr")),
        frames: Some(FrameRange { start: 0, end: 1 }.into()),
        width: W as u32,
        height: H as u32,
        ..opts
    };
    render::render_sequence(scene, &opts, &mut |_| {}).unwrap();
    opts.output
}

/// Every channel (rows top to bottom) of an EXR, read by OpenEXR's Python bindings.
const READER: &str = r#"
import sys, json, OpenEXR, numpy as np
f = OpenEXR.File(sys.argv[1], separate_channels=True)
out = {n: [float(x) for x in c.pixels.astype(np.float64).ravel()] for n, c in f.channels().items()}
print(json.dumps(out))
"#;

fn openexr_channels(path: &Path) -> HashMap<String, Vec<f32>> {
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
    let v: HashMap<String, Vec<f64>> = serde_json::from_slice(&o.stdout).unwrap();
    v.into_iter()
        .map(|(k, xs)| (k, xs.into_iter().map(|x| x as f32).collect()))
        .collect()
}

/// The largest miss, over every pixel and colour channel, of `R G B` by the sum of the
/// passes, in units of the tolerance `rel·|R| + abs` (≤ 1 passes).
fn worst_sum_error(ch: &HashMap<String, Vec<f32>>, rel: f32, abs: f32) -> (f32, String) {
    let mut worst = (0.0f32, String::new());
    for c in ["R", "G", "B"] {
        let beauty = &ch[c];
        for (i, &r) in beauty.iter().enumerate() {
            let sum: f32 = PASSES.iter().map(|p| ch[&format!("{p}.{c}")][i]).sum();
            let e = (sum - r).abs() / (rel * r.abs() + abs);
            if e > worst.0 {
                worst = (
                    e,
                    format!("{c} at pixel {i}: beauty {r}, passes add up to {sum}"),
                );
            }
        }
    }
    worst
}

fn every_kind_options() -> RenderOptions {
    RenderOptions {
        spp: 4,
        aovs: light_paths(),
        shading: ShadingOptions {
            environment: Some(sky()),
            diffuse_bounces: 1,
            ..Default::default()
        },
        ..Default::default()
    }
}

#[test]
fn passes_add_up_to_the_beauty_with_every_material_and_light() {
    let dir = temp_dir("light-paths-sum");
    let scene = import::load(&write_scene(&dir, false)).unwrap();
    // Half beauty (the default): the passes are float, so they add up to the beauty
    // before it was rounded to half, i.e. to half rounding (2^-11 relative).
    let half = openexr_channels(&render(&dir, "half", &scene, every_kind_options()));
    let (e, at) = worst_sum_error(&half, 1.0 / 2048.0 + 1e-5, 1e-6);
    assert!(e <= 1.0, "half: {at} ({e} tolerances)");
    // Float beauty, with an exposure: to the order of the float additions.
    let float = openexr_channels(&render(
        &dir,
        "float",
        &scene,
        RenderOptions {
            pixel_type: PixelType::Float,
            exposure: 1.5,
            ..every_kind_options()
        },
    ));
    let (e, at) = worst_sum_error(&float, 2e-6, 1e-7);
    assert!(e <= 1.0, "float: {at} ({e} tolerances)");
    // The exposure scales the passes as it scales the beauty.
    let k = 1.5f32.exp2();
    for c in ["diffuse.G", "specular.R", "transmission.B", "emission.R"] {
        for (a, b) in half[c].iter().zip(&float[c]) {
            assert!(
                (a * k - b).abs() <= 1e-5 * b.abs() + 1e-7,
                "{c}: {a} × {k} ≠ {b}"
            );
        }
    }

    // Each pass where its light is.
    let at = |p: Vec3| {
        let (x, y) = pixel_of(p);
        y * W + x
    };
    let share = |pass: &str, i: usize| {
        let sum = |p: &str| -> f32 {
            ["R", "G", "B"]
                .iter()
                .map(|c| half[&format!("{p}.{c}")][i])
                .sum()
        };
        sum(pass) / ["R", "G", "B"].iter().map(|c| half[*c][i]).sum::<f32>()
    };
    let mirror = at(Vec3::new(-1.8, 0.9, 0.0));
    assert!(share("specular", mirror) > 0.9, "the mirror is specular");
    let glossy = at(Vec3::new(-0.6, 0.9, 0.0));
    assert!(share("specular", glossy) > 0.6, "the GGX metal is specular");
    let glass = at(Vec3::new(0.6, 0.7, 0.8));
    assert!(
        share("transmission", glass) > 0.5,
        "the glass block transmits"
    );
    let paint = at(Vec3::new(1.8, 0.4, 0.4));
    assert!(
        share("diffuse", paint) > 0.9,
        "the painted block is diffuse"
    );
    let lamp = at(Vec3::new(0.0, 2.2, -0.5));
    assert!(share("emission", lamp) > 0.5, "the lamp emits");
    // The sky straight ahead, above everything: a camera ray that leaves the scene.
    let sky = at(Vec3::new(0.0, 3.3, -3.0));
    assert_eq!(half["A"][sky], 0.0, "the sky pixel hits nothing");
    assert!(
        share("emission", sky) > 0.999,
        "the sky seen directly is emission"
    );
    for p in ["diffuse", "specular", "transmission"] {
        assert_eq!(share(p, sky), 0.0, "{p} in the sky");
    }
    // The environment lights the floor through the diffuse bounce: diffuse, not emission.
    let floor = at(Vec3::new(0.0, 0.0, 3.0));
    assert!(share("diffuse", floor) > 0.9, "the floor is diffuse");
    assert_eq!(share("emission", floor), 0.0, "the floor emits nothing");
}

/// Motion blur and overscan together: a blurred frame's time steps each sum the passes
/// as they sum the beauty, so the passes still add up, in the border too; and the scene
/// being still, the blurred frame is the unblurred one (each sample traced once, at its
/// step, with the same seeds) to the order of the float additions, passes included.
#[test]
fn passes_add_up_with_motion_blur_and_overscan() {
    let dir = temp_dir("light-paths-blur");
    let scene = import::load(&write_scene(&dir, false)).unwrap();
    let o = 3;
    let base = RenderOptions {
        pixel_type: PixelType::Float,
        overscan: o,
        ..every_kind_options()
    };
    let sharp = openexr_channels(&render(&dir, "sharp", &scene, base.clone()));
    // An odd step count (the middle step traces the frame's own time) and an even one.
    for steps in [3, 4] {
        let blurred = openexr_channels(&render(
            &dir,
            &format!("blur{steps}"),
            &scene,
            RenderOptions {
                motion_blur: Some(MotionBlur {
                    shutter: 1.0,
                    steps,
                }),
                ..base.clone()
            },
        ));
        let n = (W + 2 * o as usize) * (H + 2 * o as usize);
        assert_eq!(blurred["R"].len(), n, "the data window with its border");
        let (e, at) = worst_sum_error(&blurred, 2e-6, 1e-7);
        assert!(e <= 1.0, "{steps} steps: {at} ({e} tolerances)");
        for c in [
            "R",
            "G",
            "B",
            "A",
            "diffuse.G",
            "specular.R",
            "transmission.B",
            "emission.R",
        ] {
            for (i, (a, b)) in sharp[c].iter().zip(&blurred[c]).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-5 * a.abs() + 1e-6,
                    "{steps} steps, {c} at pixel {i}: {a} sharp, {b} blurred"
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_diffuse_scene_has_only_diffuse_light_and_the_beauty_is_unchanged() {
    let dir = temp_dir("light-paths-diffuse");
    let scene = import::load(&write_scene(&dir, true)).unwrap();
    let opts = RenderOptions {
        spp: 2,
        shading: ShadingOptions {
            diffuse_bounces: 1,
            ..Default::default()
        },
        ..Default::default()
    };
    let with = render(
        &dir,
        "with",
        &scene,
        RenderOptions {
            aovs: light_paths(),
            ..opts.clone()
        },
    );
    let ch = openexr_channels(&with);
    for p in ["specular", "transmission", "emission"] {
        for c in ["R", "G", "B"] {
            let v = &ch[&format!("{p}.{c}")];
            assert!(v.iter().all(|&x| x == 0.0), "{p}.{c} is not zero");
        }
    }
    let (e, at) = worst_sum_error(&ch, 1.0 / 2048.0 + 1e-5, 1e-6);
    assert!(e <= 1.0, "{at} ({e} tolerances)");
    assert!(
        ch["diffuse.G"].iter().any(|&x| x > 0.05),
        "diffuse light is there"
    );
    // The beauty does not change when the passes are asked for: the same half floats.
    let without = render(&dir, "without", &scene, opts);
    let (_, _, a) = common::exr_read::read_exr(&with);
    let (_, _, b) = common::exr_read::read_exr(&without);
    for c in ["R", "G", "B", "A"] {
        let (x, y) = (
            common::exr_read::channel(&a, c),
            common::exr_read::channel(&b, c),
        );
        assert!(x == y, "{c} differs with the passes");
    }
}

#[test]
fn only_the_passes_asked_for_are_written() {
    let names = render::channel_names(Aovs {
        specular: true,
        emission: true,
        ..Default::default()
    });
    assert_eq!(
        names,
        [
            "A",
            "B",
            "G",
            "R",
            "emission.B",
            "emission.G",
            "emission.R",
            "specular.B",
            "specular.G",
            "specular.R"
        ]
    );
}
