//! Images a user can trust (issue 24): rough reflection is rough, emissive surfaces
//! light the scene with soft shadows, normal maps bend the shading, textures are
//! filtered by the ray's footprint. Each case is a scene built in code, rendered through
//! the library to a float EXR and read back.

mod common;

use std::path::{Path, PathBuf};

use common::build::{placed, SceneBuilder};
use common::exr_read::read_exr;
use common::render_scene::{quad, temp_dir};
use glam::{Quat, Vec3, Vec4};
use subfield::import;
use subfield::render::{self, FrameRange, LookAt, PixelType, RenderOptions};
use subfield::scene::{
    Falloff, Image, LightDef, LightKind, Material, Mesh, Node, Primitive, Scene, Texture,
    TextureRef, Wrap,
};

/// Luminance-free view of a render: one RGB triple per pixel, rows top to bottom.
struct Frame {
    width: usize,
    rgb: Vec<Vec3>,
}

impl Frame {
    fn at(&self, x: usize, y: usize) -> Vec3 {
        self.rgb[y * self.width + x]
    }
}

/// Renders frame 0 of `scene` through `look` at `size`, float pixels.
fn render(
    scene: &Scene,
    dir: &Path,
    name: &str,
    look: LookAt,
    size: (u32, u32),
    tweak: impl Fn(&mut RenderOptions),
) -> (Frame, PathBuf) {
    let out = dir.join(format!("{name}.exr"));
    let mut opts = RenderOptions {
        output: out.clone(),
        frames: Some(FrameRange { start: 0, end: 1 }.into()),
        width: size.0,
        height: size.1,
        look_at: Some(look),
        pixel_type: PixelType::Float,
        ..Default::default()
    };
    tweak(&mut opts);
    render::render_sequence(scene, &opts, &mut |_| {}).unwrap();
    let (w, _, chans) = read_exr(&out);
    let ch = |n: &str| &chans.iter().find(|(c, _)| c == n).unwrap().1;
    let (r, g, b) = (ch("R"), ch("G"), ch("B"));
    let rgb = (0..r.len()).map(|i| Vec3::new(r[i], g[i], b[i])).collect();
    (Frame { width: w, rgb }, out)
}

/// A dielectric with the spec's other defaults (what the scenes here start from).
fn dielectric() -> Material {
    Material {
        metallic: 0.0,
        ..Material::default()
    }
}

/// The scene written as GLB and imported back, as a user's file would be.
fn load(b: SceneBuilder, dir: &Path) -> Scene {
    let path = dir.join("scene.glb");
    import::write_gltf(&b.finish(), &path).unwrap();
    import::load(&path).unwrap()
}

fn add_mesh(b: &mut SceneBuilder, primitives: Vec<Primitive>) {
    let mesh = b.add_mesh(Mesh {
        primitives,
        ..Default::default()
    });
    let n = b.add_node(Node {
        mesh: Some(mesh),
        ..Default::default()
    });
    b.add_root(n);
}

/// A directional light of `lux` shining along `dir`.
fn add_sun(b: &mut SceneBuilder, dir: Vec3, lux: f32) {
    let sun = b.add_light(LightDef {
        name: None,
        kind: LightKind::Directional,
        color: Vec3::ONE,
        intensity: lux,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let n = b.add_node(Node {
        light: Some(sun),
        transform: placed(
            Vec3::ZERO,
            Quat::from_rotation_arc(-Vec3::Z, dir.normalize()),
        ),
        ..Default::default()
    });
    b.add_root(n);
}

fn down_at(x: f32, y: f32, z: f32, yfov_deg: f32) -> LookAt {
    LookAt {
        from: Vec3::new(x, y, z),
        at: Vec3::new(x, 0.0, z),
        up: Vec3::Z,
        yfov_deg,
    }
}

/// A metal wall in the plane z = 0 facing the camera, and behind the camera a bright
/// vertical bar facing the wall: the wall shows the bar's reflection in the middle of
/// the image. Returns the centre row's red channel.
fn reflected_bar(dir: &Path, roughness: f32, spp: u32) -> Vec<f32> {
    let mut b = SceneBuilder::new();
    let wall = b.add_material(Material {
        base_color: Vec4::ONE,
        metallic: 1.0,
        roughness,
        ..dielectric()
    });
    let bar = b.add_material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        emissive: Vec3::ONE,
        ..dielectric()
    });
    add_mesh(
        &mut b,
        vec![
            quad(Vec3::ZERO, Vec3::X * 20.0, Vec3::Y * 20.0, wall),
            // Faces -Z (towards the wall): X × ... = -Z needs a = Y, b = X.
            quad(Vec3::new(0.0, 0.0, 6.0), Vec3::Y * 4.0, Vec3::X * 0.5, bar),
        ],
    );
    let scene = load(b, dir);
    let look = LookAt {
        from: Vec3::new(0.0, 0.0, 4.0),
        at: Vec3::ZERO,
        up: Vec3::Y,
        yfov_deg: 20.0,
    };
    // 64 pixels span ±35°; the bar's image is ±2.9° wide, about 5 pixels.
    let (w, h) = (64, 16);
    let (f, _) = render(
        &scene,
        dir,
        &format!("bar-{roughness}"),
        look,
        (w, h),
        |o| {
            o.spp = spp;
            o.shading.ambient = Vec3::ZERO;
        },
    );
    (0..w as usize).map(|x| f.at(x, h as usize / 2).x).collect()
}

/// The largest step between neighbouring pixels relative to the row's peak.
fn sharpness(row: &[f32]) -> f32 {
    let peak = row.iter().cloned().fold(0.0, f32::max);
    let step = row
        .windows(2)
        .map(|p| (p[1] - p[0]).abs())
        .fold(0.0, f32::max);
    step / peak.max(1e-6)
}

#[test]
fn a_rough_wall_shows_no_sharp_reflection_and_a_smooth_one_mirrors() {
    let dir = temp_dir("shading-rough");
    let smooth = reflected_bar(&dir, 0.0, 16);
    let rough = reflected_bar(&dir, 0.3, 256);
    // The polished metal mirrors the bar (radiance 1 × F = 1) with a hard edge.
    let peak = smooth.iter().cloned().fold(0.0, f32::max);
    assert!((peak - 1.0).abs() < 1e-3, "mirror peak {peak}: {smooth:?}");
    assert!(sharpness(&smooth) > 0.7, "mirror edge {smooth:?}");
    // The rough one spreads the same light over many pixels: a soft bump, no edge,
    // most of the energy kept (GGX loses some at the shadowing term).
    let s = sharpness(&rough);
    assert!(
        s < 0.35,
        "rough wall has a sharp reflection (step/peak {s}): {rough:?}"
    );
    let (es, er): (f32, f32) = (smooth.iter().sum(), rough.iter().sum());
    assert!(er > 0.4 * es && er < 1.2 * es, "energy {er} vs mirror {es}");
    let wide = rough.iter().filter(|&&v| v > 0.05 * peak).count();
    let narrow = smooth.iter().filter(|&&v| v > 0.05 * peak).count();
    assert!(wide > 2 * narrow, "blur {wide} px vs mirror {narrow} px");
}

/// A white floor, an emissive square 2 above it facing down, and (optionally) an
/// opaque square halfway between; no other light, no ambient.
fn lamp_scene(dir: &Path, occluder: bool) -> Scene {
    let mut b = SceneBuilder::new();
    let white = b.add_material(Material {
        base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
        roughness: 1.0,
        ..dielectric()
    });
    let lamp = b.add_material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        emissive: Vec3::ONE,
        ..dielectric()
    });
    let mut prims = vec![
        quad(Vec3::ZERO, Vec3::Z * 10.0, Vec3::X * 10.0, white),
        // X × Z = -Y: the lamp faces the floor.
        quad(Vec3::new(0.0, 2.0, 0.0), Vec3::X * 0.5, Vec3::Z * 0.5, lamp),
    ];
    if occluder {
        prims.push(quad(
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::Z * 0.5,
            Vec3::X * 0.5,
            white,
        ));
    }
    add_mesh(&mut b, prims);
    load(b, dir)
}

/// Irradiance at floor point `(x, 0, 0)` from the unit lamp of [`lamp_scene`]
/// (radiance 1), integrated on a fine grid.
fn lamp_irradiance(x: f32) -> f32 {
    let n = 200;
    let mut e = 0.0;
    for i in 0..n {
        for j in 0..n {
            let p = Vec3::new(
                -0.5 + (i as f32 + 0.5) / n as f32,
                2.0,
                -0.5 + (j as f32 + 0.5) / n as f32,
            );
            let d = p - Vec3::new(x, 0.0, 0.0);
            let d2 = d.length_squared();
            let cos = d.y / d2.sqrt();
            e += cos * cos / d2;
        }
    }
    e / (n * n) as f32
}

fn no_ambient(spp: u32) -> impl Fn(&mut RenderOptions) {
    move |o: &mut RenderOptions| {
        o.spp = spp;
        o.shading.ambient = Vec3::ZERO;
    }
}

#[test]
fn an_emissive_quad_lights_the_floor_with_distance_falloff() {
    let dir = temp_dir("shading-lamp");
    let scene = lamp_scene(&dir, false);
    let mut last = f32::INFINITY;
    for (i, x) in [0.0f32, 1.0, 2.0, 4.0].into_iter().enumerate() {
        // A camera between lamp and floor (cameras are not geometry), 3×3 pixels on one
        // spot of floor.
        let (f, _) = render(
            &scene,
            &dir,
            &format!("lamp{i}"),
            down_at(x, 1.0, 0.0, 1.0),
            (3, 3),
            no_ambient(256),
        );
        let got = f.at(1, 1).x;
        let want = 0.8 / std::f32::consts::PI * lamp_irradiance(x);
        assert!(
            (got - want).abs() < 0.03 * want,
            "floor at x = {x}: {got}, want {want}"
        );
        assert!(got < last, "no falloff at x = {x}: {got} after {last}");
        last = got;
    }
    // Nothing else lights the scene: no default light was added.
    let (f, _) = render(
        &scene,
        &dir,
        "far",
        down_at(9.0, 1.0, 9.0, 1.0),
        (3, 3),
        no_ambient(4),
    );
    let far = f.at(1, 1).x;
    assert!(
        far > 0.0 && far < 0.1 * last,
        "far corner {far} against {last} at x = 4: more than the lamp gives"
    );
}

#[test]
fn an_occluder_under_the_lamp_casts_a_soft_shadow_that_converges_with_spp() {
    let dir = temp_dir("shading-penumbra");
    let scene = lamp_scene(&dir, true);
    // Umbra |x| < 0.5, penumbra 0.5 < |x| < 1.5, fully lit beyond (similar triangles).
    let spot = |name: &str, x: f32, spp: u32| {
        render(
            &scene,
            &dir,
            name,
            down_at(x, 0.5, 0.0, 0.5),
            (3, 3),
            no_ambient(spp),
        )
        .0
    };
    let umbra = spot("umbra", 0.0, 16).at(1, 1).x;
    assert!(umbra < 1e-6, "umbra {umbra}");
    let lit = spot("lit", 1.8, 64).at(1, 1).x;
    let lit_want = 0.8 / std::f32::consts::PI * lamp_irradiance(1.8);
    assert!(
        (lit - lit_want).abs() < 0.05 * lit_want,
        "lit {lit} want {lit_want}"
    );
    let half = spot("half", 1.0, 256);
    let mid = half.at(1, 1).x;
    // At x = 1 the occluder hides the lamp's half x < 0, the farther one: about 0.6 of
    // the unshadowed light is left.
    let open_dir = temp_dir("shading-penumbra-open");
    let open = render(
        &lamp_scene(&open_dir, false),
        &open_dir,
        "open",
        down_at(1.0, 0.5, 0.0, 0.5),
        (3, 3),
        no_ambient(256),
    )
    .0
    .at(1, 1)
    .x;
    assert!(
        mid > 0.45 * open && mid < 0.75 * open,
        "penumbra {mid} against {open} unshadowed: not a soft edge"
    );
    // Nine pixels on (nearly) the same point: their spread is the sampling noise, and
    // it shrinks with more samples.
    let spread = |f: &Frame| {
        let v: Vec<f32> = f.rgb.iter().map(|c| c.x).collect();
        let mean = v.iter().sum::<f32>() / v.len() as f32;
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / v.len() as f32).sqrt() / mean
    };
    let (noisy, clean) = (spread(&spot("half1", 1.0, 1)), spread(&half));
    assert!(
        noisy > 0.0 && clean < 0.5 * noisy,
        "penumbra noise {clean} at 256 spp, {noisy} at 1 spp"
    );
}

#[test]
fn area_light_frames_are_byte_identical_across_thread_counts() {
    let dir = temp_dir("shading-threads");
    let scene = lamp_scene(&dir, true);
    let look = LookAt {
        from: Vec3::new(3.0, 3.0, 3.0),
        at: Vec3::ZERO,
        up: Vec3::Y,
        yfov_deg: 50.0,
    };
    let bytes = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let (_, path) = pool.install(|| {
            render(&scene, &dir, &format!("t{threads}"), look, (48, 40), |o| {
                o.spp = 3
            })
        });
        std::fs::read(path).unwrap()
    };
    assert_eq!(bytes(1), bytes(3));
}

/// A `w × 1` image of the given RGBA texels.
fn image(texels: &[[u8; 4]]) -> Image {
    Image {
        name: None,
        width: texels.len() as u32,
        height: 1,
        rgba8: texels.iter().flatten().copied().collect(),
    }
}

#[test]
fn a_normal_mapped_plane_follows_the_map() {
    let dir = temp_dir("shading-normal");
    let mut b = SceneBuilder::new();
    let grey = b.add_material(Material {
        base_color: Vec4::new(0.5, 0.5, 0.5, 1.0),
        roughness: 1.0,
        ..dielectric()
    });
    // Floor facing +Y; u runs along +Z, v along +X (see `quad`).
    add_mesh(
        &mut b,
        vec![quad(Vec3::ZERO, Vec3::Z * 5.0, Vec3::X * 5.0, grey)],
    );
    let to_light = Vec3::new(-1.0, 2.0, 1.0).normalize();
    add_sun(&mut b, -to_light, 2.0);
    let mut scene = load(b, &dir);
    // Three texels along u: tilted 30° towards +tangent (+Z), towards -tangent, and
    // towards +Y of the map, which glTF puts towards decreasing v (-X here).
    let (s, c) = (0.5f32, 0.75f32.sqrt());
    let enc = |n: Vec3| -> [u8; 4] {
        let e = |v: f32| ((v * 0.5 + 0.5) * 255.0).round() as u8;
        [e(n.x), e(n.y), e(n.z), 255]
    };
    scene.images.push(image(&[
        enc(Vec3::new(s, 0.0, c)),
        enc(Vec3::new(-s, 0.0, c)),
        enc(Vec3::new(0.0, s, c)),
    ]));
    scene.textures.push(Texture {
        image: scene.images.len() as u32 - 1,
        wrap_s: Wrap::ClampToEdge,
        wrap_t: Wrap::ClampToEdge,
        nearest: true,
    });
    scene.materials[grey as usize].normal_texture = Some(TextureRef {
        texture: scene.textures.len() as u32 - 1,
        tex_coord: 0,
        transform: None,
    });
    // What each texel's normal would be in world space, decoded as the renderer
    // decodes bytes.
    let dec =
        |t: [u8; 4]| Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32) / 255.0 * 2.0 - Vec3::ONE;
    let world = |t: [u8; 4]| {
        let n = dec(t);
        // T = +Z, B = -X, N = +Y.
        (Vec3::Z * n.x - Vec3::X * n.y + Vec3::Y * n.z).normalize()
    };
    let radiance = |n: Vec3| 0.5 / std::f32::consts::PI * 2.0 * n.dot(to_light) + 0.5 * 0.05;
    let texels = [
        enc(Vec3::new(s, 0.0, c)),
        enc(Vec3::new(-s, 0.0, c)),
        enc(Vec3::new(0.0, s, c)),
    ];
    let mut got = Vec::new();
    for (i, z) in [-3.3f32, 0.0, 3.3].into_iter().enumerate() {
        let (f, _) = render(
            &scene,
            &dir,
            &format!("n{i}"),
            down_at(0.0, 2.0, z, 1.0),
            (3, 3),
            |_| {},
        );
        let g = f.at(1, 1).x;
        let want = radiance(world(texels[i]));
        assert!((g - want).abs() < 2e-3, "texel {i}: {g}, want {want}");
        got.push(g);
    }
    // The two halves of the map with opposite slopes are lit differently, and the
    // flat plane lies between them.
    let flat = radiance(Vec3::Y);
    assert!(
        got[0] > flat + 0.02 && got[1] < flat - 0.05,
        "{got:?} flat {flat}"
    );
    // normalTexture.scale 0 flattens the map.
    scene.materials[grey as usize].normal_scale = 0.0;
    let (f, _) = render(
        &scene,
        &dir,
        "n-flat",
        down_at(0.0, 2.0, -3.3, 1.0),
        (3, 3),
        |_| {},
    );
    let g = f.at(1, 1).x;
    assert!((g - flat).abs() < 2e-3, "scale 0: {g}, want {flat}");
}

#[test]
fn a_checkerboard_to_the_horizon_averages_to_grey_at_one_spp() {
    let dir = temp_dir("shading-checker");
    let mut b = SceneBuilder::new();
    let board = b.add_material(Material {
        base_color: Vec4::ONE,
        roughness: 1.0,
        ..dielectric()
    });
    // A 1000 × 1000 floor, a 2 × 2 checker repeated 500 times each way (texels of
    // one world unit).
    let mut floor = quad(Vec3::ZERO, Vec3::Z * 500.0, Vec3::X * 500.0, board);
    if let Some(uvs) = &mut floor.uvs {
        for t in uvs {
            *t *= 500.0;
        }
    }
    add_mesh(&mut b, vec![floor]);
    // Straight down at π lux: radiance = albedo for a white rough diffuse floor.
    add_sun(&mut b, -Vec3::Y, std::f32::consts::PI);
    let mut scene = load(b, &dir);
    let checker = common::build::add_checker(&mut scene);
    scene.materials[board as usize].base_color_texture = Some(TextureRef {
        texture: checker,
        tex_coord: 0,
        transform: None,
    });
    let look = LookAt {
        from: Vec3::new(0.3, 1.0, 0.3),
        at: Vec3::new(10.3, 0.7, -30.0),
        up: Vec3::Y,
        yfov_deg: 40.0,
    };
    let (w, h) = (96usize, 64usize);
    let (f, _) = render(&scene, &dir, "checker", look, (w as u32, h as u32), |o| {
        o.shading.ambient = Vec3::ZERO;
    });
    let stats = |rows: std::ops::Range<usize>| {
        let v: Vec<f32> = rows
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f.at(x, y).x)
            .collect();
        let mean = v.iter().sum::<f32>() / v.len() as f32;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / v.len() as f32).sqrt();
        (mean, sd)
    };
    // Find the horizon: the first row whose pixels all hit the floor.
    let first = (0..h)
        .find(|&y| (0..w).all(|x| f.at(x, y).x > 0.0))
        .expect("the floor is in view");
    let (far_mean, far_sd) = stats(first..first + 6);
    assert!(
        (far_mean - 0.5).abs() < 0.05 && far_sd < 0.06,
        "far field (rows {first}..): mean {far_mean}, deviation {far_sd}: aliasing"
    );
    // The near field still shows the checker.
    let (_, near_sd) = stats(h - 4..h);
    assert!(
        near_sd > 0.3,
        "near field lost its checker: deviation {near_sd}"
    );
}

#[test]
fn flight_helmet_imports_its_normal_maps_and_warns_once_for_occlusion() {
    let Some(path) = common::shared_scene("gltf/FlightHelmet/FlightHelmet.gltf") else {
        return;
    };
    let scene = import::load(&path).unwrap();
    let mapped = scene
        .materials
        .iter()
        .filter(|m| m.normal_texture.is_some())
        .count();
    assert!(mapped >= 5, "{mapped} materials with a normal map");
    let occlusion: Vec<_> = scene
        .warnings
        .iter()
        .filter(|w| w.0.contains("occlusionTexture"))
        .collect();
    assert_eq!(occlusion.len(), 1, "{:?}", scene.warnings);
}
