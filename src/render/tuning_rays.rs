//! The sample rays a bake is tuned on (`subfield bake --quality high`,
//! [`tune`](crate::psf::tune)): a render of the scene in small. Primary rays through a
//! grid of each camera's image (every camera the scene places, else the framing camera
//! a render would use) at the start, middle and end of the animation; from each primary
//! ray's hit on the static triangles, a shadow ray towards every light (the scene's
//! lights at that time, else the default light a render adds) and the mirror ray.
//!
//! The sample is split as a render traces it: each view's primary rays one batch, the
//! shadow rays towards each light one batch, the view's mirror rays one batch, each
//! planned as the render plans its batches (`Psf::point_grids_take`, the planner of
//! the batch queries). The rays that point grids take are only counted
//! ([`SampleRays::point`]); the others, which the render traces through the parallel
//! subfields, are what the trials trace. Each batch is planned once before it is
//! classified, as a render's earlier frame would have planned it: a camera or light
//! that stays put has its grid kept from the second frame on, and the sample is
//! classified as those later frames are (for a point that moves, this may credit
//! point grids with rays a render's batch of that size would not give them; the
//! tuner then weighs the parallel subfields' share as smaller, the cautious side).
//!
//! Everything here is a function of the scene and the static triangles, and the batches
//! are planned one after another in a fixed order, so the sample, and the choice tuning
//! makes on it, is the same on every machine and thread count.

use glam::Vec3;

use super::camera::{animation_bounds, CameraModel};
use crate::geometry::{Intersector, Ray};
use crate::psf::{Psf, SampleRays};
use crate::scene::{ClipSelection, LightKind, Scene};

/// Primary rays over all views together (cameras × times): the sample's size.
pub const PRIMARY_RAYS: usize = 1 << 16;
/// Cameras sampled at most (the first ones the scene places).
pub const MAX_CAMERAS: usize = 4;
/// Lights sampled at most (the first ones the scene places).
pub const MAX_LIGHTS: usize = 8;

/// Where a shadow ray goes: along a direction (a directional light), or to a point.
enum Toward {
    Along(Vec3),
    Point(Vec3),
}

/// The sample rays for `scene` whose static part `psf` is (any bake of it: the hits, and
/// the point grids' plans, are the same; its kept point grids are used and replaced as
/// a render's would be).
pub fn tuning_rays(scene: &Scene, psf: &Psf) -> SampleRays {
    let sel = ClipSelection::All;
    let d = scene.duration(sel);
    let times: Vec<f32> = if d > 0.0 {
        vec![0.0, 0.5 * d, d]
    } else {
        vec![0.0]
    };
    let bounds = psf.bounds();
    let extent = (bounds.max - bounds.min).length();
    let eps = 1e-4
        * if extent.is_finite() && extent > 0.0 {
            extent
        } else {
            1.0
        };
    // The views: every placed camera at every time, else the framing camera.
    let mut views: Vec<(f32, Option<usize>)> = Vec::new();
    let placed: Vec<usize> = (0..scene.cameras.len())
        .filter(|i| scene.camera_at(sel, 0.0, Some(&i.to_string())).is_some())
        .take(MAX_CAMERAS)
        .collect();
    for &t in &times {
        if placed.is_empty() {
            views.push((t, None));
        }
        for &c in &placed {
            views.push((t, Some(c)));
        }
    }
    let per_view = PRIMARY_RAYS / views.len().max(1);
    let mut rays = SampleRays::default();
    for (t, cam) in views {
        let posed = cam.and_then(|c| scene.camera_at(sel, t, Some(&c.to_string())));
        let aspect = posed
            .as_ref()
            .and_then(|c| c.aspect())
            .filter(|a| a.is_finite() && *a > 0.0)
            .unwrap_or(4.0 / 3.0)
            .clamp(0.1, 10.0);
        let h = ((per_view as f32 / aspect).sqrt().round() as u32).max(1);
        let w = ((per_view as f32 / h as f32).round() as u32).max(1);
        let model = match &posed {
            Some(c) => CameraModel::from_scene(c, w, h),
            None => {
                let (lo, hi) = animation_bounds(scene, sel).unwrap_or((-Vec3::ONE, Vec3::ONE));
                CameraModel::framing(lo, hi, w, h)
            }
        };
        let lights = scene.lights_at(sel, t);
        // The lights, else the render's default light: directional, set relative to
        // the camera (as `ShadeContext::new` places it).
        let toward: Vec<Toward> = if lights.is_empty() {
            let towards = (model.rotation * Vec3::new(-0.4, 0.6, 0.7)).normalize_or_zero();
            vec![Toward::Along(towards)]
        } else {
            lights
                .iter()
                .take(MAX_LIGHTS)
                .map(|l| match l.kind {
                    LightKind::Directional => Toward::Along(-l.direction),
                    _ => Toward::Point(l.position),
                })
                .collect()
        };
        let primary: Vec<Ray> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| model.ray(x as f32 + 0.5, y as f32 + 0.5))
            .collect();
        let mut hits = vec![None; primary.len()];
        psf.intersect_batch(&primary, &mut hits);
        let mut shadows: Vec<Vec<Ray>> = toward.iter().map(|_| Vec::new()).collect();
        let mut mirrors = Vec::new();
        for (r, hit) in primary.iter().zip(&hits) {
            let Some(hit) = hit else { continue };
            let Some(tri) = psf.triangles().get(hit.tri as usize) else {
                continue;
            };
            let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero();
            if n == Vec3::ZERO {
                continue;
            }
            // The side the ray came from.
            let n = if n.dot(r.dir) > 0.0 { -n } else { n };
            let p = r.origin + r.dir * hit.t;
            let o = p + n * eps;
            for (l, batch) in toward.iter().zip(&mut shadows) {
                let (dir, t_max) = match *l {
                    Toward::Along(d) => (d, f32::INFINITY),
                    // Short of the light itself.
                    Toward::Point(at) => (at - o, 1.0 - 1e-4),
                };
                if dir.dot(n) > 0.0 && dir.is_finite() && dir != Vec3::ZERO {
                    batch.push(Ray {
                        t_max,
                        ..Ray::new(o, dir)
                    });
                }
            }
            let m = r.dir - 2.0 * r.dir.dot(n) * n;
            if m.is_finite() && m != Vec3::ZERO {
                mirrors.push(Ray::new(o, m));
            }
        }
        // In the order a render traces them.
        keep(psf, primary, false, &mut rays);
        for batch in shadows {
            keep(psf, batch, true, &mut rays);
        }
        keep(psf, mirrors, false, &mut rays);
    }
    rays
}

/// `batch` (any-hit rays when `any`) into `rays` as a render traces it: the rays its
/// point grids take counted in `rays.point`, the others kept. Planned once to see its
/// points, then again for the plan it is classified by (see the module docs).
fn keep(psf: &Psf, batch: Vec<Ray>, any: bool, rays: &mut SampleRays) {
    psf.point_grids_take(&batch, any);
    let taken = psf.point_grids_take(&batch, any);
    let into = if any {
        &mut rays.any
    } else {
        &mut rays.closest
    };
    for (r, took) in batch.into_iter().zip(taken) {
        if took {
            rays.point += 1;
        } else {
            into.push(r);
        }
    }
}
