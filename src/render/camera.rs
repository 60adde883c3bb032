//! The camera model of DESIGN.md §4: a pinhole looking down its local `-Z`, `+Y` up;
//! pixel `(x, y)` (y downwards) maps to the camera-space direction
//! `((2(x+0.5)/W − 1)·a·t, (1 − 2(y+0.5)/H)·t, −1)`, `t = tan(yfov/2)`, `a` the camera's
//! aspect ratio or else `W/H`. Primary directions are not normalised, so a ray's `t`
//! times the direction's length is the distance.

use glam::{Mat3, Quat, Vec3};

use super::options::LookAt;
use super::RenderError;
use crate::geometry::Ray;
use crate::scene::{Camera, ClipSelection, Projection, Scene};

/// A posed camera, ready to make primary rays for a `width × height` image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraModel {
    /// Camera position (world).
    pub origin: Vec3,
    /// World from camera rotation (columns: camera +X, +Y, +Z in world space).
    pub rotation: Mat3,
    /// `tan(yfov / 2)` for a perspective camera.
    pub tan_half: f32,
    /// Width over height used in the mapping.
    pub aspect: f32,
    /// Half width and half height of the view for an orthographic camera (glTF
    /// `xmag`/`ymag`); `None` for a perspective one.
    pub ortho: Option<(f32, f32)>,
    pub width: u32,
    pub height: u32,
}

impl CameraModel {
    /// The model of a scene camera.
    pub fn from_scene(cam: &Camera, width: u32, height: u32) -> CameraModel {
        let image_aspect = width as f32 / height as f32;
        let rotation = Mat3::from_quat(cam.rotation);
        let (tan_half, aspect, ortho) = match cam.projection {
            Projection::Perspective { yfov, aspect, .. } => (
                (yfov * 0.5).tan(),
                aspect
                    .filter(|a| a.is_finite() && *a > 0.0)
                    .unwrap_or(image_aspect),
                None,
            ),
            Projection::Orthographic { xmag, ymag, .. } => {
                (1.0, image_aspect, Some((xmag.abs(), ymag.abs())))
            }
        };
        CameraModel {
            origin: cam.position,
            rotation,
            tan_half,
            aspect,
            ortho,
            width,
            height,
        }
    }

    /// A camera at `from` looking at `at`.
    pub fn look_at(l: &LookAt, width: u32, height: u32) -> Result<CameraModel, RenderError> {
        let fwd = l.at - l.from;
        if fwd.length_squared() <= 0.0 || !fwd.is_finite() {
            return Err(RenderError::Option(
                "--look-from and --look-at are the same point".into(),
            ));
        }
        if !(l.yfov_deg > 0.0 && l.yfov_deg < 180.0) {
            return Err(RenderError::Option(format!(
                "--yfov {}: must be between 0 and 180 degrees",
                l.yfov_deg
            )));
        }
        let z = -fwd.normalize();
        let x = l.up.cross(z);
        if x.length_squared() <= 1e-12 || !x.is_finite() {
            return Err(RenderError::Option(
                "--up is parallel to the viewing direction (or zero)".into(),
            ));
        }
        let x = x.normalize();
        let y = z.cross(x);
        Ok(CameraModel {
            origin: l.from,
            rotation: Mat3::from_cols(x, y, z),
            tan_half: (l.yfov_deg.to_radians() * 0.5).tan(),
            aspect: width as f32 / height as f32,
            ortho: None,
            width,
            height,
        })
    }

    /// A 45° camera framing the box `lo..hi` from the front (+Z), a little right and
    /// above, so the whole bounding sphere is in view.
    pub fn framing(lo: Vec3, hi: Vec3, width: u32, height: u32) -> CameraModel {
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-3);
        let yfov = 45f32.to_radians();
        let aspect = width as f32 / height as f32;
        let half_x = ((yfov * 0.5).tan() * aspect).atan();
        let half = half_x.min(yfov * 0.5);
        let dist = radius / half.sin() * 1.05;
        let dir = Vec3::new(0.35, 0.3, 1.0).normalize();
        let l = LookAt {
            from: centre + dir * dist,
            at: centre,
            up: Vec3::Y,
            yfov_deg: 45.0,
        };
        // `dir` is never parallel to +Y and `dist > 0`, so this cannot fail.
        Self::look_at(&l, width, height).unwrap_or(CameraModel {
            origin: l.from,
            rotation: Mat3::from_quat(Quat::IDENTITY),
            tan_half: (yfov * 0.5).tan(),
            aspect,
            ortho: None,
            width,
            height,
        })
    }

    /// The ray through the point `(px, py)` of the image plane in pixel units (the
    /// centre of pixel `(x, y)` is `(x + 0.5, y + 0.5)`).
    #[inline]
    pub fn ray(&self, px: f32, py: f32) -> Ray {
        let sx = 2.0 * px / self.width as f32 - 1.0;
        let sy = 1.0 - 2.0 * py / self.height as f32;
        match self.ortho {
            None => {
                let d = Vec3::new(sx * self.aspect * self.tan_half, sy * self.tan_half, -1.0);
                Ray::new(self.origin, self.rotation * d)
            }
            Some((xmag, ymag)) => {
                let o = self.rotation * Vec3::new(sx * xmag, sy * ymag, 0.0);
                Ray::new(self.origin + o, self.rotation * Vec3::NEG_Z)
            }
        }
    }
}

/// Bounds of the whole animation of `sel` (sampled at 17 times over its duration), so a
/// framing camera does not depend on which frames or shard a run renders.
pub fn animation_bounds(scene: &Scene, sel: ClipSelection) -> Option<(Vec3, Vec3)> {
    let d = scene.duration(sel);
    let steps = if d > 0.0 { 16 } else { 0 };
    (0..=steps)
        .filter_map(|k| {
            let t = if steps == 0 {
                0.0
            } else {
                d * k as f32 / steps as f32
            };
            scene.bounds_at(sel, t)
        })
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_down_minus_z_and_corners_follow_the_contract() {
        let l = LookAt {
            from: Vec3::ZERO,
            at: Vec3::NEG_Z,
            up: Vec3::Y,
            yfov_deg: 90.0,
        };
        let c = CameraModel::look_at(&l, 4, 2).unwrap();
        let r = c.ray(2.0, 1.0);
        assert!(r.dir.abs_diff_eq(Vec3::NEG_Z, 1e-6));
        // Pixel (0, 0): ((2*0.5/4 - 1)*2*1, (1 - 2*0.5/2)*1, -1) = (-1.5, 0.5, -1).
        let r = c.ray(0.5, 0.5);
        assert!(
            r.dir.abs_diff_eq(Vec3::new(-1.5, 0.5, -1.0), 1e-6),
            "{}",
            r.dir
        );
        let bad = LookAt {
            up: Vec3::NEG_Z,
            ..l
        };
        assert!(CameraModel::look_at(&bad, 4, 2).is_err());
        assert!(CameraModel::look_at(&LookAt { at: l.from, ..l }, 4, 2).is_err());
    }

    #[test]
    fn framing_sees_the_box() {
        let c = CameraModel::framing(Vec3::splat(-1.0), Vec3::splat(1.0), 64, 48);
        let r = c.ray(32.0, 24.0);
        // The centre ray passes through the box centre.
        let t = -r.origin.dot(r.dir) / r.dir.length_squared();
        assert!(r.at(t).length() < 1e-3);
    }
}
