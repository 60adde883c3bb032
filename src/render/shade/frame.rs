//! What shading makes of a frame: its buffers (beauty, AOVs, the light-path passes,
//! Cryptomatte), and the counts and times it reports.

use std::time::Duration;

use glam::Vec3;

/// Linear radiance and AOVs of one frame, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameBuffers {
    pub width: u32,
    pub height: u32,
    /// Linear RGB and coverage (alpha).
    pub rgba: Vec<[f32; 4]>,
    pub depth: Option<Vec<f32>>,
    pub normal: Option<Vec<[f32; 3]>>,
    pub albedo: Option<Vec<[f32; 3]>>,
    /// World-space hit point of the centre ray (`P.X/Y/Z`).
    pub position: Option<Vec<[f32; 3]>>,
    /// Screen-space motion to the next frame in pixels (`motion.X/Y`; +x right, +y down).
    pub motion: Option<Vec<[f32; 2]>>,
    pub crypto: Option<CryptoBuffers>,
    /// The light-path passes (`--aov diffuse,specular,transmission,emission`): all four
    /// when any is asked for.
    pub light_paths: Option<LightPathBuffers>,
    /// Pixels traced beyond every edge (`--overscan`): the buffers are
    /// `(width + 2·overscan) × (height + 2·overscan)`, row 0 being `y = −overscan`;
    /// `width` and `height` are the image's (the display window).
    pub overscan: u32,
}

impl FrameBuffers {
    /// Width and height of the buffers: the image and its overscan border.
    pub fn data_size(&self) -> (u32, u32) {
        (
            self.width + 2 * self.overscan,
            self.height + 2 * self.overscan,
        )
    }

    /// `--exposure EV`: the radiance (RGB and the light-path passes) × 2^EV; alpha and
    /// the data AOVs are left alone.
    pub fn apply_exposure(&mut self, ev: f32) {
        crate::render::camera::apply_exposure(&mut self.rgba, ev);
        if ev == 0.0 {
            return;
        }
        let k = ev.exp2();
        if let Some(lp) = &mut self.light_paths {
            for pass in &mut lp.passes {
                for c in pass.iter_mut().flatten() {
                    *c *= k;
                }
            }
        }
    }
}

/// Which pass a contribution to the beauty goes to (`--aov
/// diffuse,specular,transmission,emission`), decided as Cycles decides its passes: by
/// the first scattering event at the camera ray's hit (pass-through of alpha-cut or
/// blended surfaces is no event). At that hit, light from the lights through the
/// diffuse lobe, the ambient term and diffuse bounces are `Diffuse`; the lights' glint
/// (the Blinn–Phong highlight) and everything the mirror or GGX reflection ray brings
/// are `Specular`; everything the refracted ray brings is `Transmission`; the hit's own
/// emission and the background or environment a camera ray sees are `Emission`. Past
/// the first event a path keeps its pass (a mirror seen through glass is transmission).
/// Every contribution goes to exactly one pass, so the passes add up to the beauty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum LightPath {
    Diffuse = 0,
    Specular = 1,
    Transmission = 2,
    Emission = 3,
}

impl LightPath {
    /// The passes in channel-layer order.
    pub const ALL: [LightPath; 4] = [
        LightPath::Diffuse,
        LightPath::Specular,
        LightPath::Transmission,
        LightPath::Emission,
    ];

    /// The EXR layer name (`diffuse.R` …) and the `--aov` name.
    pub fn name(self) -> &'static str {
        match self {
            LightPath::Diffuse => "diffuse",
            LightPath::Specular => "specular",
            LightPath::Transmission => "transmission",
            LightPath::Emission => "emission",
        }
    }
}

/// The four light-path passes of a frame, linear RGB a pixel, indexed by
/// [`LightPath`] (`passes[LightPath::Specular as usize]`).
#[derive(Clone, Debug, PartialEq)]
pub struct LightPathBuffers {
    pub passes: [Vec<[f32; 3]>; 4],
    /// Which of them the EXR gets (the `--aov` names given).
    pub written: [bool; 4],
}

/// A contribution split over the passes (indexed by [`LightPath`]).
pub(in crate::render) type Split = [Vec3; 4];

/// `c` in pass `path`, nothing in the others.
#[inline]
pub(super) fn split_one(path: LightPath, c: Vec3) -> Split {
    let mut s = [Vec3::ZERO; 4];
    s[path as usize] = c;
    s
}

/// Cryptomatte ranks of a frame: `levels` `(id, coverage)` pairs a pixel, pixel by
/// pixel, most coverage first (`(0, 0)` past the ids a pixel has).
#[derive(Clone, Debug, PartialEq)]
pub struct CryptoBuffers {
    pub levels: usize,
    pub object: Vec<(f32, f32)>,
    pub material: Vec<(f32, f32)>,
}

/// The centre ray's surface values (zero on a miss).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(in crate::render) struct CentreAov {
    pub normal: [f32; 3],
    pub albedo: [f32; 3],
    pub point: Vec3,
}

/// Rays traced for one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    /// Camera rays (every sample, plus the pixel-centre AOV rays when `spp > 1`).
    pub primary: u64,
    /// Any-hit rays towards lights.
    pub shadow: u64,
    /// Reflection, refraction and pass-through rays.
    pub secondary: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.secondary
    }
}

/// Where one frame's time went.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameWork {
    /// Wall time inside batch intersection calls.
    pub trace: Duration,
    /// Wall time making rays and shading (everything else of the frame's pixels).
    pub shade: Duration,
    pub rays: RayCounts,
    /// What the frame did with what a still camera keeps (its last pass's).
    pub kept: super::super::stats::Kept,
    /// Samples whose sums were the last frame's, neither shaded nor traced below their
    /// camera ray (`render::replay`'s settled samples).
    pub settled: u64,
}
