//! Direct light: a shadow ray towards each punctual light that lights a surface, and
//! samples of the emissive triangles (area lights), each carrying what it adds when
//! unblocked.

use glam::{Vec3, Vec3A};

use super::block::{BlockOut, Item};
use super::bsdf::Lobes;
use super::surface::Surface;
use super::{ShadeContext, MIN_WEIGHT};
use crate::geometry::Ray;
use crate::render::sampling::{stratified, Purpose};
use crate::scene::{Falloff, LightKind};

/// A light ready for shading.
#[derive(Clone, Copy, Debug)]
pub(in crate::render) struct PreLight {
    pub(in crate::render) kind: LightKind,
    /// Colour × intensity.
    pub(in crate::render) power: Vec3,
    pub(in crate::render) position: Vec3,
    /// Unit direction the light shines along.
    pub(in crate::render) direction: Vec3,
    pub(in crate::render) range: Option<f32>,
    pub(in crate::render) falloff: Falloff,
}

impl PreLight {
    /// The bits of every field, for an exact comparison.
    pub(in crate::render) fn bits(&self) -> [u32; 15] {
        let (kind, a, b) = match self.kind {
            LightKind::Directional => (0, 0, 0),
            LightKind::Point => (1, 0, 0),
            LightKind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => (2, inner_cone_angle.to_bits(), outer_cone_angle.to_bits()),
        };
        let v = |v: Vec3| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
        let [px, py, pz] = v(self.power);
        let [ox, oy, oz] = v(self.position);
        let [dx, dy, dz] = v(self.direction);
        [
            kind,
            a,
            b,
            px,
            py,
            pz,
            ox,
            oy,
            oz,
            dx,
            dy,
            dz,
            self.range.map_or(u32::MAX, f32::to_bits),
            u32::from(self.range.is_some()),
            match self.falloff {
                Falloff::None => 0,
                Falloff::InverseSquare => 1,
            },
        ]
    }
}

/// A spot light's cone as its falloff reads it: the cosine of the outer angle and the
/// scale that takes `cos − cos_outer` to 1 at the inner angle; `None` for another kind.
#[inline]
pub(super) fn cone(l: &PreLight) -> Option<(f32, f32)> {
    let LightKind::Spot {
        inner_cone_angle,
        outer_cone_angle,
    } = l.kind
    else {
        return None;
    };
    let (ci, co) = (inner_cone_angle.cos(), outer_cone_angle.cos());
    Some((co, 1.0 / (ci - co).max(1e-3)))
}

/// The direction towards light `l` from `origin`, its distance (infinite for a
/// directional light) and the irradiance it brings there (range and cone applied);
/// `None` at the light itself or where the numbers overflow.
#[inline]
pub(super) fn light_at(l: &PreLight, origin: Vec3A) -> Option<(Vec3A, f32, Vec3A)> {
    Some(match l.kind {
        LightKind::Directional => (-Vec3A::from(l.direction), f32::INFINITY, l.power.into()),
        LightKind::Point | LightKind::Spot { .. } => {
            let d = Vec3A::from(l.position) - origin;
            let d2 = d.length_squared();
            if d2 <= 0.0 || !d2.is_finite() {
                return None;
            }
            let dist = d2.sqrt();
            let mut att = match l.falloff {
                Falloff::None => 1.0,
                Falloff::InverseSquare => 1.0 / d2,
            };
            if let Some(r) = l.range {
                att *= (1.0 - (dist / r).powi(4)).clamp(0.0, 1.0).powi(2);
            }
            let to = d / dist;
            if let Some((co, scale)) = cone(l) {
                let cd = Vec3A::from(l.direction).dot(-to);
                att *= ((cd - co) * scale).clamp(0.0, 1.0).powi(2);
            }
            (to, dist, Vec3A::from(l.power) * att)
        }
    })
}

impl ShadeContext<'_> {
    /// A shadow ray towards each light that lights `s` (from `origin`, just off the
    /// surface), carrying what the light would add: diffuse and a capped Blinn-Phong
    /// glint.
    pub(super) fn direct_light(
        &self,
        s: &Surface,
        lobes: &Lobes,
        weight: Vec3A,
        origin: Vec3A,
        item: &Item,
        out: &mut BlockOut,
    ) {
        for (li, l) in self.lights.iter().enumerate() {
            let Some((to_light, dist, irradiance)) = light_at(l, origin) else {
                continue;
            };
            let cos_i = s.ns.dot(to_light);
            if cos_i <= 0.0 || s.ng.dot(to_light) <= 0.0 {
                continue;
            }
            let brdf = Self::brdf(lobes, s, to_light, true);
            let c = weight * brdf * irradiance * cos_i;
            if c.max_element() <= MIN_WEIGHT * 1e-2 || !c.is_finite() {
                continue;
            }
            let shadow = if dist.is_finite() {
                Ray::segment(origin.into(), to_light.into(), 0.0, dist * (1.0 - 1e-4))
            } else {
                Ray::new(origin.into(), to_light.into())
            };
            out.shadow(shadow, li, item.sample, c.into(), || {
                let e = weight * irradiance * cos_i;
                Self::split_light(lobes, s, to_light, true, e, item.path)
            });
        }
    }

    /// `n` shadow rays to points on the emissive triangles (stratified over the
    /// triangle, each triangle drawn by power), each carrying `1/n` of its estimate.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn area_light(
        &self,
        s: &Surface,
        lobes: &Lobes,
        weight: Vec3A,
        origin: Vec3A,
        item: &Item,
        n: u32,
        spp: u32,
        out: &mut BlockOut,
    ) {
        // One batch for every area-light shadow ray, after the punctual lights'.
        let batch = self.lights.len();
        // At a camera ray's hit the pixel's `spp · n` samples share one stratification
        // (jittered: cell `j·spp + k` for light sample `j` of pixel sample `k`), and
        // the emitter choice is stratified too, over the cells in a scrambled order, so
        // the pick and the point do not go together.
        let (k, cells) = if item.depth == 0 {
            (item.sample % spp.max(1), n * spp.max(1))
        } else {
            (0, n)
        };
        for j in 0..n {
            let cell = j * (cells / n) + k;
            let rp = item.seed.get(Purpose::AreaLight, 2 * j);
            let scrambled = if cells % 7919 == 0 {
                cell as f32
            } else {
                (u64::from(cell) * 7919 % u64::from(cells)) as f32
            };
            let pick = ((scrambled + rp.x) / cells as f32).min(0.999_999_9);
            let r = stratified(cell, cells, item.seed.get(Purpose::AreaLight, 2 * j + 1));
            let Some(lp) = self.area.sample(pick, r) else {
                continue;
            };
            if lp.tri == s.tri {
                continue;
            }
            let d = Vec3A::from(lp.point) - origin;
            let d2 = d.length_squared();
            if !(d2 > 0.0 && d2.is_finite()) {
                continue;
            }
            let dist = d2.sqrt();
            let to = d / dist;
            let cos_i = s.ns.dot(to);
            if cos_i <= 0.0 || s.ng.dot(to) <= 0.0 {
                continue;
            }
            let mut cos_l = -Vec3A::from(lp.normal).dot(to);
            if lp.two_sided {
                cos_l = cos_l.abs();
            }
            if cos_l <= 0.0 {
                continue;
            }
            let Some(m) = self.material(lp.material) else {
                continue;
            };
            let le = self.emission(m, self.uv_at(lp.tri, lp.bary), f32::NEG_INFINITY);
            let brdf = Self::brdf(lobes, s, to, !lobes.reflects);
            let c = weight * brdf * le * (cos_i * cos_l / (d2 * lp.pdf_area * n as f32));
            if c.max_element() <= MIN_WEIGHT * 1e-2 || !c.is_finite() {
                continue;
            }
            out.shadow(
                Ray::segment(origin.into(), to.into(), 0.0, dist * (1.0 - 1e-3)),
                batch,
                item.sample,
                c.into(),
                || {
                    let e = weight * le * (cos_i * cos_l / (d2 * lp.pdf_area * n as f32));
                    Self::split_light(lobes, s, to, !lobes.reflects, e, item.path)
                },
            );
        }
    }
}
