//! Bounce light (`--diffuse-bounces`, issue 35) against references computed apart from
//! the renderer: a white furnace (a diffuse floor under a uniform background reflects
//! albedo × background, whatever the sample) and a floor lit by a point light both
//! directly and by way of a diffuse ceiling, whose one-bounce irradiance the test
//! integrates by quadrature. Scenes are built in code and rendered through the library
//! to float EXRs.

mod common;

use std::path::Path;

use common::build::{placed, SceneBuilder};
use common::exr_read::read_exr;
use common::render_scene::{quad, temp_dir};
use glam::{Quat, Vec3, Vec4};
use subfield::render::{self, FrameRange, LookAt, PixelType, RenderOptions};
use subfield::scene::{Falloff, LightDef, LightKind, Material, Mesh, Node, Scene};

const SIDE: u32 = 8;

fn lambert(b: &mut SceneBuilder, albedo: f32) -> u32 {
    b.add_material(Material {
        base_color: Vec4::new(albedo, albedo, albedo, 1.0),
        metallic: 0.0,
        // Roughness 1: Lambert alone (no glint, no reflection ray; docs/IMAGES.md).
        roughness: 1.0,
        ..Material::default()
    })
}

fn point_light(b: &mut SceneBuilder, at: Vec3, intensity: f32) {
    let l = b.add_light(LightDef {
        name: Some("lamp".into()),
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let n = b.add_node(Node {
        light: Some(l),
        transform: placed(at, Quat::IDENTITY),
        ..Default::default()
    });
    b.add_root(n);
}

fn add_quad(b: &mut SceneBuilder, centre: Vec3, a: Vec3, c: Vec3, material: u32) {
    let m = b.add_mesh(Mesh {
        primitives: vec![quad(centre, a, c, material)],
        ..Default::default()
    });
    let n = b.add_node(Node {
        mesh: Some(m),
        ..Default::default()
    });
    b.add_root(n);
}

/// Looking straight down at the floor's centre from `height`, a narrow view.
fn down_from(height: f32) -> LookAt {
    LookAt {
        from: Vec3::new(0.0, height, 0.0),
        at: Vec3::ZERO,
        up: Vec3::Z,
        yfov_deg: 2.0,
    }
}

/// The mean linear RGB of frame 0 (SIDE × SIDE pixels), and the file's bytes.
fn render_mean(
    scene: &Scene,
    dir: &Path,
    name: &str,
    look: LookAt,
    set: impl Fn(&mut RenderOptions),
) -> (Vec3, Vec<u8>) {
    let out = dir.join(format!("{name}.exr"));
    let mut opts = RenderOptions {
        output: out.clone(),
        frames: Some(FrameRange { start: 0, end: 1 }.into()),
        width: SIDE,
        height: SIDE,
        look_at: Some(look),
        pixel_type: PixelType::Float,
        ..Default::default()
    };
    set(&mut opts);
    render::render_sequence(scene, &opts, &mut |_| {}).unwrap();
    let (_, _, chans) = read_exr(&out);
    let ch = |n: &str| &chans.iter().find(|(c, _)| c == n).unwrap().1;
    let (r, g, b) = (ch("R"), ch("G"), ch("B"));
    let n = r.len() as f32;
    let mean = Vec3::new(
        r.iter().sum::<f32>() / n,
        g.iter().sum::<f32>() / n,
        b.iter().sum::<f32>() / n,
    );
    (mean, std::fs::read(&out).unwrap())
}

#[test]
fn a_white_furnace_reflects_albedo_times_the_background() {
    let dir = temp_dir("bounces-furnace");
    let mut b = SceneBuilder::new();
    let grey = lambert(&mut b, 0.5);
    // Z × X = +Y: the floor faces up. A light switched off keeps the default light away.
    add_quad(&mut b, Vec3::ZERO, Vec3::Z * 50.0, Vec3::X * 50.0, grey);
    point_light(&mut b, Vec3::new(0.0, 3.0, 0.0), 0.0);
    let scene = b.finish();
    let sky = Vec3::new(1.0, 0.5, 0.25);
    let (bounced, _) = render_mean(&scene, &dir, "one", down_from(2.0), |o| {
        o.shading.background = sky;
        o.shading.diffuse_bounces = 1;
    });
    // Every cosine-weighted bounce leaves the open floor and sees the background: the
    // estimate is exact sample by sample.
    let want = sky * 0.5;
    assert!(
        (bounced - want).abs().max_element() < 1e-4,
        "one bounce: {bounced}, albedo × background = {want}"
    );
    // Whitted's model: the ambient term (0.05 × albedo) stands in, the sky lights nothing.
    let (whitted, _) = render_mean(&scene, &dir, "zero", down_from(2.0), |o| {
        o.shading.background = sky;
    });
    assert!(
        (whitted - Vec3::splat(0.025)).abs().max_element() < 1e-4,
        "no bounce: {whitted}"
    );
}

/// The floor's irradiance at the origin from the ceiling (the plane y = `h`, a square
/// of half side `half`, albedo `rho_c`) lit by a point light of `intensity` W/sr at
/// (0, `a`, 0): the ceiling's radiance L(y) = rho_c/π · I · cos_c / r_c², integrated
/// with cos_floor · cos_ceiling / d² over a midpoint grid.
fn ceiling_irradiance(h: f64, a: f64, half: f64, rho_c: f64, intensity: f64) -> f64 {
    let n = 800;
    let step = 2.0 * half / n as f64;
    let mut e = 0.0;
    for i in 0..n {
        for j in 0..n {
            let (x, z) = (
                -half + (i as f64 + 0.5) * step,
                -half + (j as f64 + 0.5) * step,
            );
            let rc2 = x * x + z * z + (h - a) * (h - a);
            let cos_c_light = (h - a) / rc2.sqrt();
            let radiance = rho_c / std::f64::consts::PI * intensity * cos_c_light / rc2;
            let d2 = x * x + z * z + h * h;
            let cos = h / d2.sqrt(); // the same at both ends for parallel planes
            e += radiance * cos * cos / d2 * step * step;
        }
    }
    e
}

#[test]
fn one_bounce_off_a_ceiling_matches_the_integrated_irradiance() {
    let dir = temp_dir("bounces-ceiling");
    let (h, a, half, rho_f, rho_c, intensity) = (2.0f32, 1.0f32, 6.0f32, 0.5f32, 0.8f32, 10.0f32);
    let mut b = SceneBuilder::new();
    let floor = lambert(&mut b, rho_f);
    let ceiling = lambert(&mut b, rho_c);
    add_quad(&mut b, Vec3::ZERO, Vec3::Z * half, Vec3::X * half, floor);
    // X × Z = −Y: the ceiling faces down.
    add_quad(
        &mut b,
        Vec3::new(0.0, h, 0.0),
        Vec3::X * half,
        Vec3::Z * half,
        ceiling,
    );
    point_light(&mut b, Vec3::new(0.0, a, 0.0), intensity);
    let scene = b.finish();

    let pi = std::f64::consts::PI;
    let direct = intensity as f64 / (a as f64 * a as f64);
    let indirect = ceiling_irradiance(
        h as f64,
        a as f64,
        half as f64,
        rho_c as f64,
        intensity as f64,
    );
    let want = rho_f as f64 / pi * (direct + indirect);
    let (got, bytes) = render_mean(&scene, &dir, "one", down_from(0.5), |o| {
        o.spp = 1024;
        o.shading.diffuse_bounces = 1;
    });
    // 64 pixels × 1,024 samples: the Monte Carlo error of the bounce is under 1 % of
    // it; the footprint (±0.009 around the origin) moves the direct part by under
    // 0.01 %. The bounce alone is the difference from the same frame without it (and
    // without the ambient stand-in), whose direct light is the same, ray for ray.
    let (direct_only, _) = render_mean(&scene, &dir, "zero", down_from(0.5), |o| {
        o.spp = 1024;
        o.shading.ambient = Vec3::ZERO;
    });
    let want_direct = rho_f as f64 / pi * direct;
    let want_bounce = rho_f as f64 / pi * indirect;
    let got_bounce = (got.x - direct_only.x) as f64;
    assert!(
        (direct_only.x as f64 - want_direct).abs() < 1e-4 * want_direct,
        "direct light {direct_only} against {want_direct:.5}"
    );
    assert!(
        (got_bounce - want_bounce).abs() < 0.03 * want_bounce,
        "the bounce adds {got_bounce:.5}, the quadrature {want_bounce:.5} (whole: {got} against {want:.5})"
    );
    assert!((got.x as f64 - want).abs() < 0.01 * want);
    // The bounce is a real share of the whole (so a test of the whole would see it too).
    assert!(indirect > 0.1 * direct, "{indirect} against {direct}");
    // Deterministic: the same bytes again.
    let (_, again) = render_mean(&scene, &dir, "again", down_from(0.5), |o| {
        o.spp = 1024;
        o.shading.diffuse_bounces = 1;
    });
    assert!(bytes == again, "two renders of the same options differ");
    // Two bounces add light (floor → ceiling → floor → ceiling's light): more than one.
    let (two, _) = render_mean(&scene, &dir, "two", down_from(0.5), |o| {
        o.spp = 1024;
        o.shading.diffuse_bounces = 2;
    });
    assert!(two.x > got.x * 1.01, "two bounces {two} against one {got}");
}

#[test]
fn too_many_bounces_is_an_option_error() {
    let dir = temp_dir("bounces-option");
    let mut b = SceneBuilder::new();
    let grey = lambert(&mut b, 0.5);
    add_quad(&mut b, Vec3::ZERO, Vec3::Z, Vec3::X, grey);
    let scene = b.finish();
    let opts = RenderOptions {
        output: dir.join("x.exr"),
        frames: Some(FrameRange { start: 0, end: 1 }.into()),
        shading: render::ShadingOptions {
            diffuse_bounces: 65,
            ..Default::default()
        },
        ..Default::default()
    };
    let e = render::render_sequence(&scene, &opts, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("--diffuse-bounces 65"), "{e}");
}
