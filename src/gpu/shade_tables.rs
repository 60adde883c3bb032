//! The tables the GPU frame path's kernels read (shade.wgsl's `Mat`, `Light` and `Cam`,
//! and the triangles' surfaces), laid out as the kernels declare them: what depends on
//! a material, a light or the camera alone, computed on the CPU by the CPU's own code
//! (`render::gpu_frame`), so the kernels start from the CPU's very numbers.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};

/// A triangle as shading reads it: three positions (the first's `w`: the material's
/// index in the table, the second's: 1 when it has vertex normals), three normals, then
/// the three vertices' texture coordinates (the third's `w`: 1 when it has them). 128
/// bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct SurfaceTriangle {
    v: [[f32; 4]; 8],
}

impl SurfaceTriangle {
    /// Positions `p`, vertex normals `n` if any, material `material` (an index into
    /// the material table).
    pub fn new(p: &[Vec3; 3], n: Option<&[Vec3; 3]>, material: u32) -> SurfaceTriangle {
        let mut v = [[0.0f32; 4]; 8];
        for k in 0..3 {
            v[k] = [p[k].x, p[k].y, p[k].z, 0.0];
            if let Some(n) = n {
                v[3 + k] = [n[k].x, n[k].y, n[k].z, 0.0];
            }
        }
        v[0][3] = f32::from_bits(material);
        v[1][3] = f32::from_bits(u32::from(n.is_some()));
        SurfaceTriangle { v }
    }

    /// With the vertices' texture coordinates `uv`.
    pub fn with_uvs(mut self, uv: &[Vec2; 3]) -> SurfaceTriangle {
        self.v[6] = [uv[0].x, uv[0].y, uv[1].x, uv[1].y];
        self.v[7] = [uv[2].x, uv[2].y, 0.0, f32::from_bits(1)];
        self
    }
}

/// A constant material, as shade.wgsl's `lobes` and `brdf` read it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ShadeMaterial {
    /// Base colour (RGB).
    pub albedo: [f32; 3],
    /// Clamped to [0, 1].
    pub metallic: f32,
    /// `mix(0.04, albedo, metallic)`.
    pub f0: [f32; 3],
    /// Clamped to [0, 1].
    pub roughness: f32,
    /// Emissive × strength.
    pub emission: [f32; 3],
    /// Clamped, × (1 − metallic).
    pub transmission: f32,
    /// `(1 − roughness)²`.
    pub gloss: f32,
    /// The Blinn–Phong exponent (0: no glint).
    pub shininess: f32,
    /// `1 / ior` and `ior`.
    pub eta_entering: f32,
    pub eta_leaving: f32,
    /// 1 for double-sided.
    pub double_sided: u32,
    /// The reflection ray traced: 0 none, 1 the mirror's, 2 one drawn from the GGX
    /// lobe (width `roughness²`; its numbers from the item's seed).
    pub reflects: u32,
    /// `(shininess + 8) / 8π`.
    pub glint_norm: f32,
    /// `1 − gloss / 2`.
    pub glint_scale: f32,
    /// The texture slots (base colour, metallic-roughness, emissive, normal): each a
    /// view of [`GpuTextures`] (`u32::MAX`: none). With one, the kernel computes what
    /// the slot changes per hit, from the factors below, as the CPU does.
    pub tex: [u32; 4],
    /// The factors as the material holds them: metallic, roughness, transmission
    /// (clamped), the normal map's scale (1 where not finite).
    pub factors: [f32; 4],
    /// Each slot's `KHR_texture_transform`: scale (x, y), sin and cos of the rotation;
    /// offset (x, y), 1 when there is one, 0.
    pub transform: [[f32; 4]; 8],
    /// The material's own ambient colour (AFF) and 1, or zeros without one.
    pub aff: [f32; 4],
    /// Coverage (`alpha_of`): the base colour factor's alpha, the `MASK` cutoff, the
    /// mode (0 `OPAQUE`, 1 `MASK`, 2 `BLEND`), 1 when a hit may pass rays through
    /// (alpha below 1 somewhere: the host encodes the levels for it).
    pub alpha: [f32; 4],
}

/// The textures of a frame path's render, uploaded once (`GpuShading::new_textured`):
/// `meta` holds the decoding tables (the sRGB table, then `b / 255` for the linear
/// bytes; 256 words each, f32 bits), the views (one a texture and colour space the
/// materials use: [`TEXTURE_VIEW_WORDS`] words each) and the mip levels (texel offset,
/// width, height, 0); `texels` every level's RGBA8 texels, one u32 each (R in the low
/// byte).
#[derive(Clone, Debug, Default)]
pub struct GpuTextures {
    pub meta: Vec<u32>,
    pub texels: Vec<u32>,
}

/// Words of a texture view in [`GpuTextures::meta`]: reduced levels (the chain's length
/// below the image), wrap S and T (0 repeat, 1 clamp to edge, 2 mirrored repeat), 1 for
/// nearest magnification, the word of its first level, `log2(√(w·h))` (f32 bits), 1 for
/// sRGB, 0.
pub const TEXTURE_VIEW_WORDS: usize = 8;

/// A punctual light, as shade.wgsl reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ShadeLight {
    pub position: [f32; 3],
    /// 0 directional, 1 point, 2 spot.
    pub kind: u32,
    /// Unit direction the light shines along.
    pub direction: [f32; 3],
    pub range: f32,
    /// Colour × intensity.
    pub power: [f32; 3],
    /// 1 for `Falloff::None`.
    pub no_falloff: u32,
    /// The spot's `cos(outer)` and `1 / max(cos(inner) − cos(outer), 1e-3)`.
    pub cos_outer: f32,
    pub cone_scale: f32,
    /// 1 when `range` applies.
    pub has_range: u32,
    pub pad: u32,
}

/// An emissive triangle (an area light), as shade.wgsl's `Emitter` reads it: the CPU's
/// `AreaLights` table, drawn by `cdf` (the first whose `cdf` is above the number).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ShadeEmitter {
    pub p0: [f32; 3],
    pub area: f32,
    /// `p1 − p0`.
    pub e1: [f32; 3],
    /// The triangle's number (as the tracer numbers them).
    pub tri: u32,
    /// `p2 − p0`.
    pub e2: [f32; 3],
    /// Its material's row of the material table.
    pub material: u32,
    /// The unit geometric normal.
    pub normal: [f32; 3],
    /// 1 when it emits from both sides.
    pub two_sided: u32,
    /// The cumulative probability up to it, and up to the one before (0 for the first).
    pub cdf: f32,
    pub cdf_below: f32,
    pub pad: [u32; 2],
}

/// The camera as shade.wgsl's `camera` kernel makes the rays (`Cam`): the fields of
/// `render::CameraModel` and of the frame, so that the rays are `CameraModel::ray`'s
/// at `wavefront::sample_offset`'s points, to the bit.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct CameraRays {
    pub origin: [f32; 3],
    pub tan_half: f32,
    /// The rotation's columns.
    pub x_axis: [f32; 3],
    pub aspect: f32,
    pub y_axis: [f32; 3],
    /// Orthographic half width and height (with `ortho` 1).
    pub xmag: f32,
    pub z_axis: [f32; 3],
    pub ymag: f32,
    /// The image's size (not the data window's).
    pub width: u32,
    pub height: u32,
    pub frame: u32,
    pub spp: u32,
    /// The jitter grid: `ceil(√spp)` columns, `ceil(spp / columns)` rows.
    pub grid_x: u32,
    pub grid_y: u32,
    pub overscan: u32,
    /// The data window's width (image and border).
    pub data_width: u32,
    /// The first pixel (row-major in the data window) of the rays made.
    pub first_pixel: u32,
    /// 1 for an orthographic camera.
    pub ortho: u32,
    /// 0: the zero that keeps products from being fused (`nc`).
    pub zero: u32,
    pub pad: u32,
    /// The camera rays' cone (width, spread: the texture level of detail), set by
    /// `GpuShading::render_chunk` from `ShadeParams::cone`.
    pub cone: [f32; 2],
    /// 1 when the light-path passes are traced (set from `ShadeParams::light_paths`).
    pub light_paths: f32,
    pub pad2: u32,
}

/// A frame's shading constants.
#[derive(Clone, Copy, Debug)]
pub struct ShadeParams {
    pub ambient: [f32; 3],
    pub background: [f32; 3],
    /// The scene's size (ray offsets).
    pub extent: f32,
    pub max_depth: u32,
    /// Contributions at or below this are dropped (`shade::MIN_WEIGHT`).
    pub min_weight: f32,
    /// Shadow rays to the area lights at a camera ray's hit (`ceil(LIGHT_SAMPLES /
    /// spp)`; one at deeper hits); read only when there are emitters.
    pub light_samples: u32,
    /// `--diffuse-bounces`.
    pub diffuse_bounces: u32,
    /// The camera rays' cone (width, spread; the texture level of detail).
    pub cone: [f32; 2],
    /// Trace the light-path passes (`--aov diffuse,specular,transmission,emission`).
    pub light_paths: bool,
}
