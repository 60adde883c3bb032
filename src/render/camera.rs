//! The camera model of DESIGN.md §4: a pinhole looking down its local `-Z`, `+Y` up;
//! pixel `(x, y)` (y downwards) maps to the camera-space direction
//! `((2(x+0.5)/W − 1)·a·t, (1 − 2(y+0.5)/H)·t, −1)`, `t = tan(yfov/2)`, `a = W/H`:
//! pixels are square, `yfov` is vertical and the horizontal extent follows the image. A
//! camera's own `aspectRatio` only picks the default image size ([`default_size`]); a
//! `--size` of another shape is warned about ([`aspect_warning`]). Orthographic cameras
//! likewise: `ymag` is the half height, the half width is `ymag·W/H`. Primary directions
//! are not normalised, so a ray's `t` times the direction's length is the distance.

use glam::{Mat3, Quat, Vec3};

use super::errors::OptionError;
use super::options::{LookAt, RenderOptions, MAX_SIDE};
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
    /// Width over height used in the mapping: the image's (`W/H`), so pixels are square.
    pub aspect: f32,
    /// Half width and half height of the view for an orthographic camera (glTF `ymag`,
    /// and `ymag·W/H` for square pixels); `None` for a perspective one.
    pub ortho: Option<(f32, f32)>,
    pub width: u32,
    pub height: u32,
}

impl CameraModel {
    /// How many 32-bit words [`bits`](Self::bits) gives.
    pub const BITS: usize = 19;

    /// Every field's bits: two models with the same bits make the same rays, to the bit
    /// (`PartialEq` would take `-0.0` for `0.0`).
    pub fn bits(&self) -> [u32; Self::BITS] {
        let r = self.rotation.to_cols_array();
        let (has, (ox, oy)) = match self.ortho {
            Some(o) => (1, o),
            None => (0, (0.0, 0.0)),
        };
        let mut b = [0u32; Self::BITS];
        let floats = [
            self.origin.x,
            self.origin.y,
            self.origin.z,
            r[0],
            r[1],
            r[2],
            r[3],
            r[4],
            r[5],
            r[6],
            r[7],
            r[8],
            self.tan_half,
            self.aspect,
            ox,
            oy,
        ];
        for (d, f) in b.iter_mut().zip(floats) {
            *d = f.to_bits();
        }
        b[16] = has;
        b[17] = self.width;
        b[18] = self.height;
        b
    }

    /// The model of a scene camera: `yfov` (or `ymag`) vertical, the horizontal extent
    /// from the image, whatever the camera's own aspect ratio.
    pub fn from_scene(cam: &Camera, width: u32, height: u32) -> CameraModel {
        let image_aspect = width as f32 / height as f32;
        let rotation = Mat3::from_quat(cam.rotation);
        let (tan_half, ortho) = match cam.projection {
            Projection::Perspective { yfov, .. } => ((yfov * 0.5).tan(), None),
            Projection::Orthographic { ymag, .. } => {
                let ymag = ymag.abs();
                (1.0, Some((ymag * image_aspect, ymag)))
            }
        };
        let aspect = image_aspect;
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
            return Err(OptionError::LookAtSamePoint.into());
        }
        if !(l.yfov_deg > 0.0 && l.yfov_deg < 180.0) {
            return Err(OptionError::Yfov(l.yfov_deg).into());
        }
        let z = -fwd.normalize();
        let x = l.up.cross(z);
        if x.length_squared() <= 1e-12 || !x.is_finite() {
            return Err(OptionError::UpParallel.into());
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

/// Largest `|EV|` `--exposure` takes (2^64 is far past any radiance worth scaling).
pub const MAX_EXPOSURE: f32 = 64.0;

/// `--exposure EV`: scales the radiance (RGB) of `rgba` by 2^EV, as a camera's exposure
/// does; alpha (coverage) is left alone. EV 0 changes nothing.
pub fn apply_exposure(rgba: &mut [[f32; 4]], ev: f32) {
    if ev == 0.0 {
        return;
    }
    let k = ev.exp2();
    for p in rgba {
        for c in &mut p[..3] {
            *c *= k;
        }
    }
}

/// Width of the default image ([`default_size`]).
pub const DEFAULT_WIDTH: u32 = 640;

/// The aspect ratio (width over height) a camera asks for: a perspective camera's
/// `aspectRatio`, an orthographic one's `xmag / ymag`; `None` when it names none (or a
/// value that is not a positive finite number).
pub fn camera_aspect(projection: &Projection) -> Option<f32> {
    let a = match *projection {
        Projection::Perspective { aspect, .. } => aspect?,
        Projection::Orthographic { xmag, ymag, .. } => xmag.abs() / ymag.abs(),
    };
    (a.is_finite() && a > 0.0).then_some(a)
}

/// The image size for a camera of aspect `aspect`: [`DEFAULT_WIDTH`] wide, the height
/// rounded to the nearest pixel (kept in `1..=MAX_SIDE`); 640x480 without an aspect.
pub fn size_for_aspect(aspect: Option<f32>) -> (u32, u32) {
    match aspect {
        Some(a) => {
            let h = (DEFAULT_WIDTH as f64 / a as f64).round();
            (DEFAULT_WIDTH, h.clamp(1.0, MAX_SIDE as f64) as u32)
        }
        None => (DEFAULT_WIDTH, 480),
    }
}

/// Whether `width × height` is the shape of `aspect`, to the pixel: either side is the
/// other times the aspect, rounded (so [`size_for_aspect`]'s sizes always match).
pub fn size_matches(width: u32, height: u32, aspect: f32) -> bool {
    let (w, h, a) = (width as f64, height as f64, aspect as f64);
    (w / a - h).abs() <= 0.5 || (h * a - w).abs() <= 0.5
}

/// The scene camera `opts` renders through (`--camera`, else the first), when it is a
/// scene camera at all (not `--look-from`, not a framing camera).
fn chosen_camera(scene: &Scene, opts: &RenderOptions) -> Option<Camera> {
    if opts.look_at.is_some() {
        return None;
    }
    let sel = match &opts.animation {
        Some(a) => scene.resolve_clip(a).ok()?,
        None => ClipSelection::All,
    };
    scene.camera_at(sel, 0.0, opts.camera.as_deref())
}

/// The image size when `--size` is not given: 640 wide at the aspect ratio of the camera
/// `opts` chooses (see [`camera_aspect`]), else 640x480.
pub fn default_size(scene: &Scene, opts: &RenderOptions) -> (u32, u32) {
    size_for_aspect(chosen_camera(scene, opts).and_then(|c| camera_aspect(&c.projection)))
}

/// The warning (without `warning: `) when the image's shape is not the chosen camera's
/// aspect ratio: pixels stay square, so the image shows more or less of the scene than
/// the camera's frame, never a stretched one.
pub fn aspect_warning(scene: &Scene, opts: &RenderOptions) -> Option<String> {
    let cam = chosen_camera(scene, opts)?;
    let a = camera_aspect(&cam.projection)?;
    if size_matches(opts.width, opts.height, a) {
        return None;
    }
    let name = cam
        .name
        .clone()
        .or_else(|| scene.nodes.get(cam.node).and_then(|n| n.name.clone()))
        .map_or_else(|| format!("of node {}", cam.node), |n| format!("{n:?}"));
    let (w, h) = size_for_aspect(Some(a));
    Some(format!(
        "--size {}x{} is not the aspect ratio {a:.4} of camera {name}: pixels stay square and \
         the vertical field of view is kept, so the image is {} than the camera's frame \
         (without --size: {w}x{h})",
        opts.width,
        opts.height,
        if (opts.width as f64 / opts.height as f64) > a as f64 {
            "wider"
        } else {
            "narrower"
        },
    ))
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

    fn scene_camera(projection: Projection) -> Camera {
        Camera {
            name: None,
            node: 0,
            world_from_camera: glam::Mat4::IDENTITY,
            position: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            projection,
        }
    }

    #[test]
    fn pixels_are_square_whatever_the_cameras_aspect() {
        let yfov = 90f32.to_radians();
        let wide = Projection::Perspective {
            yfov,
            aspect: Some(16.0 / 9.0),
            znear: 0.1,
            zfar: None,
        };
        // 400x200 (aspect 2, not the camera's 16:9): the right edge of the image is at
        // x = a·t = 2 (square pixels), the top at y = t = 1.
        let c = CameraModel::from_scene(&scene_camera(wide), 400, 200);
        assert!(c
            .ray(400.0, 100.0)
            .dir
            .abs_diff_eq(Vec3::new(2.0, 0.0, -1.0), 1e-5));
        assert!(c
            .ray(200.0, 0.0)
            .dir
            .abs_diff_eq(Vec3::new(0.0, 1.0, -1.0), 1e-5));
        // Orthographic: ymag is the half height, the half width ymag·W/H, not xmag.
        let ortho = Projection::Orthographic {
            xmag: 3.0,
            ymag: 1.5,
            znear: 0.1,
            zfar: 10.0,
        };
        let c = CameraModel::from_scene(&scene_camera(ortho), 100, 100);
        let r = c.ray(100.0, 0.0);
        assert!(
            r.origin.abs_diff_eq(Vec3::new(1.5, 1.5, 0.0), 1e-5),
            "{}",
            r.origin
        );
        assert!(r.dir.abs_diff_eq(Vec3::NEG_Z, 1e-6));
        assert_eq!(camera_aspect(&ortho), Some(2.0));
        assert_eq!(camera_aspect(&wide), Some(16.0 / 9.0));
    }

    #[test]
    fn default_sizes_follow_the_aspect_and_match_it() {
        assert_eq!(size_for_aspect(Some(16.0 / 9.0)), (640, 360));
        assert_eq!(size_for_aspect(Some(1.0)), (640, 640));
        assert_eq!(size_for_aspect(Some(1.5)), (640, 427));
        assert_eq!(size_for_aspect(None), (640, 480));
        assert_eq!(size_for_aspect(Some(1e-4)), (640, MAX_SIDE));
        for a in [16.0 / 9.0, 1.0, 1.5, 2.39, 0.5, 4.0 / 3.0] {
            let (w, h) = size_for_aspect(Some(a));
            assert!(size_matches(w, h, a), "{a}");
        }
        assert!(size_matches(1920, 1080, 16.0 / 9.0));
        assert!(!size_matches(640, 480, 16.0 / 9.0));
        assert!(!size_matches(640, 640, 1.5));
    }

    #[test]
    fn exposure_scales_rgb_by_two_to_the_ev_and_keeps_alpha() {
        let mut px = vec![[0.5, 0.25, 1.0, 0.75], [0.0, 2.0, 0.125, 1.0]];
        let before = px.clone();
        apply_exposure(&mut px, 0.0);
        assert_eq!(px, before);
        apply_exposure(&mut px, 2.0);
        assert_eq!(px, vec![[2.0, 1.0, 4.0, 0.75], [0.0, 8.0, 0.5, 1.0]]);
        apply_exposure(&mut px, -2.0);
        assert_eq!(px, before);
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
