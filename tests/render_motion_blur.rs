//! Motion blur (`--shutter S --motion-steps K`, issue 35 item 5): a quad sliding 20 px a
//! frame smears over its path with linear ramps and a plateau, measured in the pixels
//! against the coverage the steps give; a still quad beside it stays sharp; a camera
//! moving sideways blurs a still quad; a shutter of 0 changes no byte; blurred frames are
//! the same bytes whatever the thread count or shard, and on the GPU; bad values are one
//! line naming the flag.

mod common;

use std::path::{Path, PathBuf};

use common::build::{linear, mesh, perspective, placed, SceneBuilder};
use common::exr_read::{channel, read_exr};
use common::farm::{ok, s, stderr, subfield};
use common::render_scene::{files_under, quad, temp_dir, write_scene};
use glam::{Quat, Vec3, Vec4};
use subfield::import;
use subfield::render::{self, Aovs, FrameRange, MotionBlur, PixelType, RenderOptions};
use subfield::scene::{Animation, Material, Node, Property, Scene};

const W: usize = 128;
const H: usize = 32;
const YFOV: f32 = 0.8;
const FPS: f32 = 24.0;
/// Distance from the camera to the plane of the quads (z = 0).
const DIST: f32 = 5.0;
/// Screen motion a frame, pixels.
const SLIDE_PX: f32 = 20.0;
/// The slider: half width and its centre's column at frame 1; the still quad likewise.
const SLIDER_HALF: f32 = 14.0;
const SLIDER_AT: f32 = 44.0;
const STILL_HALF: f32 = 6.0;
const STILL_AT: f32 = 105.0;
/// Rows the quads cover: 6..26 (half height 10 px around the middle).
const HALF_ROWS: f32 = 10.0;

/// World units of one pixel at the quads' depth.
fn px() -> f32 {
    2.0 * DIST * (YFOV * 0.5).tan() / H as f32
}

/// World x of image column coordinate `u` (a pixel's left edge is its number).
fn world_x(u: f32) -> f32 {
    (u - W as f32 / 2.0) * px()
}

/// Two emitting quads facing the camera on a black, empty background: "slider" (moving
/// +x at `SLIDE_PX` a frame when `slider_moves`) and "still"; the camera at z = 5 looking
/// down −z, sliding +x by as much when `camera_moves`. Black base colour: a pixel's
/// radiance is its coverage times the emission, and alpha its coverage.
fn scene(dir: &Path, slider_moves: bool, camera_moves: bool) -> Scene {
    let mut b = SceneBuilder::new();
    let glow = b.add_material(Material {
        name: Some("glow".into()),
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        metallic: 0.0,
        emissive: Vec3::ONE,
        emissive_strength: 1.0,
        ..Material::default()
    });
    let (p, h) = (px(), HALF_ROWS * px());
    let slider = b.add_mesh(mesh(
        "slider",
        vec![quad(
            Vec3::ZERO,
            Vec3::X * SLIDER_HALF * p,
            Vec3::Y * h,
            glow,
        )],
    ));
    let still = b.add_mesh(mesh(
        "still",
        vec![quad(
            Vec3::ZERO,
            Vec3::X * STILL_HALF * p,
            Vec3::Y * h,
            glow,
        )],
    ));
    let cam = b.add_camera(perspective("cam", YFOV, None, 0.1, None));
    let mut node = |name: &str, mesh: Option<usize>, camera: Option<usize>, at: Vec3| {
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
    // At frame 0 the slider is one frame's motion short of `SLIDER_AT`.
    let slider_from = Vec3::new(world_x(SLIDER_AT - SLIDE_PX), 0.0, 0.0);
    let slider_node = node("slider", Some(slider), None, slider_from);
    node(
        "still",
        Some(still),
        None,
        Vec3::new(world_x(STILL_AT), 0.0, 0.0),
    );
    let camera_from = Vec3::new(0.0, 0.0, DIST);
    let camera_node = node("camera", None, Some(cam), camera_from);
    // Units a second for SLIDE_PX a frame.
    let speed = SLIDE_PX * p * FPS;
    let slide = |n: usize, from: Vec3| {
        linear(
            n,
            Property::Translation,
            vec![0.0, 1.0],
            [from.to_array(), (from + Vec3::X * speed).to_array()].concat(),
        )
    };
    let mut channels = Vec::new();
    if slider_moves {
        channels.push(slide(slider_node, slider_from));
    }
    if camera_moves {
        channels.push(slide(camera_node, camera_from));
    }
    if !channels.is_empty() {
        b.add_animation(Animation {
            name: Some("slide".into()),
            channels,
        });
    }
    b.scene.fps = Some(FPS);
    let path = dir.join("scene.glb");
    import::write_gltf(&b.finish(), &path).unwrap();
    import::load(&path).unwrap()
}

/// Frame 1 of `scene` at `spp` with `blur`, as float RGBA (and Cryptomatte), into
/// `dir/NAME.1.exr`; its channels.
fn render1(
    dir: &Path,
    name: &str,
    scene: &Scene,
    spp: u32,
    blur: Option<MotionBlur>,
) -> Vec<(String, Vec<f32>)> {
    let opts = RenderOptions {
        output: dir.join(format!("{name}.#.exr")),
        frames: Some(FrameRange { start: 1, end: 2 }.into()),
        width: W as u32,
        height: H as u32,
        spp,
        pixel_type: PixelType::Float,
        aovs: Aovs {
            cryptomatte: true,
            ..Aovs::default()
        },
        motion_blur: blur,
        ..Default::default()
    };
    render::render_sequence(scene, &opts, &mut |_| {}).unwrap();
    let (w, h, chans) = read_exr(&dir.join(format!("{name}.1.exr")));
    assert_eq!((w, h), (W, H));
    chans
}

/// Mean alpha of each column over the quads' inner rows (8..24).
fn column_profile(chans: &[(String, Vec<f32>)]) -> Vec<f32> {
    let a = channel(chans, "A");
    let rows = 8..24;
    let n = rows.len() as f32;
    (0..W)
        .map(|x| rows.clone().map(|y| a[y * W + x]).sum::<f32>() / n)
        .collect()
}

/// The coverage of column `x` by a quad of half width `half` whose centre is at column
/// coordinate `c(k)` at each of `steps` steps: the mean over the steps of the pixel's
/// overlap with the quad.
fn expected(x: usize, half: f32, steps: u32, c: impl Fn(u32) -> f32) -> f32 {
    let (lo, hi) = (x as f32, x as f32 + 1.0);
    (0..steps)
        .map(|k| {
            let (a, b) = (c(k) - half, c(k) + half);
            (hi.min(b) - lo.max(a)).clamp(0.0, 1.0)
        })
        .sum::<f32>()
        / steps as f32
}

/// The slider's centre at step `k` of `steps` of frame 1 with a shutter of 1.
fn slider_centre(k: u32, steps: u32) -> f32 {
    SLIDER_AT + SLIDE_PX * ((k as f32 + 0.5) / steps as f32 - 0.5)
}

#[test]
fn a_sliding_quad_smears_over_its_path_and_a_still_one_stays_sharp() {
    let dir = temp_dir("blur-smear");
    let scene = scene(&dir, true, false);
    let steps = 8;
    let blur = MotionBlur {
        shutter: 1.0,
        steps,
    };
    let spp = 64;
    let blurred = render1(&dir, "blur", &scene, spp, Some(blur));
    let sharp = render1(&dir, "sharp", &scene, spp, None);
    let prof = column_profile(&blurred);
    let sharp_prof = column_profile(&sharp);

    // The profile is the steps' coverage: ramps of 20 px at both ends, a plateau
    // between (the quad is wider than its motion), up to the sampling noise of 8 samples
    // a step and pixel over 16 rows.
    let mut worst = (0.0f32, 0);
    for (x, &p) in prof.iter().enumerate().take(88) {
        let want = expected(x, SLIDER_HALF, steps, |k| slider_centre(k, steps));
        let err = (p - want).abs();
        if err > worst.0 {
            worst = (err, x);
        }
    }
    assert!(
        worst.0 < 0.05,
        "column {} differs from the steps' coverage by {} (profile {:?})",
        worst.1,
        worst.0,
        &prof[..88]
    );
    // Its length: the path of the quad's edges over the shutter plus its width.
    let lit: Vec<usize> = (0..88).filter(|&x| prof[x] > 0.02).collect();
    let span = lit.last().unwrap() - lit.first().unwrap() + 1;
    let want_span = SLIDE_PX * (steps - 1) as f32 / steps as f32 + 2.0 * SLIDER_HALF;
    assert!(
        (span as f32 - want_span).abs() <= 1.5,
        "smear {span} px, want about {want_span}"
    );
    let sharp_span = (0..88).filter(|&x| sharp_prof[x] > 0.02).count();
    assert_eq!(
        sharp_span,
        2 * SLIDER_HALF as usize,
        "unblurred quad's width"
    );
    // The plateau: columns every step covers.
    for (x, &p) in prof.iter().enumerate().take(49).skip(39) {
        assert_eq!(p, 1.0, "column {x} of the plateau");
    }
    // Linear ramps: the left ramp (columns 22..=37, where the quad's left edge passes)
    // lies on a line rising 1/20 a column (the shutter sweeps the edge over 20 px), up to
    // the steps' stairs (1/8 every 2.5 px) and the noise.
    let xs: Vec<f32> = (22..38).map(|x| x as f32).collect();
    let ys = &prof[22..38];
    let n = xs.len() as f32;
    let (mx, my) = (xs.iter().sum::<f32>() / n, ys.iter().sum::<f32>() / n);
    let sxy: f32 = xs.iter().zip(ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f32 = xs.iter().map(|x| (x - mx) * (x - mx)).sum();
    let slope = sxy / sxx;
    let want_slope = 1.0 / SLIDE_PX;
    assert!(
        (slope - want_slope).abs() < 0.1 * want_slope,
        "ramp slope {slope}, want {want_slope}: {ys:?}"
    );
    for (x, y) in xs.iter().zip(ys) {
        let line = my + slope * (x - mx);
        assert!(
            (y - line).abs() < 0.08,
            "column {x}: {y} off the ramp's line {line}"
        );
    }
    // The right ramp mirrors it.
    for d in 0..16 {
        let (l, r) = (prof[22 + d], prof[65 - d]);
        assert!(
            (l - r).abs() < 0.07,
            "ramps not mirrored at {d}: {l} vs {r}"
        );
    }

    // The still quad: its pixels are the unblurred render's (alpha to the bit, radiance
    // up to the order its samples are summed in).
    let (a, a0) = (channel(&blurred, "A"), channel(&sharp, "A"));
    let (r, r0) = (channel(&blurred, "R"), channel(&sharp, "R"));
    for y in 0..H {
        for x in 90..W {
            let i = y * W + x;
            assert_eq!(
                a[i].to_bits(),
                a0[i].to_bits(),
                "still quad's alpha at ({x}, {y})"
            );
            assert!((r[i] - r0[i]).abs() <= 1e-6, "still quad's R at ({x}, {y})");
        }
    }
    let edges = (90..W).filter(|&x| sharp_prof[x] > 0.0 && sharp_prof[x] < 1.0);
    assert!(edges.count() <= 2, "the still quad is sharp without blur");

    // Cryptomatte counts every step's samples: in the smear the slider's coverage (the
    // first rank) is the pixel's alpha, not the share of one step.
    let (id, cov) = (
        channel(&blurred, "CryptoObject00.R"),
        channel(&blurred, "CryptoObject00.G"),
    );
    for y in 8..24 {
        for x in 20..70 {
            let i = y * W + x;
            if a[i] > 0.0 {
                assert!(id[i] != 0.0, "({x}, {y}) has no id");
                assert!(
                    (cov[i] - a[i]).abs() < 1e-6,
                    "({x}, {y}): coverage {} vs alpha {}",
                    cov[i],
                    a[i]
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_moving_camera_blurs_a_still_quad() {
    let dir = temp_dir("blur-camera");
    let scene = scene(&dir, false, true);
    let steps = 8;
    let blur = MotionBlur {
        shutter: 0.5,
        steps,
    };
    let blurred = column_profile(&render1(&dir, "blur", &scene, 32, Some(blur)));
    let sharp = column_profile(&render1(&dir, "sharp", &scene, 32, None));
    // The camera moves +x, the still quad −x on screen: at frame 1 it is one frame's
    // motion left of where it is at frame 0, the shutter half a frame around that.
    let centre = |k: u32| STILL_AT - SLIDE_PX - 0.5 * SLIDE_PX * ((k as f32 + 0.5) / 8.0 - 0.5);
    for x in 60..W {
        let want = expected(x, STILL_HALF, steps, centre);
        assert!(
            (blurred[x] - want).abs() < 0.07,
            "column {x}: {} vs the steps' {want} ({:?})",
            blurred[x],
            &blurred[60..]
        );
    }
    let partial = |p: &[f32]| (60..W).filter(|&x| p[x] > 0.02 && p[x] < 0.98).count();
    assert!(partial(&sharp) <= 2, "unblurred edges: {:?}", &sharp[60..]);
    assert!(
        partial(&blurred) >= 8,
        "blurred edges: {:?}",
        &blurred[60..]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `subfield render` of the shared test scene (moving cube, moving camera, lights) at
/// 40x30, 2 spp, frames 0..3, with every AOV, into `dir/NAME/`, with `extra` flags.
fn cli_render(dir: &Path, scene: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out_dir = dir.join(name);
    let out = out_dir.join("f.##.exr");
    let mut args = vec![
        "render",
        s(scene),
        "-o",
        s(&out),
        "--frames",
        "0..3",
        "--size",
        "40x30",
        "--spp",
        "2",
        "--aov",
        "depth,normal,albedo,position,motion,cryptomatte",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    ok(&args);
    out_dir
}

fn bytes_of(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    files_under(dir)
        .into_iter()
        .map(|f| {
            let b = std::fs::read(dir.join(&f)).unwrap();
            (f, b)
        })
        .collect()
}

fn contains(hay: &[u8], needle: &str) -> bool {
    hay.windows(needle.len()).any(|w| w == needle.as_bytes())
}

#[test]
fn blurred_frames_are_the_same_bytes_across_threads_and_shards_and_shutter_0_changes_nothing() {
    let dir = temp_dir("blur-cli");
    let scene = write_scene(&dir);
    let plain = bytes_of(&cli_render(&dir, &scene, "plain", &[]));
    let zero = bytes_of(&cli_render(&dir, &scene, "zero", &["--shutter", "0"]));
    assert_eq!(plain.len(), 3);
    assert_eq!(plain, zero, "--shutter 0 changed the frames");
    for (f, b) in &plain {
        assert!(
            !contains(b, "shutter="),
            "{}: header names a shutter",
            f.display()
        );
    }

    let blur = ["--shutter", "1", "--motion-steps", "4"];
    let t1 = bytes_of(&cli_render(
        &dir,
        &scene,
        "t1",
        &[&blur[..], &["--threads", "1"]].concat(),
    ));
    let t2 = bytes_of(&cli_render(
        &dir,
        &scene,
        "t2",
        &[&blur[..], &["--threads", "2"]].concat(),
    ));
    assert_eq!(t1, t2, "blurred frames differ between --threads 1 and 2");
    let sh = dir.join("t2sh");
    for i in ["0/2", "1/2"] {
        cli_render(&dir, &scene, "t2sh", &[&blur[..], &["--shard", i]].concat());
    }
    assert_eq!(t1, bytes_of(&sh), "blurred frames differ when sharded");
    for ((f, b), (_, p)) in t1.iter().zip(&plain) {
        assert!(contains(b, "shutter=1 motion-steps=4"), "{}", f.display());
        assert_ne!(b, p, "{}: blur changed nothing", f.display());
    }
    // The AOVs come from the frame's own time (at 4 steps, none of which is at that
    // time, a pass of their own): they are the unblurred frame's.
    let (_, _, c0) = read_exr(&dir.join("plain").join("f.01.exr"));
    let (_, _, c1) = read_exr(&dir.join("t1").join("f.01.exr"));
    for name in ["Z", "N.X", "P.Y", "albedo.R", "motion.X", "motion.Y"] {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            bits(channel(&c0, name)),
            bits(channel(&c1, name)),
            "{name} differs from the unblurred frame's"
        );
    }
    // --resume re-renders frames made without blur (their options string differs).
    let o = ok(&[
        "render",
        s(&scene),
        "-o",
        s(&dir.join("plain").join("f.##.exr")),
        "--frames",
        "0..3",
        "--size",
        "40x30",
        "--spp",
        "2",
        "--aov",
        "depth,normal,albedo,position,motion,cryptomatte",
        "--shutter",
        "1",
        "--motion-steps",
        "4",
        "--resume",
    ]);
    assert!(
        stderr(&o).contains("--resume rendered 3 finished frames again"),
        "{}",
        stderr(&o)
    );
    assert_eq!(bytes_of(&dir.join("plain")), t1);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_middle_step_gives_the_aovs_at_an_odd_step_count() {
    let dir = temp_dir("blur-odd");
    let scene = write_scene(&dir);
    cli_render(&dir, &scene, "plain", &[]);
    cli_render(&dir, &scene, "odd", &["--shutter", "0.5"]);
    let (_, _, c0) = read_exr(&dir.join("plain").join("f.02.exr"));
    let bytes = std::fs::read(dir.join("odd").join("f.02.exr")).unwrap();
    assert!(
        contains(&bytes, "shutter=0.5 motion-steps=5"),
        "the default step count"
    );
    let (_, _, c1) = read_exr(&dir.join("odd").join("f.02.exr"));
    for name in ["Z", "N.Y", "P.X", "albedo.G", "motion.X"] {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(channel(&c0, name)), bits(channel(&c1, name)), "{name}");
    }
    assert_ne!(channel(&c0, "R"), channel(&c1, "R"), "no blur");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_blur_values_are_one_line_naming_the_flag() {
    let dir = temp_dir("blur-bad");
    let scene = write_scene(&dir);
    let out = dir.join("f.#.exr");
    let cases: [(&[&str], &str); 6] = [
        (&["--shutter", "1.5"], "--shutter 1.5"),
        (&["--shutter", "-0.25"], "--shutter -0.25"),
        (&["--shutter", "NaN"], "--shutter NaN"),
        (
            &["--shutter", "1", "--motion-steps", "0"],
            "--motion-steps 0",
        ),
        (
            &["--shutter", "1", "--motion-steps", "257"],
            "--motion-steps 257",
        ),
        (&["--motion-steps", "4"], "--motion-steps 4 needs --shutter"),
    ];
    for (extra, want) in cases {
        let mut args = vec![
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--frames",
            "0",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        let o = subfield(&args);
        let e = stderr(&o);
        assert!(!o.status.success(), "{extra:?} succeeded");
        assert_eq!(e.trim_end().lines().count(), 1, "{extra:?}: {e}");
        assert!(e.contains(want), "{extra:?}: {e}");
    }
    assert!(
        files_under(&dir)
            .iter()
            .all(|f| f.extension().unwrap() == "glb"),
        "a frame was written"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn submit_forwards_the_blur_to_its_tasks() {
    let dir = temp_dir("blur-submit");
    let scene = write_scene(&dir);
    let out = dir.join("out/f.##.exr");
    let o = ok(&[
        "submit",
        "slurm",
        s(&scene),
        "-o",
        s(&out),
        "--frames",
        "0..4",
        "--size",
        "40x30",
        "--shutter",
        "0.5",
        "--motion-steps",
        "3",
        "--dry-run",
        "--quiet",
    ]);
    let script = String::from_utf8_lossy(&o.stdout);
    assert!(
        script.contains("--shutter=0.5") && script.contains("--motion-steps=3"),
        "{script}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The test scene blurred on the GPU (the frame path: every step traced and shaded
/// there): the AOVs, Z and Cryptomatte the CPU's to the bit, the colour within 1e-3 in
/// every pixel (the GPU's shading arithmetic rounds differently in the last bits;
/// tests/gpu_frames.rs states the bound, docs/GPU.md why).
#[cfg(feature = "gpu")]
#[test]
fn gpu_blurred_frames_match_cpu_blurred_frames() {
    if common::gpu::device().is_none() {
        return;
    }
    let dir = temp_dir("blur-gpu");
    let scene = write_scene(&dir);
    let blur = ["--shutter", "1", "--motion-steps", "3", "--float"];
    let cpu = cli_render(
        &dir,
        &scene,
        "cpu",
        &[&blur[..], &["--device", "cpu"]].concat(),
    );
    let gpu = cli_render(
        &dir,
        &scene,
        "gpu",
        &[&blur[..], &["--device", "gpu"]].concat(),
    );
    for f in files_under(&cpu) {
        let (_, _, a) = read_exr(&cpu.join(&f));
        let (_, _, b) = read_exr(&gpu.join(&f));
        assert_eq!(a.len(), b.len());
        for ((na, va), (nb, vb)) in a.iter().zip(&b) {
            assert_eq!(na, nb);
            if ["R", "G", "B"].contains(&na.as_str()) {
                for (x, y) in va.iter().zip(vb) {
                    assert!(
                        (x - y).abs() <= 1e-3 * x.abs().max(1.0),
                        "{}: {na} {x} on the CPU, {y} on the GPU",
                        f.display()
                    );
                }
                continue;
            }
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(va), bits(vb), "{}: channel {na}", f.display());
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
