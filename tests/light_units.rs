//! Light units as the glTF specification states them (issue 35): `KHR_lights_punctual`
//! point and spot intensities are candela, directional ones lux, converted to our
//! radiometric unit at 683 lm/W as Blender's glTF importer does; emissive strength is a
//! unitless multiplier of `emissiveFactor`. Each case is a glTF file whose lights and
//! materials are written here by hand (the geometry comes from the scene builder), read,
//! rendered to a float EXR and compared, pixel by pixel, with the closed form:
//!
//! * point: `L = ρ/π · (I/683) · cosθ / d²`, at every floor pixel (its hit point from the
//!   position AOV, so the expected value needs no camera model);
//! * spot: the same times the spec's cone falloff
//!   `clamp((cos α − cos outer)/(cos inner − cos outer), 0, 1)²`;
//! * sun: `L = ρ/π · (lux/683) · cosθ`;
//! * emission: `emissiveFactor · emissiveTexture · emissiveStrength`.
//!
//! Tolerance: 1e-3 relative (plus 1e-7 absolute) of the formula evaluated at the hit
//! point or at the shadow ray's origin, which starts up to 1e-4 × the coordinates' size
//! off the surface (that offset matters only at the spot's outer edge, where the falloff
//! is steep). The renderer's arithmetic is f32; a wrong unit is off by 683×, a missing
//! `cosθ` or falloff by tens of percent over these floors.

mod common;

use std::path::Path;

use common::build::SceneBuilder;
use common::exr_read::read_exr;
use common::render_scene::{quad, temp_dir};
use glam::{Vec3, Vec4};
use serde_json::{json, Value};
use subfield::import;
use subfield::render::{self, Aovs, FrameRange, LookAt, PixelType, RenderOptions};
use subfield::scene::{Image, Material, Mesh, Node, Scene, Texture, TextureRef, Wrap};

const ALBEDO: f32 = 0.5;
const PI: f32 = std::f32::consts::PI;
const SIZE: u32 = 48;

/// A floor of half size 4 in the plane y = 0, facing up: grey Lambertian (albedo
/// [`ALBEDO`], metallic 0, roughness 1: no highlight, no reflection ray).
fn floor_json() -> Value {
    let mut b = SceneBuilder::new();
    let grey = b.add_material(Material {
        base_color: Vec4::new(ALBEDO, ALBEDO, ALBEDO, 1.0),
        metallic: 0.0,
        roughness: 1.0,
        ..Material::default()
    });
    let mesh = b.add_mesh(Mesh {
        // Z × X = +Y: the floor faces up.
        primitives: vec![quad(Vec3::ZERO, Vec3::Z * 4.0, Vec3::X * 4.0, grey)],
        ..Default::default()
    });
    let n = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    b.add_root(n);
    to_json(&b.finish())
}

fn to_json(scene: &Scene) -> Value {
    serde_json::from_str(&import::to_gltf_json(scene).unwrap()).unwrap()
}

/// `doc` with `light` (a `KHR_lights_punctual` light object, as a file states it) on a
/// new root node placed by `node` (translation, rotation), imported from its bytes.
fn with_light(mut doc: Value, light: Value, node: Value, dir: &Path) -> Scene {
    doc["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    doc["extensions"] = json!({ "KHR_lights_punctual": { "lights": [light] } });
    let mut node = node;
    node["extensions"] = json!({ "KHR_lights_punctual": { "light": 0 } });
    let nodes = doc["nodes"].as_array_mut().unwrap();
    nodes.push(node);
    let index = nodes.len() - 1;
    doc["scenes"][0]["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!(index));
    import(&doc, dir)
}

fn import(doc: &Value, dir: &Path) -> Scene {
    let path = dir.join("scene.gltf");
    let bytes = serde_json::to_vec(doc).unwrap();
    std::fs::write(&path, &bytes).unwrap();
    import::load(&path).unwrap()
}

/// One rendered frame: RGB and the centre ray's hit point per pixel (rows top down).
struct Frame {
    rgb: Vec<Vec3>,
    p: Vec<Vec3>,
}

/// Frame 0 of `scene` looking down at the floor from `height` above the origin, float
/// pixels, no ambient term, no default light.
fn render_down(scene: &Scene, dir: &Path, height: f32) -> Frame {
    let out = dir.join("frame.exr");
    let mut opts = RenderOptions {
        output: out.clone(),
        frames: Some(FrameRange { start: 0, end: 1 }.into()),
        width: SIZE,
        height: SIZE,
        look_at: Some(LookAt {
            from: Vec3::new(0.0, height, 0.0),
            at: Vec3::ZERO,
            up: Vec3::Z,
            yfov_deg: 60.0,
        }),
        pixel_type: PixelType::Float,
        aovs: Aovs {
            position: true,
            ..Aovs::default()
        },
        ..Default::default()
    };
    opts.shading.ambient = Vec3::ZERO;
    opts.shading.default_light = false;
    render::render_sequence(scene, &opts, &mut |_| {}).unwrap();
    let (w, h, chans) = read_exr(&out);
    assert_eq!((w, h), (SIZE as usize, SIZE as usize));
    let ch = |n: &str| &chans.iter().find(|(c, _)| c == n).unwrap().1;
    let v3 = |a: &str, b: &str, c: &str| {
        let (a, b, c) = (ch(a), ch(b), ch(c));
        (0..a.len())
            .map(|i| Vec3::new(a[i], b[i], c[i]))
            .collect::<Vec<_>>()
    };
    Frame {
        rgb: v3("R", "G", "B"),
        p: v3("P.X", "P.Y", "P.Z"),
    }
}

fn close(got: f32, want: f32) -> bool {
    (got - want).abs() <= 1e-3 * want.abs() + 1e-7
}

/// Compares every floor pixel of `f` (grey: R = G = B) with `want(hit point)`; returns
/// how many floor pixels were compared and the largest expected value.
fn check_floor(f: &Frame, what: &str, mut want: impl FnMut(Vec3) -> f32) -> (usize, f32) {
    let (mut n, mut peak) = (0, 0.0f32);
    for (i, (&c, &p)) in f.rgb.iter().zip(&f.p).enumerate() {
        if p.y.abs() > 1e-4 || p.x.abs() > 3.9 || p.z.abs() > 3.9 {
            continue; // not the floor, or at its rim
        }
        let w = want(p);
        // The shadow ray's origin: off the floor by at most 1e-4 × |p| (plus a margin).
        let lifted = want(p + Vec3::Y * 2e-4 * p.abs().max_element().max(1.0));
        let (lo, hi) = (w.min(lifted), w.max(lifted));
        for (k, got) in c.to_array().into_iter().enumerate() {
            assert!(
                close(got, got.clamp(lo, hi)),
                "{what}: pixel {i} at {p}: channel {k} is {got}, the formula gives {w} ({lifted} just above)"
            );
        }
        n += 1;
        peak = peak.max(w);
    }
    (n, peak)
}

#[test]
fn a_point_light_in_candela_lights_a_floor_as_the_inverse_square_law_says() {
    let dir = temp_dir("units-point");
    let (cd, at) = (3000.0f32, Vec3::new(1.5, 2.0, -0.5));
    let scene = with_light(
        floor_json(),
        json!({ "type": "point", "intensity": cd }),
        json!({ "translation": at.to_array() }),
        &dir,
    );
    let f = render_down(&scene, &dir, 6.0);
    let (n, peak) = check_floor(&f, "point", |p| {
        let to = at - p;
        let d2 = to.length_squared();
        let cos = to.y / d2.sqrt();
        ALBEDO / PI * (cd / 683.0) * cos / d2
    });
    assert!(n > 1000, "the floor fills most of the frame: {n} pixels");
    // Straight under the light: 0.5/π · 3000/683 / 4 = 0.1748, a sensible radiance.
    assert!((0.15..0.2).contains(&peak), "{peak}");
}

#[test]
fn a_spot_light_in_candela_with_the_specs_cone_falloff() {
    let dir = temp_dir("units-spot");
    let (cd, h) = (5000.0f32, 3.0f32);
    let (inner, outer) = (0.3f32, 0.6f32);
    // The node's -Z turned to -Y: the spot points straight down.
    let rot = glam::Quat::from_rotation_arc(Vec3::NEG_Z, Vec3::NEG_Y);
    let scene = with_light(
        floor_json(),
        json!({
            "type": "spot",
            "intensity": cd,
            "spot": { "innerConeAngle": inner, "outerConeAngle": outer },
        }),
        json!({ "translation": [0.0, h, 0.0], "rotation": rot.to_array() }),
        &dir,
    );
    let f = render_down(&scene, &dir, 6.0);
    let at = Vec3::new(0.0, h, 0.0);
    // The spec's falloff at `p`; cos α is also cos θ: the spot points straight down.
    let cone = |p: Vec3| {
        let to = at - p;
        let cos = to.y / to.length();
        let t = ((cos - outer.cos()) / (inner.cos() - outer.cos())).clamp(0.0, 1.0);
        (t, cos, to.length_squared())
    };
    let (n, _) = check_floor(&f, "spot", |p| {
        let (t, cos, d2) = cone(p);
        ALBEDO / PI * (cd / 683.0) * t * t * cos / d2
    });
    assert!(n > 1000, "{n}");
    let ts: Vec<f32> = f.p.iter().map(|&p| cone(p).0).collect();
    let inside = ts.iter().filter(|&&t| t >= 1.0).count();
    let dark = ts.iter().filter(|&&t| t <= 0.0).count();
    let edge = ts.len() - inside - dark;
    assert!(
        inside > 50 && edge > 50 && dark > 50,
        "the frame holds the cone, its soft edge and the dark outside: {inside} {edge} {dark}"
    );
}

#[test]
fn a_directional_light_in_lux() {
    let dir = temp_dir("units-sun");
    let lux = 1366.0f32;
    let theta = 0.5f32;
    // Shining down, tilted by θ from the vertical.
    let along = Vec3::new(theta.sin(), -theta.cos(), 0.0);
    let rot = glam::Quat::from_rotation_arc(Vec3::NEG_Z, along);
    let scene = with_light(
        floor_json(),
        json!({ "type": "directional", "intensity": lux, "color": [1.0, 1.0, 1.0] }),
        json!({ "rotation": rot.to_array() }),
        &dir,
    );
    let f = render_down(&scene, &dir, 6.0);
    let want = ALBEDO / PI * (lux / 683.0) * theta.cos();
    let (n, _) = check_floor(&f, "sun", |_| want);
    assert!(n > 1000, "{n}");
    // 2 W/m² at 0.5 rad: 0.5/π · 2 · 0.8776 = 0.2793.
    assert!((want - 0.2793).abs() < 1e-3, "{want}");
}

#[test]
fn emissive_strength_multiplies_factor_and_texture() {
    let dir = temp_dir("units-emissive");
    let mut b = SceneBuilder::new();
    // One texel, sRGB (255, 128, 64): linear (1, 0.2158605, 0.0512695).
    let image = b.add_image(Image {
        name: None,
        width: 1,
        height: 1,
        rgba8: vec![255, 128, 64, 255],
    });
    let texture = b.add_texture(Texture {
        image,
        wrap_s: Wrap::Repeat,
        wrap_t: Wrap::Repeat,
        nearest: true,
    });
    let glow = b.add_material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        metallic: 0.0,
        emissive: Vec3::ONE,
        emissive_texture: Some(TextureRef {
            texture,
            tex_coord: 0,
            transform: None,
        }),
        ..Material::default()
    });
    let mesh = b.add_mesh(Mesh {
        primitives: vec![quad(Vec3::ZERO, Vec3::Z * 4.0, Vec3::X * 4.0, glow)],
        ..Default::default()
    });
    let n = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    b.add_root(n);
    let mut doc = to_json(&b.finish());
    // What the file says, by hand: factor (0.5, 0.25, 1), strength 4.
    doc["materials"][0]["emissiveFactor"] = json!([0.5, 0.25, 1.0]);
    doc["materials"][0]["extensions"] =
        json!({ "KHR_materials_emissive_strength": { "emissiveStrength": 4.0 } });
    doc["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]);
    let scene = import(&doc, &dir);
    let f = render_down(&scene, &dir, 6.0);
    let texel = Vec3::new(1.0, srgb_to_linear(128), srgb_to_linear(64));
    let want = Vec3::new(0.5, 0.25, 1.0) * texel * 4.0;
    let mut n = 0;
    for (&c, &p) in f.rgb.iter().zip(&f.p) {
        if p.y.abs() > 1e-4 || p.x.abs() > 3.9 || p.z.abs() > 3.9 {
            continue;
        }
        for k in 0..3 {
            assert!(close(c[k], want[k]), "at {p}: {c} against {want}");
        }
        n += 1;
    }
    assert!(n > 1000, "{n}");
}

fn srgb_to_linear(v: u8) -> f32 {
    let c = f32::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The writer states the model's W/sr in candela (× 683), exactly enough that the
/// reader gives back the same f32; a file from another exporter means the same.
#[test]
fn the_writer_writes_candela_and_lux_that_read_back_exactly() {
    use subfield::scene::{Falloff, LightDef, LightKind};
    let dir = temp_dir("units-writer");
    for (i, w) in [0.1f32, std::f32::consts::PI, 200.0, 1.0e-3, 123.456_79]
        .into_iter()
        .enumerate()
    {
        let mut b = SceneBuilder::new();
        let light = b.add_light(LightDef {
            name: None,
            kind: if i % 2 == 0 {
                LightKind::Point
            } else {
                LightKind::Directional
            },
            color: Vec3::ONE,
            intensity: w,
            range: None,
            falloff: Falloff::InverseSquare,
        });
        let n = b.add_node(Node {
            light: Some(light),
            ..Default::default()
        });
        b.add_root(n);
        let scene = b.finish();
        let doc = to_json(&scene);
        let written = doc["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"]
            .as_f64()
            .unwrap();
        assert_eq!(written, f64::from(w) * 683.0, "candela or lux in the file");
        let path = dir.join(format!("w{i}.glb"));
        import::write_gltf(&scene, &path).unwrap();
        assert_eq!(import::load(&path).unwrap().lights[0].intensity, w);
    }
}
