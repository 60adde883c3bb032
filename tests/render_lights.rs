//! Lights a user can trust (issue 24): a point light without falloff (AFF/NFF, BART)
//! is as bright far away as near, an inverse-square one is not, and the falloff survives
//! the glTF round trip. Each case is a scene built in code (or a small AFF text), rendered
//! through the library to a float EXR and read back.

mod common;

use std::path::{Path, PathBuf};

use common::build::{placed, SceneBuilder};
use common::exr_read::read_exr;
use common::render_scene::{quad, temp_dir};
use glam::{Quat, Vec3, Vec4};
use subfield::import;
use subfield::render::{self, FrameRange, LookAt, PixelType, RenderOptions};
use subfield::scene::{Falloff, LightDef, LightKind, Material, Mesh, Node, Scene};

/// Linear RGB of the middle 4×4 pixels of frame 0 of `scene`, seen from `look` at
/// 32×32, one sample a pixel, with the ambient term `ambient` (the options' one where
/// the scene has none).
fn centre(scene: &Scene, dir: &Path, name: &str, look: Option<LookAt>, ambient: Vec3) -> Vec3 {
    let (rgb, _) = render_rgb(scene, dir, name, look, ambient);
    let mut sum = Vec3::ZERO;
    for y in 14..18 {
        for x in 14..18 {
            sum += rgb[y * 32 + x];
        }
    }
    sum / 16.0
}

fn render_rgb(
    scene: &Scene,
    dir: &Path,
    name: &str,
    look: Option<LookAt>,
    ambient: Vec3,
) -> (Vec<Vec3>, PathBuf) {
    let out = dir.join(format!("{name}.exr"));
    let mut opts = RenderOptions {
        output: out.clone(),
        frames: Some(FrameRange { start: 0, end: 1 }.into()),
        width: 32,
        height: 32,
        look_at: look,
        pixel_type: PixelType::Float,
        ..Default::default()
    };
    opts.shading.ambient = ambient;
    render::render_sequence(scene, &opts, &mut |_| {}).unwrap();
    let (w, h, chans) = read_exr(&out);
    assert_eq!((w, h), (32, 32));
    let ch = |n: &str| &chans.iter().find(|(c, _)| c == n).unwrap().1;
    let (r, g, b) = (ch("R"), ch("G"), ch("B"));
    let rgb = (0..r.len()).map(|i| Vec3::new(r[i], g[i], b[i])).collect();
    (rgb, out)
}

/// Looking straight down at the floor's centre from height 5.
fn from_above() -> LookAt {
    LookAt {
        from: Vec3::new(0.0, 5.0, 0.0),
        at: Vec3::ZERO,
        up: Vec3::Z,
        yfov_deg: 20.0,
    }
}

/// A grey diffuse floor (the plane y = 0, facing up) and a white point light of
/// `intensity` straight above its centre at `height`, with `falloff`; written as GLB
/// and imported back, as a user's file would be.
fn lit_floor(dir: &Path, height: f32, intensity: f32, falloff: Falloff) -> Scene {
    lit_floor_with(dir, height, intensity, falloff, None)
}

/// [`lit_floor`] with the scene's ambient light `ambient`.
fn lit_floor_with(
    dir: &Path,
    height: f32,
    intensity: f32,
    falloff: Falloff,
    ambient: Option<Vec3>,
) -> Scene {
    let mut b = SceneBuilder::new();
    let grey = b.add_material(Material {
        base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
        metallic: 0.0,
        roughness: 1.0,
        ..Material::default()
    });
    let mesh = b.add_mesh(Mesh {
        // Z × X = +Y: the floor faces up.
        primitives: vec![quad(Vec3::ZERO, Vec3::Z * 10.0, Vec3::X * 10.0, grey)],
        ..Default::default()
    });
    let n = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    b.add_root(n);
    let light = b.add_light(LightDef {
        name: Some("lamp".into()),
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity,
        range: None,
        falloff,
    });
    let n = b.add_node(Node {
        light: Some(light),
        transform: placed(Vec3::new(0.0, height, 0.0), Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(n);
    let path = dir.join(format!("floor-{height}-{falloff:?}-{ambient:?}.glb"));
    let mut scene = b.finish();
    scene.ambient = ambient;
    import::write_gltf(&scene, &path).unwrap();
    import::load(&path).unwrap()
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs())
}

#[test]
fn a_light_without_falloff_lights_a_far_floor_as_much_as_a_near_one() {
    let dir = temp_dir("lights-falloff");
    let pi = std::f32::consts::PI;
    let none = |h: f32| {
        let s = lit_floor(&dir, h, pi, Falloff::None);
        assert_eq!(
            s.lights[0].falloff,
            Falloff::None,
            "the glb lost the falloff"
        );
        centre(
            &s,
            &dir,
            &format!("none-{h}"),
            Some(from_above()),
            Vec3::ZERO,
        )
    };
    let (near, far) = (none(2.0), none(500.0));
    // kd/π · E · cos with E = π and cos ≈ 1: the albedo, at any height.
    assert!(close(near.x, 0.8, 0.05), "near: {near}");
    assert!(close(far.x, near.x, 0.01), "near {near}, far {far}");

    let inverse = |h: f32| {
        let s = lit_floor(&dir, h, pi, Falloff::InverseSquare);
        assert_eq!(s.lights[0].falloff, Falloff::InverseSquare);
        centre(
            &s,
            &dir,
            &format!("inv-{h}"),
            Some(from_above()),
            Vec3::ZERO,
        )
    };
    let (near, far) = (inverse(2.0), inverse(20.0));
    assert!(close(near.x, 0.8 / 4.0, 0.05), "near: {near}");
    // Ten times as far: a hundredth of the light.
    assert!(close(far.x * 100.0, near.x, 0.05), "near {near}, far {far}");
}

#[test]
fn the_gltf_round_trip_keeps_the_falloff_and_other_readers_see_inverse_square() {
    let dir = temp_dir("lights-gltf");
    let scene = lit_floor(&dir, 3.0, 1.0, Falloff::None);
    let path = dir.join("floor.gltf");
    import::write_gltf(&scene, &path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let light = &json["extensions"]["KHR_lights_punctual"]["lights"][0];
    assert_eq!(light["type"], "point", "{light}");
    assert_eq!(light["extras"]["falloff"], "none", "{light}");
    let back = import::load(&path).unwrap();
    assert_eq!(back.lights, scene.lights);
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);

    // An inverse-square light writes no extras (files as before).
    let plain = lit_floor(&dir, 3.0, 1.0, Falloff::InverseSquare);
    let p2 = dir.join("plain.gltf");
    import::write_gltf(&plain, &p2).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&p2).unwrap()).unwrap();
    let light = &json["extensions"]["KHR_lights_punctual"]["lights"][0];
    assert!(light.get("extras").is_none(), "{light}");

    // A falloff this reader does not know: inverse square, with a warning naming it.
    let odd = dir.join("odd.gltf");
    std::fs::write(
        &odd,
        text.replace("\"falloff\":\"none\"", "\"falloff\":\"linear\""),
    )
    .unwrap();
    let s = import::load(&odd).unwrap();
    assert_eq!(s.lights[0].falloff, Falloff::InverseSquare);
    let w: Vec<String> = s.warnings.iter().map(|w| w.to_string()).collect();
    assert!(
        w.iter()
            .any(|w| w.contains("lights[0]") && w.contains("\"linear\"")),
        "{w:?}"
    );
}

/// An AFF floor lit by a light 1000 above it (BART robots' light is 500 up): an NFF
/// light does not fall off, so the floor shows its diffuse colour.
const AFF_FLOOR: &str = "\
v
from 0 5 0
at 0 0 0
up 0 0 1
angle 20
hither 0.1
resolution 32 32
%AM%
l 0 1000 0 1 1 1
f 1 1 1 0.8 0 0 0 0
p 4
-10 0 -10
-10 0 10
10 0 10
10 0 -10
";

#[test]
fn an_aff_light_far_away_lights_the_floor() {
    let dir = temp_dir("lights-aff");
    let path = dir.join("floor.aff");
    std::fs::write(&path, AFF_FLOOR.replace("%AM%", "am 0 0 0")).unwrap();
    let scene = import::load(&path).unwrap();
    assert_eq!(scene.lights.len(), 1);
    assert_eq!(scene.lights[0].falloff, Falloff::None);
    let c = centre(&scene, &dir, "aff", None, Vec3::ZERO);
    assert!(close(c.x, 0.8, 0.05), "{c}");
    // Converted to glTF and back, the same picture.
    let glb = dir.join("floor.glb");
    import::write_gltf(&scene, &glb).unwrap();
    let back = import::load(&glb).unwrap();
    assert_eq!(back.lights, scene.lights);
    let (a, _) = render_rgb(&scene, &dir, "aff-full", None, Vec3::ZERO);
    let (b, _) = render_rgb(&back, &dir, "glb-full", None, Vec3::ZERO);
    assert_eq!(a, b);
}

/// AFF `am` is the scene's ambient light: `kd · am` added to the direct light, in place
/// of the options' ambient term; without `am`, the format's default 1 1 1.
#[test]
fn aff_ambient_lights_the_floor_and_survives_the_conversion() {
    let dir = temp_dir("lights-aff-ambient");
    let path = dir.join("floor.aff");
    std::fs::write(&path, AFF_FLOOR.replace("%AM%", "am 0.5 0.25 0")).unwrap();
    let scene = import::load(&path).unwrap();
    assert_eq!(scene.ambient, Some(Vec3::new(0.5, 0.25, 0.0)));
    // The options' ambient (here 0.3) gives way to the scene's.
    let c = centre(&scene, &dir, "am", None, Vec3::splat(0.3));
    let want = Vec3::splat(0.8) + 0.8 * Vec3::new(0.5, 0.25, 0.0);
    for i in 0..3 {
        assert!(close(c[i], want[i], 0.05), "{c} against {want}");
    }
    let glb = dir.join("floor.glb");
    import::write_gltf(&scene, &glb).unwrap();
    let back = import::load(&glb).unwrap();
    assert_eq!(back.ambient, scene.ambient);
    let (a, out) = render_rgb(&scene, &dir, "am-aff", None, Vec3::splat(0.3));
    let (b, _) = render_rgb(&back, &dir, "am-glb", None, Vec3::splat(0.3));
    assert_eq!(a, b);
    // The frame's options string records the ambient light used, the scene's.
    let header = std::fs::read(&out).unwrap();
    let has = |s: &str| header.windows(s.len()).any(|w| w == s.as_bytes());
    assert!(
        has("ambient=scene:0.5,0.25,0 "),
        "the header records the scene's ambient"
    );
    assert!(
        !has("ambient=0.3,"),
        "the header records the options' ambient"
    );

    std::fs::write(&path, AFF_FLOOR.replace("%AM%", "")).unwrap();
    let scene = import::load(&path).unwrap();
    assert_eq!(scene.ambient, Some(Vec3::ONE));
    let c = centre(&scene, &dir, "am-default", None, Vec3::ZERO);
    assert!(close(c.x, 1.6, 0.05), "{c}");

    // `fm`: the ambient light is reflected with the material's ambient colour (0.2,
    // 0.1, 0.05 here), not its diffuse one (0.8), as NFF and BART do.
    let fm = AFF_FLOOR.replace("%AM%", "am 1 1 1").replace(
        "f 1 1 1 0.8 0 0 0 0",
        "fm 0.2 0.1 0.05  0.8 0.8 0.8  0 0 0  1 0 0",
    );
    std::fs::write(&path, fm).unwrap();
    let scene = import::load(&path).unwrap();
    let floor = scene
        .materials
        .iter()
        .find(|m| m.ambient.is_some())
        .unwrap();
    assert_eq!(floor.ambient, Some(Vec3::new(0.2, 0.1, 0.05)));
    let c = centre(&scene, &dir, "fm", None, Vec3::ZERO);
    let want = Vec3::splat(0.8) + Vec3::new(0.2, 0.1, 0.05);
    for i in 0..3 {
        assert!(close(c[i], want[i], 0.05), "{c} against {want}");
    }
    import::write_gltf(&scene, &glb).unwrap();
    let back = import::load(&glb).unwrap();
    assert_eq!(back.materials, scene.materials);
    let (a, _) = render_rgb(&scene, &dir, "fm-aff", None, Vec3::ZERO);
    let (b, _) = render_rgb(&back, &dir, "fm-glb", None, Vec3::ZERO);
    assert_eq!(a, b);
    // A malformed material ambient: ignored (the diffuse colour), with a warning.
    let text_path = dir.join("fm.gltf");
    import::write_gltf(&scene, &text_path).unwrap();
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&text_path).unwrap()).unwrap();
    let a = &mut json["materials"][0]["extras"]["ambient"];
    assert_eq!(a.as_array().map(Vec::len), Some(3), "{a}");
    *a = serde_json::json!("grey");
    let odd = dir.join("fm-odd.gltf");
    std::fs::write(&odd, json.to_string()).unwrap();
    let s = import::load(&odd).unwrap();
    assert!(s.materials.iter().all(|m| m.ambient.is_none()));
    let w: Vec<String> = s.warnings.iter().map(|w| w.to_string()).collect();
    assert!(
        w.iter()
            .any(|w| w.contains("materials[") && w.contains("extras.ambient")),
        "{w:?}"
    );
}

/// A glTF scene's `extras.ambient` (as subfield writes it) replaces the options'
/// ambient term; a scene without one keeps the options' term; a malformed one is
/// ignored with a warning.
#[test]
fn a_gltf_scene_ambient_replaces_the_options_term() {
    let dir = temp_dir("lights-gltf-ambient");
    let pi = std::f32::consts::PI;
    let lit = lit_floor_with(&dir, 3.0, pi, Falloff::None, Some(Vec3::splat(0.5)));
    assert_eq!(lit.ambient, Some(Vec3::splat(0.5)));
    let c = centre(
        &lit,
        &dir,
        "scene-ambient",
        Some(from_above()),
        Vec3::splat(0.1),
    );
    assert!(close(c.x, 0.8 + 0.8 * 0.5, 0.05), "{c}");
    let plain = lit_floor(&dir, 3.0, pi, Falloff::None);
    assert_eq!(plain.ambient, None);
    let c = centre(
        &plain,
        &dir,
        "options-ambient",
        Some(from_above()),
        Vec3::splat(0.1),
    );
    assert!(close(c.x, 0.8 + 0.8 * 0.1, 0.05), "{c}");

    let path = dir.join("ambient.gltf");
    import::write_gltf(&lit, &path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(
        json["scenes"][0]["extras"]["ambient"],
        serde_json::json!([0.5, 0.5, 0.5])
    );
    let odd = dir.join("odd.gltf");
    std::fs::write(
        &odd,
        text.replace("\"ambient\":[0.5,0.5,0.5]", "\"ambient\":[0.5,-1,0.5]"),
    )
    .unwrap();
    let s = import::load(&odd).unwrap();
    assert_eq!(s.ambient, None);
    let w: Vec<String> = s.warnings.iter().map(|w| w.to_string()).collect();
    assert!(w.iter().any(|w| w.contains("extras.ambient")), "{w:?}");
}
