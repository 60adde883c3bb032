//! The built-in museum: the demo scene of `subfield demo` and `subfield generate museum`,
//! made in code as a [`Scene`] (and written as glTF), in the manner of BART's *museum*
//! (Lext, Assarsson, Möller).
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

mod geometry;
mod layout;
mod materials;
mod motion;
mod room;

use std::path::Path;

use glam::{Quat, Vec2, Vec3, Vec4};

use super::synth::Rng;
use crate::import::ImportError;
use crate::scene::{
    Animation, CameraDef, Channel, Falloff, Interpolation, LightDef, LightKind, Material, Mesh,
    MorphTarget, Node, NodeTransform, Primitive, Projection, Property, Scene, Trs,
};
use geometry::*;
use layout::*;
use materials::*;
use motion::*;
use room::*;

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
#[non_exhaustive]
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

/// The museum as a [`Scene`] (write it with `import::write_gltf` / `import::to_glb`).
pub fn museum(p: &MuseumParams) -> Result<Scene, MuseumError> {
    p.validate()?;
    let mut b = Scene {
        fps: Some(p.fps),
        ..Scene::default()
    };
    let m = Materials::add(&mut b);
    let plan = Plan::for_budget(p.static_tris);
    build_static(&mut b, &m, &plan);
    build_dynamic(&mut b, &m, p);
    build_camera_and_lights(&mut b);
    b.link_parents();
    Ok(b)
}

/// The museum as GLB bytes.
pub fn museum_glb(p: &MuseumParams) -> Result<Vec<u8>, MuseumError> {
    Ok(crate::import::to_glb(&museum(p)?)?)
}

/// Writes the museum to `path` atomically (`.gltf`: JSON with an embedded buffer; any
/// other extension: GLB).
pub fn write_museum(p: &MuseumParams, path: &Path) -> Result<(), MuseumError> {
    Ok(crate::import::write_gltf(&museum(p)?, path)?)
}

/// Rotation that turns a node's `-Z` towards `dir` with `+Y` up.
fn look_along(dir: Vec3) -> Quat {
    let f = dir.normalize();
    let r = f.cross(Vec3::Y).normalize();
    let u = r.cross(f);
    Quat::from_mat3(&glam::Mat3::from_cols(r, u, -f)).normalize()
}

fn build_camera_and_lights(b: &mut Scene) {
    let eye = Vec3::new(3.5, 4.0, 9.2);
    let target = Vec3::new(0.0, 3.4, 0.0);
    b.cameras.push(CameraDef {
        name: Some("visitor".into()),
        projection: Projection::Perspective {
            yfov: 1.0,
            // None: the image's own aspect, as the harness assumes at every size.
            aspect: None,
            znear: 0.05,
            zfar: Some(100.0),
        },
    });
    let camera = b.cameras.len() - 1;
    add_root(
        b,
        Node {
            name: Some("camera".into()),
            camera: Some(camera),
            transform: placed(eye, look_along(target - eye)),
            ..Node::default()
        },
    );
    // Intensities in the model's W/sr; the written file says 683 times as many candela.
    b.lights.push(LightDef {
        name: Some("lamp".into()),
        kind: LightKind::Point,
        color: Vec3::new(1.0, 0.95, 0.85),
        intensity: 200.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    b.lights.push(LightDef {
        name: Some("spot".into()),
        kind: LightKind::Spot {
            inner_cone_angle: 0.25,
            outer_cone_angle: 0.45,
        },
        color: Vec3::new(0.85, 0.9, 1.0),
        intensity: 600.0,
        range: None,
        falloff: Falloff::InverseSquare,
    });
    let (lamp, spot) = (b.lights.len() - 2, b.lights.len() - 1);
    let lamp_at = Vec3::new(0.0, 7.2, 2.0);
    let spot_at = Vec3::new(-7.5, 7.0, 7.5);
    // The spot is the lamp's child (see the module notes): its translation is relative.
    b.nodes.push(Node {
        name: Some("spot".into()),
        light: Some(spot),
        transform: placed(spot_at - lamp_at, look_along(CENTRE - spot_at)),
        ..Node::default()
    });
    let spot_node = b.nodes.len() - 1;
    add_root(
        b,
        Node {
            name: Some("lamp".into()),
            light: Some(lamp),
            transform: placed(lamp_at, Quat::IDENTITY),
            children: vec![spot_node],
            ..Node::default()
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
