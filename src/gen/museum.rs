//! The built-in museum: the demo scene of `subfield demo` and `subfield generate museum`,
//! made in code as glTF, in the manner of BART's *museum* (Lext, Assarsson, Möller).
//!
//! * **Static part**: a 20 × 8 × 20 room (checkered floor, walls, ceiling, a baseboard),
//!   four pillars, seven framed paintings, a framed wall mirror, pedestals with a chrome
//!   sphere, a glass sphere and a bronze torus, two benches. Exactly `static_tris`
//!   triangles: the tessellation of the room, pillars, spheres and torus is chosen from
//!   the budget and the baseboard takes the last few triangles.
//! * **Dynamic part**: `dynamic_tris` independent triangles (three unshared vertices each),
//!   choreographed like BART's *animart*: scattered in the air, gathering into a sphere,
//!   exploding, a torus, exploding, a cube, exploding, a double helix, scattering again. Each
//!   formation assigns every triangle a random slot, so paths cross: the motion has no
//!   structure a hierarchy could follow.
//! * **Motion encoding** (what `../shared/peers/gen_scene.py` does, so the Embree harness
//!   reads the very same triangles): key `k` is morph target `k` (its displacement from
//!   key 0, so target 0 is zero), and one LINEAR `weights` channel is one-hot at key `k`:
//!   between two keys exactly two consecutive targets blend and a vertex moves on the
//!   straight line between its two key positions.
//! * A perspective camera inside the room looking at the centre of the action, a point
//!   light under the ceiling and a spot light. The spot's node is a child of the point
//!   light's: our importer (depth first, roots in order) and the harness (which pops its
//!   node stack, so it visits roots last to first but a parent before its children) then
//!   both meet the point light first.
//! * `scenes[0].extras.fps` is `fps`; the last key falls on frame `frames − 1`.
//!
//! Deterministic: the same parameters give the same bytes (SplitMix64 from the seed, no
//! hash-map order; trigonometry is the platform's `f32` `sin`/`cos`, so the bytes are the
//! same on one platform and build, and may differ in the last bit across C libraries).
//! The seed moves the dynamic triangles only; the room is the same for every seed.

use std::path::Path;

use glam::{Quat, Vec2, Vec3, Vec4};

use super::synth::Rng;
use crate::import::{
    AnimationDesc, CameraDesc, ChannelDesc, GltfBuilder, ImportError, MaterialDesc, MeshDesc,
    NodeDesc, PrimitiveDesc,
};
use crate::scene::{Interpolation, LightDef, LightKind, Property};

/// Morph keys of the dynamic part (one morph target each). 13 keys over 10 s: a formation
/// every 0.8 s, and 7.7 MB of targets at the default 16,384 triangles.
pub const MUSEUM_KEYS: usize = 13;

/// Fewest static triangles the room can be built with (every part at its coarsest).
pub const MIN_STATIC_TRIS: usize = FIXED_TRIS + BASEBOARD_MIN + MIN_SCALABLE;

/// Caps that keep a request inside memory and the 4 GiB GLB limit (a dynamic triangle
/// costs about 36 bytes per key).
pub const MAX_STATIC_TRIS: usize = 20_000_000;
pub const MAX_DYNAMIC_TRIS: usize = 4_000_000;
pub const MAX_FRAMES: u32 = 1_000_000;
pub const MAX_FPS: f32 = 10_000.0;

/// What to build. The defaults are the paper's museum7 figures (10,284 static and
/// 16,384 dynamic triangles, 300 frames) at 30 frames per second.
#[derive(Clone, Debug, PartialEq)]
pub struct MuseumParams {
    /// Static triangles, exactly; at least [`MIN_STATIC_TRIS`].
    pub static_tris: usize,
    /// Moving triangles, at least 1.
    pub dynamic_tris: usize,
    /// Frames of the animation (at least 2); frame `i` shows time `i / fps`, and the last
    /// key is at `(frames − 1) / fps`.
    pub frames: u32,
    pub fps: f32,
    /// Seeds the dynamic triangles' shapes and paths.
    pub seed: u64,
}

impl Default for MuseumParams {
    fn default() -> Self {
        MuseumParams {
            static_tris: 10_284,
            dynamic_tris: 16_384,
            frames: 300,
            fps: 30.0,
            seed: 1,
        }
    }
}

impl MuseumParams {
    /// Refuses numbers the museum cannot be built with, naming the parameter.
    pub fn validate(&self) -> Result<(), MuseumError> {
        let bad = |param: &'static str, value: String, reason: String| {
            Err(MuseumError::Param {
                param,
                value,
                reason,
            })
        };
        if self.static_tris < MIN_STATIC_TRIS || self.static_tris > MAX_STATIC_TRIS {
            return bad(
                "static triangles",
                self.static_tris.to_string(),
                format!(
                    "must be {MIN_STATIC_TRIS}..={MAX_STATIC_TRIS} (the room, pillars and \
                     paintings at their coarsest take {MIN_STATIC_TRIS})"
                ),
            );
        }
        if self.dynamic_tris == 0 || self.dynamic_tris > MAX_DYNAMIC_TRIS {
            return bad(
                "dynamic triangles",
                self.dynamic_tris.to_string(),
                format!("must be 1..={MAX_DYNAMIC_TRIS}"),
            );
        }
        if self.frames < 2 || self.frames > MAX_FRAMES {
            return bad(
                "frames",
                self.frames.to_string(),
                format!("must be 2..={MAX_FRAMES} (the animation needs a duration)"),
            );
        }
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= MAX_FPS) {
            return bad(
                "fps",
                self.fps.to_string(),
                format!("must be a number in (0, {MAX_FPS}]"),
            );
        }
        Ok(())
    }

    /// Length of the animation in seconds: the time of the last frame.
    pub fn duration(&self) -> f32 {
        self.frames.saturating_sub(1) as f32 / self.fps
    }

    /// Times of the morph keys, evenly spaced from 0 to [`MuseumParams::duration`].
    pub fn key_times(&self) -> Vec<f32> {
        let d = self.duration();
        (0..MUSEUM_KEYS)
            .map(|k| d * k as f32 / (MUSEUM_KEYS - 1) as f32)
            .collect()
    }
}

/// Why the museum could not be built or written.
#[derive(Debug, thiserror::Error)]
pub enum MuseumError {
    /// A parameter out of range.
    #[error("museum: {param} {value}: {reason}")]
    Param {
        param: &'static str,
        value: String,
        reason: String,
    },
    /// The glTF writer refused the scene or could not write the file.
    #[error(transparent)]
    Gltf(#[from] ImportError),
}

/// The museum as a glTF builder (add to it, or write it with [`GltfBuilder::write`] /
/// [`GltfBuilder::to_glb`]).
pub fn museum(p: &MuseumParams) -> Result<GltfBuilder, MuseumError> {
    p.validate()?;
    let mut b = GltfBuilder::new();
    b.fps = Some(p.fps);
    let m = Materials::add(&mut b);
    let plan = Plan::for_budget(p.static_tris);
    build_static(&mut b, &m, &plan);
    build_dynamic(&mut b, &m, p);
    build_camera_and_lights(&mut b);
    Ok(b)
}

/// The museum as GLB bytes.
pub fn museum_glb(p: &MuseumParams) -> Result<Vec<u8>, MuseumError> {
    Ok(museum(p)?.to_glb()?)
}

/// Writes the museum to `path` atomically (`.gltf`: JSON with an embedded buffer; any
/// other extension: GLB).
pub fn write_museum(p: &MuseumParams, path: &Path) -> Result<(), MuseumError> {
    Ok(museum(p)?.write(path)?)
}

// ------------------------------------------------------------------------------ layout

/// Half extents of the room: x and z in [-10, 10], y (up) in [0, 8].
const ROOM_HALF: f32 = 10.0;
const ROOM_HEIGHT: f32 = 8.0;
/// Where the dynamic formations gather.
const CENTRE: Vec3 = Vec3::new(0.0, 3.6, 0.0);
const PILLARS: [Vec2; 4] = [
    Vec2::new(-6.0, -6.0),
    Vec2::new(6.0, -6.0),
    Vec2::new(-6.0, 6.0),
    Vec2::new(6.0, 6.0),
];

/// Triangles of the parts whose tessellation does not depend on the budget: 7 paintings
/// and a mirror (canvas 2 + frame 4 boxes), 3 pedestals, 2 benches (3 boxes), and each
/// pillar's base and capital (2 boxes).
const FRAMED: usize = 2 + 4 * 12;
const FIXED_TRIS: usize = 8 * FRAMED + 3 * 12 + 2 * 3 * 12 + 4 * 2 * 12;
/// The baseboard takes what is left; it needs one quad per wall.
const BASEBOARD_MIN: usize = 8;
const MIN_SCALABLE: usize = shell_tris(1) + 4 * pillar_tris(6) + 2 * sphere_tris(3) + torus_tris(6);

const fn wall_rows(n: usize) -> usize {
    // Walls are 8 high and 20 wide: keep their cells near square.
    let m = (2 * n + 2) / 5;
    if m == 0 {
        1
    } else {
        m
    }
}
/// Floor and ceiling `n × n`, four walls `n × wall_rows(n)`.
const fn shell_tris(n: usize) -> usize {
    4 * n * n + 8 * n * wall_rows(n)
}
/// One pillar's open cylinder: `s` segments around, `s / 2` rings up.
const fn pillar_tris(s: usize) -> usize {
    let r = if s / 2 == 0 { 1 } else { s / 2 };
    2 * s * r
}
/// UV sphere with `r` rings and `2r` segments.
const fn sphere_tris(r: usize) -> usize {
    4 * r * (r - 1)
}
/// Torus with `a` segments around and `a / 2` (at least 3) around the tube.
const fn torus_tris(a: usize) -> usize {
    2 * a * torus_tube(a)
}
const fn torus_tube(a: usize) -> usize {
    if a / 2 < 3 {
        3
    } else {
        a / 2
    }
}

/// Tessellation levels for a static budget.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Plan {
    shell: usize,
    pillar: usize,
    sphere: usize,
    torus: usize,
    baseboard: usize,
}

impl Plan {
    /// Shares of what is left above the minimum: room shell 35 %, pillars 15 %, each
    /// sphere 15 %, the torus the rest (about 20 %); the baseboard takes the rounding
    /// (8 to about 100 triangles at the default budget), so the total is exact.
    /// `static_tris` must be at least [`MIN_STATIC_TRIS`].
    fn for_budget(static_tris: usize) -> Plan {
        let budget = static_tris.saturating_sub(FIXED_TRIS + BASEBOARD_MIN);
        let extra = budget.saturating_sub(MIN_SCALABLE) as f64;
        let cap = |min: usize, share: f64| min + (share * extra) as usize;
        // Largest level whose count fits the cap (counts grow with the level).
        let fit = |start: usize, count: &dyn Fn(usize) -> usize, cap: usize| {
            let mut l = start;
            while count(l + 1) <= cap {
                l += 1;
            }
            l
        };
        let shell = fit(1, &|n| shell_tris(n), cap(shell_tris(1), 0.35));
        let pillar = fit(6, &|s| 4 * pillar_tris(s), cap(4 * pillar_tris(6), 0.15));
        let sphere = fit(3, &sphere_tris, cap(sphere_tris(3), 0.15));
        let used = shell_tris(shell) + 4 * pillar_tris(pillar) + 2 * sphere_tris(sphere);
        let torus = fit(6, &torus_tris, budget.saturating_sub(used));
        let baseboard = static_tris
            .saturating_sub(FIXED_TRIS + used + torus_tris(torus))
            .max(BASEBOARD_MIN);
        Plan {
            shell,
            pillar,
            sphere,
            torus,
            baseboard,
        }
    }
}

// ------------------------------------------------------------------------------ materials

struct Materials {
    floor_light: u32,
    floor_dark: u32,
    wall: u32,
    ceiling: u32,
    marble: u32,
    gold: u32,
    mirror: u32,
    chrome: u32,
    glass: u32,
    bronze: u32,
    wood: u32,
    baseboard: u32,
    canvases: [u32; 7],
    chips: [u32; 4],
}

impl Materials {
    fn add(b: &mut GltfBuilder) -> Materials {
        let mut mat = |name: &str, rgb: [f32; 3], metallic: f32, roughness: f32| {
            b.add_material(MaterialDesc {
                name: Some(name.to_string()),
                base_color: Vec3::from(rgb).extend(1.0),
                metallic,
                roughness,
                ..MaterialDesc::default()
            })
        };
        let floor_light = mat("floor-marble-light", [0.82, 0.80, 0.74], 0.0, 0.25);
        let floor_dark = mat("floor-marble-dark", [0.07, 0.07, 0.08], 0.0, 0.25);
        let wall = mat("wall", [0.72, 0.62, 0.48], 0.0, 0.9);
        let ceiling = mat("ceiling", [0.90, 0.90, 0.88], 0.0, 0.9);
        let marble = mat("pillar-marble", [0.88, 0.86, 0.82], 0.0, 0.4);
        let gold = mat("frame-gold", [1.0, 0.78, 0.34], 1.0, 0.25);
        let mirror = mat("mirror", [0.95, 0.95, 0.95], 1.0, 0.0);
        let chrome = mat("chrome", [0.90, 0.90, 0.92], 1.0, 0.02);
        let bronze = mat("bronze", [0.80, 0.50, 0.28], 1.0, 0.3);
        let wood = mat("wood", [0.35, 0.22, 0.12], 0.0, 0.6);
        let baseboard = mat("baseboard", [0.20, 0.15, 0.10], 0.0, 0.5);
        let palette = [
            [0.70, 0.12, 0.10],
            [0.10, 0.25, 0.60],
            [0.85, 0.65, 0.15],
            [0.12, 0.45, 0.22],
            [0.50, 0.20, 0.55],
            [0.90, 0.45, 0.20],
            [0.20, 0.55, 0.60],
        ];
        let mut canvases = [0; 7];
        for (i, c) in palette.iter().enumerate() {
            canvases[i] = mat(&format!("canvas-{i}"), *c, 0.0, 0.8);
        }
        let glass = b.add_material(MaterialDesc {
            name: Some("glass".into()),
            base_color: Vec4::new(0.95, 0.97, 1.0, 1.0),
            metallic: 0.0,
            roughness: 0.0,
            transmission: 1.0,
            ior: 1.5,
            ..MaterialDesc::default()
        });
        // Thin triangles seen from both sides.
        let mut chip = |name: &str, rgb: [f32; 3], metallic: f32, roughness: f32| {
            b.add_material(MaterialDesc {
                name: Some(name.to_string()),
                base_color: Vec3::from(rgb).extend(1.0),
                metallic,
                roughness,
                double_sided: true,
                ..MaterialDesc::default()
            })
        };
        let chips = [
            chip("chip-red", [0.85, 0.12, 0.08], 0.0, 0.4),
            chip("chip-gold", [1.0, 0.80, 0.40], 1.0, 0.15),
            chip("chip-blue", [0.12, 0.30, 0.85], 0.0, 0.4),
            chip("chip-white", [0.92, 0.92, 0.90], 0.0, 0.4),
        ];
        Materials {
            floor_light,
            floor_dark,
            wall,
            ceiling,
            marble,
            gold,
            mirror,
            chrome,
            glass,
            bronze,
            wood,
            baseboard,
            canvases,
            chips,
        }
    }
}

// ------------------------------------------------------------------------------ geometry

/// Indexed triangles under construction; `normals` is empty (flat shading) or one per
/// position (smooth).
#[derive(Default)]
struct Part {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    indices: Vec<u32>,
}

impl Part {
    fn base(&self) -> u32 {
        self.positions.len() as u32
    }

    /// `nu × nv` cells spanning `du`, `dv` from `origin`; front side (counter-clockwise)
    /// towards `du × dv`.
    fn grid(&mut self, origin: Vec3, du: Vec3, dv: Vec3, nu: usize, nv: usize) {
        let base = self.base();
        for i in 0..=nu {
            for j in 0..=nv {
                let p = origin + du * (i as f32 / nu as f32) + dv * (j as f32 / nv as f32);
                self.positions.push(p);
            }
        }
        let at = |i: usize, j: usize| base + (i * (nv + 1) + j) as u32;
        for i in 0..nu {
            for j in 0..nv {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                self.indices.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
    }

    /// An axis-aligned box, faces outwards, 12 triangles.
    fn cuboid(&mut self, lo: Vec3, hi: Vec3) {
        let e = hi - lo;
        let (x, y, z) = (Vec3::X * e.x, Vec3::Y * e.y, Vec3::Z * e.z);
        self.grid(lo, z, y, 1, 1); // -X
        self.grid(lo + x, y, z, 1, 1); // +X
        self.grid(lo, x, z, 1, 1); // -Y
        self.grid(lo + y, z, x, 1, 1); // +Y
        self.grid(lo, y, x, 1, 1); // -Z
        self.grid(lo + z, x, y, 1, 1); // +Z
    }

    /// A vertical band of `quads` cells from `origin` along `du`, `dv` up; with `odd`, the
    /// last cell is three triangles (a vertex in the middle of its top edge, which is a
    /// border, so no crack).
    fn band(&mut self, origin: Vec3, du: Vec3, dv: Vec3, quads: usize, odd: bool) {
        let base = self.base();
        for i in 0..=quads {
            let p = origin + du * (i as f32 / quads as f32);
            self.positions.push(p);
            self.positions.push(p + dv);
        }
        for i in 0..quads as u32 {
            let (b0, t0, b1, t1) = (
                base + 2 * i,
                base + 2 * i + 1,
                base + 2 * i + 2,
                base + 2 * i + 3,
            );
            if odd && i + 1 == quads as u32 {
                let m = self.base();
                let mid = (self.positions[t0 as usize] + self.positions[t1 as usize]) * 0.5;
                self.positions.push(mid);
                self.indices
                    .extend_from_slice(&[b0, b1, t1, b0, t1, m, b0, m, t0]);
            } else {
                self.indices.extend_from_slice(&[b0, b1, t1, b0, t1, t0]);
            }
        }
    }

    #[cfg(test)]
    fn tris(&self) -> usize {
        self.indices.len() / 3
    }

    fn primitive(self, material: u32) -> PrimitiveDesc {
        PrimitiveDesc {
            normals: (!self.normals.is_empty()).then_some(self.normals),
            positions: self.positions,
            indices: Some(self.indices),
            material: Some(material),
            ..PrimitiveDesc::default()
        }
    }
}

/// Smooth surface `f(u, v) -> (position, normal)` over a `nu × nv` lattice; `wrap_u`
/// closes the lattice in `u` (no seam vertices: shading needs none without UVs).
/// Front side (counter-clockwise) towards `∂f/∂u × ∂f/∂v`.
fn smooth_lattice(
    part: &mut Part,
    nu: usize,
    nv: usize,
    wrap_v: bool,
    f: impl Fn(f32, f32) -> (Vec3, Vec3),
) {
    let base = part.base();
    let cols = if wrap_v { nv } else { nv + 1 };
    for i in 0..=nu {
        for j in 0..cols {
            let (p, n) = f(i as f32 / nu as f32, j as f32 / nv as f32);
            part.positions.push(p);
            part.normals.push(n);
        }
    }
    let at = |i: usize, j: usize| base + (i * cols + j % cols) as u32;
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            part.indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
}

/// UV sphere around the origin: `rings` bands, `2 * rings` segments, fans at the poles.
fn sphere(radius: f32, rings: usize) -> Part {
    let segs = 2 * rings;
    let mut part = Part::default();
    let dir = |i: usize, j: usize| {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        let ph = std::f32::consts::TAU * j as f32 / segs as f32;
        Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin())
    };
    part.positions.push(Vec3::Y * radius);
    part.normals.push(Vec3::Y);
    for i in 1..rings {
        for j in 0..segs {
            let d = dir(i, j);
            part.positions.push(d * radius);
            part.normals.push(d);
        }
    }
    let bottom = part.base();
    part.positions.push(Vec3::NEG_Y * radius);
    part.normals.push(Vec3::NEG_Y);
    let at = |i: usize, j: usize| 1 + ((i - 1) * segs + j % segs) as u32;
    for j in 0..segs {
        part.indices.extend_from_slice(&[0, at(1, j + 1), at(1, j)]);
        part.indices
            .extend_from_slice(&[bottom, at(rings - 1, j), at(rings - 1, j + 1)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
            let (a, b, c, d) = (at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
            part.indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    part
}

/// One pillar: an open cylinder of radius 0.4 from the base to the capital (smooth),
/// and the base and capital blocks (flat). Local origin on the floor.
fn pillar(segments: usize) -> (Part, Part) {
    let rings = (segments / 2).max(1);
    let mut column = Part::default();
    smooth_lattice(&mut column, rings, segments, true, |u, v| {
        let (s, c) = (std::f32::consts::TAU * v).sin_cos();
        let n = Vec3::new(c, 0.0, s);
        (n * 0.4 + Vec3::Y * (0.3 + 7.3 * u), n)
    });
    let mut blocks = Part::default();
    blocks.cuboid(Vec3::new(-0.55, 0.0, -0.55), Vec3::new(0.55, 0.3, 0.55));
    blocks.cuboid(
        Vec3::new(-0.55, 7.6, -0.55),
        Vec3::new(0.55, ROOM_HEIGHT, 0.55),
    );
    (column, blocks)
}

/// Torus around the local Y axis: major radius 0.55, tube 0.2.
fn torus(segments: usize) -> Part {
    let tube = torus_tube(segments);
    let mut part = Part::default();
    // u around the tube, v around the ring: ∂f/∂u × ∂f/∂v points outwards.
    smooth_lattice(&mut part, tube, segments, true, |u, v| {
        let (sp, cp) = (std::f32::consts::TAU * u).sin_cos();
        let (st, ct) = (std::f32::consts::TAU * v).sin_cos();
        let n = Vec3::new(cp * ct, sp, cp * st);
        (Vec3::new(0.55 * ct, 0.0, 0.55 * st) + n * 0.2, n)
    });
    // The tube wraps too: its first and last rows coincide, so merge them.
    let cols = segments as u32;
    let last_row = tube as u32 * cols;
    for i in &mut part.indices {
        if *i >= last_row {
            *i -= last_row;
        }
    }
    part.positions.truncate(last_row as usize);
    part.normals.truncate(last_row as usize);
    part
}

/// A framed picture in its local frame: canvas `w × h` centred on the origin facing +Z,
/// a gold frame 0.12 wide and 0.08 deep behind it against the wall (z = 0).
fn framed(w: f32, h: f32, canvas_material: u32, gold: u32) -> MeshDesc {
    let (hw, hh, bar, depth) = (w / 2.0, h / 2.0, 0.12, 0.08);
    let mut frame = Part::default();
    frame.cuboid(
        Vec3::new(-hw - bar, hh, 0.0),
        Vec3::new(hw + bar, hh + bar, depth),
    );
    frame.cuboid(
        Vec3::new(-hw - bar, -hh - bar, 0.0),
        Vec3::new(hw + bar, -hh, depth),
    );
    frame.cuboid(Vec3::new(-hw - bar, -hh, 0.0), Vec3::new(-hw, hh, depth));
    frame.cuboid(Vec3::new(hw, -hh, 0.0), Vec3::new(hw + bar, hh, depth));
    let mut canvas = Part::default();
    canvas.grid(Vec3::new(-hw, -hh, 0.03), Vec3::X * w, Vec3::Y * h, 1, 1);
    MeshDesc {
        name: None,
        primitives: vec![frame.primitive(gold), canvas.primitive(canvas_material)],
        weights: Vec::new(),
    }
}

fn node(name: &str, mesh: u32, translation: Vec3, rotation: Quat) -> NodeDesc {
    NodeDesc {
        name: Some(name.to_string()),
        mesh: Some(mesh),
        translation,
        rotation,
        ..NodeDesc::default()
    }
}

fn add_root(b: &mut GltfBuilder, n: NodeDesc) -> u32 {
    let i = b.add_node(n);
    b.add_root(i);
    i
}

fn build_static(b: &mut GltfBuilder, m: &Materials, plan: &Plan) {
    let (h, top) = (ROOM_HALF, ROOM_HEIGHT);
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);

    // Room shell: checkered floor, ceiling, walls facing inwards, baseboard.
    let n = plan.shell;
    let rows = wall_rows(n);
    let (mut light, mut dark) = (Part::default(), Part::default());
    let cell = 2.0 * h / n as f32;
    for i in 0..n {
        for j in 0..n {
            let o = Vec3::new(-h + i as f32 * cell, 0.0, -h + j as f32 * cell);
            let tile = if (i + j) % 2 == 0 {
                &mut light
            } else {
                &mut dark
            };
            tile.grid(o, z * cell, x * cell, 1, 1);
        }
    }
    let mut ceiling = Part::default();
    ceiling.grid(Vec3::new(-h, top, -h), x * 2.0 * h, z * 2.0 * h, n, n);
    let mut walls = Part::default();
    let (w, up) = (2.0 * h, y * top);
    walls.grid(Vec3::new(-h, 0.0, -h), x * w, up, n, rows); // back, faces +Z
    walls.grid(Vec3::new(-h, 0.0, h), up, x * w, rows, n); // front, faces -Z
    walls.grid(Vec3::new(-h, 0.0, -h), up, z * w, rows, n); // left, faces +X
    walls.grid(Vec3::new(h, 0.0, -h), z * w, up, n, rows); // right, faces -X
    let mut board = Part::default();
    let quads = plan.baseboard / 2;
    let (inset, height) = (0.02, y * 0.2);
    let sides = [
        (Vec3::new(-h, 0.0, -h + inset), x * w), // back
        (Vec3::new(h, 0.0, h - inset), -x * w),  // front
        (Vec3::new(-h + inset, 0.0, h), -z * w), // left
        (Vec3::new(h - inset, 0.0, -h), z * w),  // right
    ];
    for (k, (o, du)) in sides.into_iter().enumerate() {
        let q = quads / 4 + usize::from(k < quads % 4);
        board.band(o, du, height, q, k == 3 && plan.baseboard % 2 == 1);
    }
    let room = b.add_mesh(MeshDesc {
        name: Some("room".into()),
        // A 1 × 1 floor has no dark tile: empty parts are left out.
        primitives: [
            (light, m.floor_light),
            (dark, m.floor_dark),
            (ceiling, m.ceiling),
            (walls, m.wall),
            (board, m.baseboard),
        ]
        .into_iter()
        .filter(|(part, _)| !part.indices.is_empty())
        .map(|(part, material)| part.primitive(material))
        .collect(),
        weights: Vec::new(),
    });
    add_root(b, node("room", room, Vec3::ZERO, Quat::IDENTITY));

    // Pillars: one mesh, four nodes.
    let (column, blocks) = pillar(plan.pillar);
    let pillar_mesh = b.add_mesh(MeshDesc {
        name: Some("pillar".into()),
        primitives: vec![column.primitive(m.marble), blocks.primitive(m.marble)],
        weights: Vec::new(),
    });
    for (i, p) in PILLARS.iter().enumerate() {
        let at = Vec3::new(p.x, 0.0, p.y);
        add_root(
            b,
            node(&format!("pillar-{i}"), pillar_mesh, at, Quat::IDENTITY),
        );
    }

    // Paintings and the mirror: local +Z turned to face into the room, 1 cm off the wall.
    let turn = |deg: f32| Quat::from_rotation_y(deg.to_radians());
    let off = 0.01;
    let hangs: [(&str, Vec3, Quat, f32, f32); 8] = [
        (
            "painting-0",
            Vec3::new(-4.5, 3.2, -h + off),
            turn(0.0),
            3.0,
            2.0,
        ),
        (
            "painting-1",
            Vec3::new(0.0, 3.4, -h + off),
            turn(0.0),
            3.6,
            2.6,
        ),
        (
            "painting-2",
            Vec3::new(4.5, 3.2, -h + off),
            turn(0.0),
            3.0,
            2.0,
        ),
        (
            "painting-3",
            Vec3::new(h - off, 3.2, -3.5),
            turn(-90.0),
            2.6,
            1.8,
        ),
        (
            "painting-4",
            Vec3::new(h - off, 3.2, 3.5),
            turn(-90.0),
            2.6,
            1.8,
        ),
        (
            "painting-5",
            Vec3::new(-4.5, 3.2, h - off),
            turn(180.0),
            3.0,
            2.0,
        ),
        (
            "painting-6",
            Vec3::new(4.5, 3.2, h - off),
            turn(180.0),
            3.0,
            2.0,
        ),
        (
            "mirror",
            Vec3::new(-h + off, 3.6, 0.0),
            turn(90.0),
            6.0,
            3.6,
        ),
    ];
    for (i, (name, at, rot, w, hgt)) in hangs.into_iter().enumerate() {
        let canvas = m.canvases.get(i).copied().unwrap_or(m.mirror);
        let mut mesh = framed(w, hgt, canvas, m.gold);
        mesh.name = Some(name.to_string());
        let mesh = b.add_mesh(mesh);
        add_root(b, node(name, mesh, at, rot));
    }

    // Pedestals with a glass sphere, a chrome sphere and a bronze torus.
    let mut block = Part::default();
    block.cuboid(Vec3::new(-0.4, 0.0, -0.4), Vec3::new(0.4, 1.0, 0.4));
    let pedestal = b.add_mesh(MeshDesc {
        name: Some("pedestal".into()),
        primitives: vec![block.primitive(m.wood)],
        weights: Vec::new(),
    });
    let stands = [
        Vec3::new(-3.5, 0.0, 4.0),
        Vec3::new(4.2, 0.0, 2.5),
        Vec3::new(-4.0, 0.0, -3.5),
    ];
    for (i, at) in stands.iter().enumerate() {
        add_root(
            b,
            node(&format!("pedestal-{i}"), pedestal, *at, Quat::IDENTITY),
        );
    }
    for (name, mat, at) in [
        ("glass-sphere", m.glass, stands[0]),
        ("chrome-sphere", m.chrome, stands[1]),
    ] {
        let mesh = b.add_mesh(MeshDesc {
            name: Some(name.into()),
            primitives: vec![sphere(0.7, plan.sphere).primitive(mat)],
            weights: Vec::new(),
        });
        add_root(b, node(name, mesh, at + Vec3::Y * 1.7, Quat::IDENTITY));
    }
    let ring = b.add_mesh(MeshDesc {
        name: Some("torus".into()),
        primitives: vec![torus(plan.torus).primitive(m.bronze)],
        weights: Vec::new(),
    });
    let stand_up = Quat::from_rotation_y(0.7) * Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
    add_root(b, node("torus", ring, stands[2] + Vec3::Y * 1.75, stand_up));

    // Benches: a seat on two legs, one mesh, two nodes.
    let mut bench = Part::default();
    bench.cuboid(Vec3::new(-1.2, 0.42, -0.3), Vec3::new(1.2, 0.5, 0.3));
    bench.cuboid(Vec3::new(-1.0, 0.0, -0.25), Vec3::new(-0.9, 0.42, 0.25));
    bench.cuboid(Vec3::new(0.9, 0.0, -0.25), Vec3::new(1.0, 0.42, 0.25));
    let bench = b.add_mesh(MeshDesc {
        name: Some("bench".into()),
        primitives: vec![bench.primitive(m.wood)],
        weights: Vec::new(),
    });
    add_root(
        b,
        node("bench-0", bench, Vec3::new(0.0, 0.0, -7.2), Quat::IDENTITY),
    );
    add_root(
        b,
        node("bench-1", bench, Vec3::new(7.6, 0.0, 0.0), turn(90.0)),
    );
}

// ------------------------------------------------------------------------------ motion

/// A shape the triangles gather into, centred on [`CENTRE`].
#[derive(Clone, Copy, Debug)]
enum Shape {
    Sphere,
    Torus,
    Cube,
    Helix,
}

/// Where the triangles are at one key.
#[derive(Clone, Copy, Debug)]
enum Formation {
    /// Uniformly in the air of the room, random orientations.
    Scatter,
    /// Flying outwards from the previous key's positions.
    Explode,
    /// Gathered on a shape turned by an angle about Y; a new random assignment of
    /// triangles to places on the shape when `fresh`, else the previous key's (the shape
    /// is held while it turns).
    Gather {
        shape: Shape,
        turn: f32,
        fresh: bool,
    },
}

const fn gather(shape: Shape, turn: f32, fresh: bool) -> Formation {
    Formation::Gather { shape, turn, fresh }
}

/// One formation per key, [`MUSEUM_KEYS`] of them. The second key of each shape holds it
/// while it turns.
const CHOREOGRAPHY: [Formation; MUSEUM_KEYS] = [
    Formation::Scatter,
    gather(Shape::Sphere, 0.0, true),
    gather(Shape::Sphere, 0.9, false),
    Formation::Explode,
    gather(Shape::Torus, 0.0, true),
    gather(Shape::Torus, 1.2, false),
    Formation::Explode,
    gather(Shape::Cube, 0.0, true),
    gather(Shape::Cube, 0.8, false),
    Formation::Explode,
    gather(Shape::Helix, 0.0, true),
    gather(Shape::Helix, 1.6, false),
    Formation::Scatter,
];

/// The air the triangle centres keep to: walls, floor and ceiling stay clear, and the
/// last 2 m before the front wall, where the camera stands.
const AIR_LO: Vec3 = Vec3::new(-9.0, 0.8, -9.0);
const AIR_HI: Vec3 = Vec3::new(9.0, 7.2, 7.0);
/// The shapes are sized to about this area, so one triangle size covers them all.
const SHAPE_AREA: f32 = 60.0;

/// Fractional part of `0.5 + k a`, in f64 so that a million slots still spread evenly.
fn weyl(k: usize, a: f64) -> f32 {
    (0.5 + k as f64 * a).fract() as f32
}
const GOLDEN: f64 = 0.618_033_988_749_894_8;

/// The `j`-th of `n` places, evenly over the shape: (position, outward normal).
fn slot(shape: Shape, turn: f32, j: usize, n: usize) -> (Vec3, Vec3) {
    use std::f32::consts::TAU;
    let jf = j as f32;
    match shape {
        Shape::Sphere => {
            // Fibonacci lattice, radius 2.2 (area 61).
            let yy = 1.0 - 2.0 * (jf + 0.5) / n as f32;
            let r = (1.0 - yy * yy).max(0.0).sqrt();
            let (s, c) = (TAU * weyl(j, GOLDEN) + turn).sin_cos();
            let d = Vec3::new(r * c, yy, r * s);
            (CENTRE + d * 2.2, d)
        }
        Shape::Torus => {
            // Ring 2.0, tube 0.7 (area 55), tilted towards the camera.
            let (st, ct) = (TAU * (jf + 0.5) / n as f32 + turn).sin_cos();
            let (sp, cp) = (TAU * weyl(j, GOLDEN)).sin_cos();
            let nrm = Vec3::new(cp * ct, sp, cp * st);
            let p = Vec3::new(2.0 * ct, 0.0, 2.0 * st) + nrm * 0.7;
            let tilt = Quat::from_rotation_x(0.9);
            (CENTRE + tilt * p, tilt * nrm)
        }
        Shape::Cube => {
            // Half side 1.6 (area 61), tipped over, turned about Y.
            let (face, k) = (j % 6, j / 6);
            let axes = [Vec3::X, Vec3::Y, Vec3::Z];
            let a = axes[face % 3];
            let sign = if face < 3 { 1.0 } else { -1.0 };
            let (u, v) = (axes[(face + 1) % 3], axes[(face + 2) % 3]);
            // The R2 sequence (Roberts 2018).
            let su = 2.0 * weyl(k, 0.754_877_666_246_692_7) - 1.0;
            let sv = 2.0 * weyl(k, 0.569_840_290_998_053_3) - 1.0;
            let p = (a * sign + u * su + v * sv) * 1.6;
            let rot = Quat::from_rotation_y(turn)
                * Quat::from_rotation_x(0.6)
                * Quat::from_rotation_z(0.5);
            (CENTRE + rot * p, rot * (a * sign))
        }
        Shape::Helix => {
            // Two ribbons 0.6 wide, radius 1.8, two turns over 5.2 (area about 55).
            let strand = (j % 2) as f32;
            let s = ((j / 2) as f32 + 0.5) / n.div_ceil(2) as f32;
            let th = TAU * 2.0 * s + strand * std::f32::consts::PI + turn;
            let (st, ct) = th.sin_cos();
            let radial = Vec3::new(ct, 0.0, st);
            let along = Vec3::new(-st * 1.8 * TAU * 2.0, 5.2, ct * 1.8 * TAU * 2.0).normalize();
            let across = radial.cross(along);
            let w = 0.6 * (weyl(j / 2, GOLDEN) - 0.5);
            let p = CENTRE + Vec3::new(0.0, 5.2 * s - 2.6, 0.0) + radial * 1.8 + across * w;
            (p, radial)
        }
    }
}

/// A right-handed frame in the plane normal to `n`, turned by `spin` about it.
fn plane_frame(n: Vec3, spin: f32) -> (Vec3, Vec3) {
    let a = if n.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
    let t0 = n.cross(a).normalize();
    let b0 = n.cross(t0);
    let (s, c) = spin.sin_cos();
    let t = t0 * c + b0 * s;
    (t, n.cross(t))
}

/// Fisher–Yates: `out[i]` is the slot of triangle `i`.
fn permutation(rng: &mut Rng, n: usize) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        p.swap(i, rng.below(i + 1));
    }
    p
}

/// Vertex positions of every triangle at every key: `keys[k][3 i + c]`.
fn dynamic_keys(p: &MuseumParams) -> Vec<Vec<Vec3>> {
    let n = p.dynamic_tris;
    let mut rng = Rng::new(p.seed);
    let size = (1.4 * (SHAPE_AREA / n as f32).sqrt()).clamp(0.02, 0.6);
    // Each triangle keeps its own shape: three corners around its centre.
    let shapes: Vec<[Vec2; 3]> = (0..n)
        .map(|_| {
            let turn = rng.range(0.0, std::f32::consts::TAU);
            std::array::from_fn(|c| {
                let a = turn + c as f32 * std::f32::consts::TAU / 3.0 + rng.range(-0.35, 0.35);
                Vec2::from_angle(a) * size * rng.range(0.75, 1.25)
            })
        })
        .collect();
    let spins: Vec<f32> = (0..n)
        .map(|_| rng.range(0.0, std::f32::consts::TAU))
        .collect();

    let mut centres = vec![CENTRE; n];
    let mut keys = Vec::with_capacity(MUSEUM_KEYS);
    let mut slots: Vec<usize> = Vec::new();
    for f in CHOREOGRAPHY {
        let mut frames = Vec::with_capacity(n);
        match f {
            Formation::Scatter => {
                for c in centres.iter_mut() {
                    *c = rng.in_box(AIR_LO, AIR_HI);
                    frames.push(plane_frame(
                        rng.unit(),
                        rng.range(0.0, std::f32::consts::TAU),
                    ));
                }
            }
            Formation::Explode => {
                for c in centres.iter_mut() {
                    let out = (*c - CENTRE + rng.unit() * 0.7).normalize_or(Vec3::Y);
                    *c = (*c + out * rng.range(2.5, 6.0)).clamp(AIR_LO, AIR_HI);
                    frames.push(plane_frame(
                        rng.unit(),
                        rng.range(0.0, std::f32::consts::TAU),
                    ));
                }
            }
            Formation::Gather { shape, turn, fresh } => {
                if fresh || slots.len() != n {
                    slots = permutation(&mut rng, n);
                }
                for (i, c) in centres.iter_mut().enumerate() {
                    let (pos, nrm) = slot(shape, turn, slots[i], n);
                    *c = pos;
                    frames.push(plane_frame(nrm, spins[i] + turn));
                }
            }
        }
        let key: Vec<Vec3> = centres
            .iter()
            .zip(&frames)
            .zip(&shapes)
            .flat_map(|((&c, &(t, b)), shape)| shape.map(|l| c + t * l.x + b * l.y))
            .collect();
        keys.push(key);
    }
    keys
}

fn build_dynamic(b: &mut GltfBuilder, m: &Materials, p: &MuseumParams) {
    let keys = dynamic_keys(p);
    let n = p.dynamic_tris;
    // Four primitives (paint chips of four colours), contiguous runs of triangles.
    let parts = m.chips.len().min(n);
    let mut primitives = Vec::with_capacity(parts);
    for (c, &material) in m.chips.iter().take(parts).enumerate() {
        let (lo, hi) = (3 * (c * n / parts), 3 * ((c + 1) * n / parts));
        let base = &keys[0][lo..hi];
        let targets = keys
            .iter()
            .map(|k| k[lo..hi].iter().zip(base).map(|(a, o)| *a - *o).collect())
            .collect();
        primitives.push(PrimitiveDesc {
            positions: base.to_vec(),
            material: Some(material),
            morph_targets: targets,
            ..PrimitiveDesc::default()
        });
    }
    let mesh = b.add_mesh(MeshDesc {
        name: Some("animart".into()),
        primitives,
        weights: vec![0.0; MUSEUM_KEYS],
    });
    let node = add_root(b, node("animart", mesh, Vec3::ZERO, Quat::IDENTITY));
    // One-hot weights: at key k, target k has weight 1.
    let values = (0..MUSEUM_KEYS * MUSEUM_KEYS)
        .map(|i| {
            if i / MUSEUM_KEYS == i % MUSEUM_KEYS {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    b.add_animation(AnimationDesc {
        name: Some("animart".into()),
        channels: vec![ChannelDesc {
            node,
            property: Property::Weights,
            interpolation: Interpolation::Linear,
            times: p.key_times(),
            values,
        }],
    });
}

/// Rotation that turns a node's `-Z` towards `dir` with `+Y` up.
fn look_along(dir: Vec3) -> Quat {
    let f = dir.normalize();
    let r = f.cross(Vec3::Y).normalize();
    let u = r.cross(f);
    Quat::from_mat3(&glam::Mat3::from_cols(r, u, -f)).normalize()
}

fn build_camera_and_lights(b: &mut GltfBuilder) {
    let eye = Vec3::new(3.5, 4.0, 9.2);
    let target = Vec3::new(0.0, 3.4, 0.0);
    let camera = b.add_camera(CameraDesc {
        name: Some("visitor".into()),
        yfov: 1.0,
        // None: the image's own aspect, as the harness assumes at every size.
        aspect: None,
        znear: 0.05,
        zfar: Some(100.0),
    });
    add_root(
        b,
        NodeDesc {
            name: Some("camera".into()),
            camera: Some(camera),
            translation: eye,
            rotation: look_along(target - eye),
            ..NodeDesc::default()
        },
    );
    let lamp = b.add_light(LightDef {
        name: Some("lamp".into()),
        kind: LightKind::Point,
        color: Vec3::new(1.0, 0.95, 0.85),
        intensity: 200.0,
        range: None,
    });
    let spot = b.add_light(LightDef {
        name: Some("spot".into()),
        kind: LightKind::Spot {
            inner_cone_angle: 0.25,
            outer_cone_angle: 0.45,
        },
        color: Vec3::new(0.85, 0.9, 1.0),
        intensity: 600.0,
        range: None,
    });
    let lamp_at = Vec3::new(0.0, 7.2, 2.0);
    let spot_at = Vec3::new(-7.5, 7.0, 7.5);
    // The spot is the lamp's child (see the module notes): its translation is relative.
    let spot_node = b.add_node(NodeDesc {
        name: Some("spot".into()),
        light: Some(spot),
        translation: spot_at - lamp_at,
        rotation: look_along(CENTRE - spot_at),
        ..NodeDesc::default()
    });
    add_root(
        b,
        NodeDesc {
            name: Some("lamp".into()),
            light: Some(lamp),
            translation: lamp_at,
            children: vec![spot_node],
            ..NodeDesc::default()
        },
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_spends_the_budget_exactly() {
        for s in [
            MIN_STATIC_TRIS,
            MIN_STATIC_TRIS + 1,
            2_000,
            10_284,
            10_285,
            123_457,
            1_000_000,
        ] {
            let p = Plan::for_budget(s);
            let total = FIXED_TRIS
                + shell_tris(p.shell)
                + 4 * pillar_tris(p.pillar)
                + 2 * sphere_tris(p.sphere)
                + torus_tris(p.torus)
                + p.baseboard;
            assert_eq!(total, s, "{p:?}");
            assert!(p.baseboard >= BASEBOARD_MIN, "{p:?}");
        }
        let p = Plan::for_budget(10_284);
        assert!(p.baseboard < 200, "{p:?}");
    }

    #[test]
    fn parts_have_the_counts_the_plan_assumes() {
        assert_eq!(sphere(1.0, 7).tris(), sphere_tris(7));
        assert_eq!(torus(10).tris(), torus_tris(10));
        assert_eq!(torus(10).positions.len(), 10 * torus_tube(10));
        assert_eq!(pillar(9).0.tris(), pillar_tris(9));
        assert_eq!(pillar(9).1.tris(), 24);
        let mut band = Part::default();
        band.band(Vec3::ZERO, Vec3::X, Vec3::Y, 3, true);
        assert_eq!(band.tris(), 7);
    }

    #[test]
    fn closed_parts_face_outwards() {
        // Every triangle's geometric normal agrees with the outward direction.
        let check = |part: &Part, centre_of: &dyn Fn(Vec3) -> Vec3| {
            for t in part.indices.chunks_exact(3) {
                let [a, b, c] = [0, 1, 2].map(|k| part.positions[t[k] as usize]);
                let n = (b - a).cross(c - a);
                let mid = (a + b + c) / 3.0;
                assert!(n.dot(mid - centre_of(mid)) > 0.0, "{a} {b} {c}");
            }
        };
        check(&sphere(1.0, 6), &|_| Vec3::ZERO);
        check(&torus(12), &|p| Vec3::new(p.x, 0.0, p.z).normalize() * 0.55);
        check(&pillar(8).0, &|p| Vec3::new(0.0, p.y, 0.0));
        let mut cube = Part::default();
        cube.cuboid(Vec3::ZERO, Vec3::ONE);
        check(&cube, &|_| Vec3::splat(0.5));
    }
}
