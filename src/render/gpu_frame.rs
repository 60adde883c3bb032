//! The GPU frame path's render side (`--device gpu`, issue 37 part 2, first step): which
//! scenes it takes ([`outside_subset`]), the tables the kernels read (materials,
//! lights, surfaces) made from the CPU's own shading values, and a frame traced as
//! [`wavefront::render_frame_with`](super::wavefront) traces it, but with each chunk's
//! whole wavefront on the GPU (`gpu::GpuShading`, shade.wgsl): camera rays made here,
//! pixels and (for the AOVs and Cryptomatte) the camera rays' hits read back.
//!
//! The subset is all `ShadeContext::shade` does, with or without motion blur (a
//! blurred frame's time steps each a pass of their samples) and the light-path passes,
//! but for an emissive texture on an area light: materials (base colour, metallic,
//! roughness, emission, transmission, IOR, double-sided, a material's own ambient
//! colour, alpha: `MASK` and `BLEND` with their pass-through rays), textured or
//! not (the textures uploaded once a render, [`textures`], and filtered in the kernel
//! as `render::mips` filters them); the mirror reflection (GGX width under
//! `MIRROR_ALPHA`), one reflection ray drawn from the GGX lobe (the random numbers made
//! from the CPU's seeds, to the bit) or none (roughness from `GLOSSY_LIMIT` on);
//! refraction with exact dielectric Fresnel; punctual lights (the default light too) and
//! area lights (emissive triangles); the options' or the scene's ambient light; a
//! constant background or an environment map; diffuse bounces. Anything else keeps
//! shading on
//! the CPU, traced on the GPU as before, and the log says which feature did.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::camera::CameraModel;
use super::lights::emits;
use super::mips::TextureMips;
use super::options::RenderOptions;
use super::shade::{
    FrameBuffers, FrameWork, ShadeContext, GLOSSY_LIMIT, LIGHT_SAMPLES, MIN_WEIGHT, MIRROR_ALPHA,
};
use super::wavefront::{
    primary_cone, sample_offset, write_aovs, write_crypto, CentreInputs, FrameArgs, FrameScratch,
    StepPass,
};
use crate::geometry::Ray;
use crate::gpu::{
    CameraRays, GpuDevice, GpuError, GpuMoving, GpuShading, GpuStatic, GpuTextures, GpuTracer,
    ShadeEmitter, ShadeLight, ShadeMaterial, ShadeParams, SurfaceTriangle, TEXTURE_VIEW_WORDS,
};
use crate::scene::{AlphaMode, Falloff, Image, LightKind, Material, Scene, TriangleSoup, Wrap};

/// Samples a chunk traces at most (bounds the GPU's buffers: a level's rays at most
/// double, and its shadow rays are at most one a light an item).
const CHUNK_SAMPLES: usize = 1 << 16;

/// The most samples a pixel the kernel's area-light strata take (`(spp + 7) · 7919`
/// stays under 2^32).
const MAX_AREA_SPP: u32 = 1 << 19;

/// Why `scene` rendered with `opts` cannot take the GPU frame path (the first feature
/// outside the subset, in words), or `None` when it can. `max_binding`: the adapter's
/// largest storage binding (the surfaces of either part must fit one).
pub(super) fn outside_subset(
    scene: &Scene,
    opts: &RenderOptions,
    static_triangles: usize,
    moving_triangles: usize,
    max_binding: u64,
) -> Option<String> {
    if opts.cpu_shading {
        return Some("a render asked to shade on the CPU (SUBFIELD_GPU_SHADING=cpu)".into());
    }
    if let Some(env) = &opts.shading.environment {
        let bytes = (8 + 3 * env.texel_count() as u64) * 4;
        if bytes > max_binding {
            return Some(format!(
                "an environment map of {bytes} bytes (more than one GPU storage binding, {max_binding} bytes)"
            ));
        }
    }
    // The area lights' strata are numbered in 32 bits (`cell · 7919` a camera ray's
    // hit, up to `spp + 7` cells).
    if opts.spp > MAX_AREA_SPP && scene.materials.iter().any(emits) {
        return Some(format!(
            "area lights at more than {MAX_AREA_SPP} samples a pixel (--spp)"
        ));
    }
    let texels = texel_count(scene).saturating_mul(4);
    if texels > max_binding {
        return Some(format!(
            "the textures ({texels} bytes with their mip levels) exceed one GPU storage binding ({max_binding} bytes)"
        ));
    }
    for (what, n) in [("static", static_triangles), ("moving", moving_triangles)] {
        let bytes = n as u64 * std::mem::size_of::<SurfaceTriangle>() as u64;
        if bytes > max_binding {
            return Some(format!(
                "the {what} triangles' surfaces ({bytes} bytes) exceed one GPU storage binding ({max_binding} bytes)"
            ));
        }
    }
    None
}

/// Texture `t`'s image where `ShadeContext::texture` reads it (a texture and an image
/// there, of a size its bytes fill); `None` where the CPU reads no texture.
fn image_of(scene: &Scene, t: u32) -> Option<&Image> {
    let tex = scene.textures.get(t as usize)?;
    let img = scene.images.get(tex.image as usize)?;
    let (w, h) = (u64::from(img.width), u64::from(img.height));
    (w > 0 && h > 0 && img.rgba8.len() as u64 == w * h * 4).then_some(img)
}

/// Whether a hit on `m` may pass rays through (alpha below 1 somewhere, as `alpha_of`
/// finds it): its factor's alpha, or a base colour texture with an alpha byte below 255
/// under `MASK` or `BLEND` (every mip level's byte lies between the image's least and
/// greatest, the box filter's means, so a texture of alpha 255 throughout reads 1
/// wherever filtered, and the factor decides as without it).
fn passes_through(scene: &Scene, m: &Material) -> bool {
    let texture = m
        .base_color_texture
        .and_then(|r| byte_range(scene, r.texture, 3))
        .is_some_and(|(lo, _)| lo < 255);
    match m.alpha_mode {
        AlphaMode::Opaque => false,
        // `alpha_of`: 0 unless the factor reaches the cutoff (a NaN does not).
        AlphaMode::Mask { cutoff } => {
            texture
                || m.base_color
                    .w
                    .partial_cmp(&cutoff)
                    .is_none_or(std::cmp::Ordering::is_lt)
        }
        // The factor clamped to [0, 1] (a NaN stays one, and passes nothing through).
        AlphaMode::Blend => texture || m.base_color.w < 1.0,
    }
}

/// The least and greatest byte of channel `c` of texture `t`'s image.
fn byte_range(scene: &Scene, t: u32, c: usize) -> Option<(u8, u8)> {
    let img = image_of(scene, t)?;
    Some(
        img.rgba8
            .chunks_exact(4)
            .fold((u8::MAX, 0), |(lo, hi), p| (lo.min(p[c]), hi.max(p[c]))),
    )
}

/// The textures as the materials read them, one view a texture and colour space used
/// (`TextureMips::build`'s chains: base colour and emissive sRGB, the others linear),
/// in the order of the textures, sRGB first; textures the CPU does not read left out.
fn texture_views(scene: &Scene) -> Vec<(u32, bool)> {
    let want = TextureMips::wanted(scene);
    let mut views = Vec::new();
    for (t, (s, l)) in want.into_iter().enumerate() {
        let t = t as u32;
        if image_of(scene, t).is_none() {
            continue;
        }
        if s {
            views.push((t, true));
        }
        if l {
            views.push((t, false));
        }
    }
    views
}

/// The sizes of a mip chain from a `w × h` image on (`TextureMips::build`'s levels).
fn level_sizes(w: u32, h: u32) -> Vec<(u32, u32)> {
    let mut sizes = vec![(w, h)];
    let (mut w, mut h) = (w, h);
    while w > 1 || h > 1 {
        (w, h) = ((w / 2).max(1), (h / 2).max(1));
        sizes.push((w, h));
    }
    sizes
}

/// The texels the frame path uploads: every level of every view.
fn texel_count(scene: &Scene) -> u64 {
    texture_views(scene)
        .iter()
        .filter_map(|&(t, _)| image_of(scene, t))
        .flat_map(|img| level_sizes(img.width, img.height))
        .map(|(w, h)| u64::from(w) * u64::from(h))
        .sum()
}

/// The textures for the GPU ([`GpuTextures`]): the decoding tables, the views and
/// every level of their chains (the image, then `mips`' reduced levels).
pub(super) fn textures(scene: &Scene, mips: &TextureMips) -> GpuTextures {
    let views = texture_views(scene);
    if views.is_empty() {
        return GpuTextures::default();
    }
    let mut meta: Vec<u32> = mips.srgb_table().iter().map(|x| x.to_bits()).collect();
    meta.resize(256, 0);
    meta.extend((0..256).map(|b| (b as f32 / 255.0).to_bits()));
    let levels_at = meta.len() + views.len() * TEXTURE_VIEW_WORDS;
    let mut levels: Vec<u32> = Vec::new();
    let mut texels: Vec<u32> = Vec::new();
    let wrap = |w: Wrap| match w {
        Wrap::Repeat => 0,
        Wrap::ClampToEdge => 1,
        Wrap::MirroredRepeat => 2,
    };
    for &(t, srgb) in &views {
        let (Some(tex), Some(img)) = (scene.textures.get(t as usize), image_of(scene, t)) else {
            continue;
        };
        let (w, h) = (img.width, img.height);
        let top = mips.levels(t as usize, srgb) - 1;
        meta.extend([
            top as u32,
            wrap(tex.wrap_s),
            wrap(tex.wrap_t),
            u32::from(tex.nearest),
            (levels_at + levels.len()) as u32,
            (0.5 * ((w as f32) * (h as f32)).log2()).to_bits(),
            u32::from(srgb),
            0,
        ]);
        for i in 0..=top {
            let (data, lw, lh) = match i {
                0 => (&img.rgba8[..], w, h),
                _ => mips.level(t as usize, srgb, i).unwrap_or((&[], 0, 0)),
            };
            levels.extend([texels.len() as u32, lw, lh, 0]);
            texels.extend(
                data.chunks_exact(4)
                    .map(|p| u32::from_le_bytes([p[0], p[1], p[2], p[3]])),
            );
        }
    }
    meta.extend(levels);
    GpuTextures { meta, texels }
}

/// The material table: the scene's materials, then glTF's default material (for
/// triangles without one), each as `ShadeContext::lobes` and `glint` compute it, with
/// its textures' views (numbered as [`textures`] numbers them). A material with a
/// metallic-roughness texture is marked as reflecting and transmitting as its factors
/// allow (so the levels are encoded; the kernel decides per hit), and one that may
/// pass rays through as such ([`passes_through`]: the levels of the passes are
/// encoded).
fn materials(scene: &Scene) -> Vec<ShadeMaterial> {
    let default = Material::default();
    let views = texture_views(scene);
    let view = |slot: Option<crate::scene::TextureRef>, srgb: bool| {
        slot.and_then(|r| views.iter().position(|&v| v == (r.texture, srgb)))
            .map_or(u32::MAX, |i| i as u32)
    };
    scene
        .materials
        .iter()
        .chain(std::iter::once(&default))
        .map(|m| {
            let albedo = m.base_color.truncate();
            let metallic = m.metallic.clamp(0.0, 1.0);
            let roughness = m.roughness.clamp(0.0, 1.0);
            let transmission = (m.transmission.clamp(0.0, 1.0)) * (1.0 - metallic);
            let gloss = (1.0 - roughness) * (1.0 - roughness);
            let f0 = Vec3::splat(0.04).lerp(albedo, metallic);
            let ior = if m.ior.is_finite() && m.ior >= 1.0 {
                m.ior
            } else {
                1.5
            };
            let shininess = ShadeContext::shininess(roughness);
            let slots = [
                m.base_color_texture,
                m.metallic_roughness_texture,
                m.emissive_texture,
                m.normal_texture,
            ];
            let tex = [
                view(slots[0], true),
                view(slots[1], false),
                view(slots[2], true),
                view(slots[3], false),
            ];
            let mut transform = [[0.0f32; 4]; 8];
            for (k, slot) in slots.iter().enumerate() {
                if let Some(t) = slot.and_then(|s| s.transform) {
                    let (sin, cos) = t.rotation.sin_cos();
                    transform[2 * k] = [t.scale.x, t.scale.y, sin, cos];
                    transform[2 * k + 1] = [t.offset.x, t.offset.y, 1.0, 0.0];
                }
            }
            let rough_texture = tex[1] != u32::MAX;
            ShadeMaterial {
                albedo: albedo.to_array(),
                metallic,
                f0: f0.to_array(),
                roughness,
                emission: (m.emissive * m.emissive_strength).to_array(),
                transmission: if rough_texture {
                    m.transmission.clamp(0.0, 1.0)
                } else {
                    transmission
                },
                gloss,
                shininess,
                eta_entering: 1.0 / ior,
                eta_leaving: ior,
                double_sided: u32::from(m.double_sided),
                // 0 none, 1 the mirror's, 2 GGX; with a metallic-roughness texture
                // `textured` decides a hit's own (2 here: seeds are made).
                reflects: if rough_texture {
                    2
                } else if roughness >= GLOSSY_LIMIT {
                    0
                } else if roughness * roughness < MIRROR_ALPHA {
                    1
                } else {
                    2
                },
                glint_norm: (shininess + 8.0) / (8.0 * std::f32::consts::PI),
                glint_scale: 1.0 - gloss * 0.5,
                tex,
                factors: [
                    m.metallic,
                    m.roughness,
                    m.transmission.clamp(0.0, 1.0),
                    if m.normal_scale.is_finite() {
                        m.normal_scale
                    } else {
                        1.0
                    },
                ],
                transform,
                aff: m.ambient.map_or([0.0; 4], |a| a.extend(1.0).to_array()),
                alpha: [
                    m.base_color.w,
                    match m.alpha_mode {
                        AlphaMode::Mask { cutoff } => cutoff,
                        _ => 0.0,
                    },
                    match m.alpha_mode {
                        AlphaMode::Opaque => 0.0,
                        AlphaMode::Mask { .. } => 1.0,
                        AlphaMode::Blend => 2.0,
                    },
                    if passes_through(scene, m) { 1.0 } else { 0.0 },
                ],
            }
        })
        .collect()
}

/// The punctual lights of `ctx` (posed for the frame; the default light included).
fn lights(ctx: &ShadeContext<'_>) -> Vec<ShadeLight> {
    ctx.lights
        .iter()
        .map(|l| {
            let (kind, cos_outer, cone_scale) = match l.kind {
                LightKind::Directional => (0, 0.0, 0.0),
                LightKind::Point => (1, 0.0, 0.0),
                LightKind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => {
                    let (ci, co) = (inner_cone_angle.cos(), outer_cone_angle.cos());
                    (2, co, 1.0 / (ci - co).max(1e-3))
                }
            };
            ShadeLight {
                position: l.position.to_array(),
                kind,
                direction: l.direction.to_array(),
                range: l.range.unwrap_or(0.0),
                power: l.power.to_array(),
                no_falloff: u32::from(l.falloff == Falloff::None),
                cos_outer,
                cone_scale,
                has_range: u32::from(l.range.is_some()),
                pad: 0,
            }
        })
        .collect()
}

/// The area lights of `ctx` (the frame's emissive triangles, static and posed), as the
/// CPU draws them.
fn emitters(ctx: &ShadeContext<'_>) -> Vec<ShadeEmitter> {
    ctx.area
        .table()
        .map(|(e, cdf, cdf_below)| ShadeEmitter {
            p0: e.p0.to_array(),
            area: e.area,
            e1: e.e1.to_array(),
            tri: e.tri,
            e2: e.e2.to_array(),
            material: e.material,
            normal: e.normal.to_array(),
            two_sided: u32::from(e.two_sided),
            cdf,
            cdf_below,
            pad: [0; 2],
        })
        .collect()
}

/// The surfaces of `soup`'s triangles; a material number outside the table's
/// `materials` scene materials takes the default material after them.
pub(super) fn surfaces(soup: &TriangleSoup, materials: usize) -> Vec<SurfaceTriangle> {
    soup.positions
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .map(|(i, p)| {
            let m = soup
                .material
                .get(i)
                .copied()
                .filter(|&m| (m as usize) < materials)
                .unwrap_or(materials as u32);
            let t = SurfaceTriangle::new(p, soup.normals.get(i), m);
            match soup.uvs.get(i) {
                Some(uv) => t.with_uvs(uv),
                None => t,
            }
        })
        .collect()
}

/// `camera` and the frame as the GPU makes their rays (`CameraModel::ray` at
/// `sample_offset`'s points), from the data window's first pixel on.
pub(super) fn camera_rays(camera: &CameraModel, frame: u32, spp: u32, overscan: u32) -> CameraRays {
    let spp = spp.max(1);
    // `sample_offset`'s grid.
    let gx = (spp as f64).sqrt().ceil() as u32;
    let (xmag, ymag) = camera.ortho.unwrap_or((0.0, 0.0));
    let r = &camera.rotation;
    CameraRays {
        origin: camera.origin.to_array(),
        tan_half: camera.tan_half,
        x_axis: r.x_axis.to_array(),
        aspect: camera.aspect,
        y_axis: r.y_axis.to_array(),
        xmag,
        z_axis: r.z_axis.to_array(),
        ymag,
        width: camera.width,
        height: camera.height,
        frame,
        spp,
        grid_x: gx.max(1),
        grid_y: spp.div_ceil(gx.max(1)),
        overscan,
        data_width: camera.width + 2 * overscan,
        first_pixel: 0,
        ortho: u32::from(camera.ortho.is_some()),
        zero: 0,
        pad: 0,
        cone: [0.0; 2],
        light_paths: 0.0,
        pad2: 0,
    }
}

/// What the frame path needs of the GPU.
pub(super) struct GpuParts<'a> {
    pub dev: &'a GpuDevice,
    pub stat: &'a GpuStatic,
    pub moving: &'a GpuMoving,
    pub shading: &'a GpuShading,
}

/// One frame traced and shaded on the GPU into `fb` (from `wavefront::new_frame`), or
/// with `pass` one time step of a blurred frame (from `wavefront::begin_blurred`: its
/// samples' sums added to the steps' before, `finish_blurred` averaging them): the same
/// pixels `render_pass_with` makes on the CPU, to the rounding of the GPU's shading
/// arithmetic (docs/GPU.md), and the same AOVs.
#[allow(clippy::too_many_arguments)]
pub(super) fn render_frame_gpu(
    gpu: &GpuParts<'_>,
    scratch: &mut FrameScratch,
    ctx: &ShadeContext<'_>,
    args: &FrameArgs<'_>,
    pass: Option<StepPass>,
    fb: &mut FrameBuffers,
    work: &mut FrameWork,
) -> Result<(), GpuError> {
    let FrameArgs {
        camera,
        frame,
        spp,
        max_depth,
        inputs,
        still_ahead: _,
    } = *args;
    let aovs = inputs.aovs;
    let o = inputs.overscan as usize;
    let (w, h) = (
        camera.width as usize + 2 * o,
        camera.height as usize + 2 * o,
    );
    let spp = spp.max(1) as usize;
    let clock = Instant::now();
    let mats = materials(ctx.scene);
    let lts = lights(ctx);
    let ems = emitters(ctx);
    let cone = primary_cone(camera);
    let params = ShadeParams {
        ambient: ctx.options.ambient.to_array(),
        background: ctx.options.background.to_array(),
        extent: ctx.extent,
        max_depth,
        min_weight: MIN_WEIGHT,
        light_samples: LIGHT_SAMPLES.div_ceil(spp.max(1) as u32),
        diffuse_bounces: ctx.options.diffuse_bounces,
        cone: [cone.width, cone.spread],
        light_paths: fb.light_paths.is_some(),
    };
    // Uploaded once a render (the key names the file's bytes, turn and scale).
    let env = match &ctx.options.environment {
        Some(map) => Some(
            gpu.shading
                .environment(gpu.dev, &map.describe(), || map.gpu_table())?,
        ),
        None => None,
    };
    let moving_surf = surfaces(ctx.dynamic_soup, ctx.scene.materials.len());
    work.shade += clock.elapsed();
    let clock = Instant::now();
    let surf = gpu.shading.moving(gpu.dev, &moving_surf)?;
    work.trace += clock.elapsed();
    let crypto = inputs.crypto.filter(|_| aovs.cryptomatte);
    // As `trace_pass`: the centre-ray AOVs every frame's, or the one pass of a blurred
    // frame that has them, from rays of their own unless one sample a pixel unblurred.
    let any_aov = aovs.any_centre() && pass.is_none_or(|p| p.aovs);
    let centre_batch = spp > 1 || pass.is_some();
    let step = pass.map(|p| p.samples);
    let want_hits = (any_aov && !centre_batch) || (crypto.is_some() && fb.crypto.is_some());
    let centre_inputs = CentreInputs {
        camera,
        next: inputs.next.filter(|_| aovs.motion),
    };
    let pixel = |i: u32| i.wrapping_sub(o as u32);
    let cam = camera_rays(camera, frame, spp as u32, inputs.overscan);
    // A chunk's levels hold `capacity` items each (the buffers are sized before the
    // GPU knows how many rays a level makes): twice the chunk's samples to begin with,
    // doubled while a level outgrows it, up to what the adapter allows; past that the
    // chunk is traced again in halves. A sample's light does not depend on the chunk or
    // the room it is traced in, so neither changes a byte.
    let slots = lts.len()
        + if ems.is_empty() {
            0
        } else {
            params.light_samples as usize
        };
    let max_capacity = GpuShading::max_capacity(gpu.dev, slots, params.light_paths) as usize;
    let mut rows_per_chunk = ((CHUNK_SAMPLES.min(max_capacity / 4)) / (w * spp)).max(1);
    let mut capacity = 0;
    let mut y0 = 0;
    while y0 < h {
        let y1 = (y0 + rows_per_chunk).min(h);
        let px0 = y0 * w;
        let npix = (y1 - y0) * w;
        let clock = Instant::now();
        let chunk_camera = CameraRays {
            first_pixel: u32::try_from(px0).map_err(|_| GpuError::TooLarge {
                what: "an image (pixels numbered in 32 bits)",
                needed: px0 as u64,
                available: u64::from(u32::MAX),
                adapter: gpu.dev.describe(),
            })?,
            ..cam
        };
        // A blurred frame's step: the chunk's samples of the step (chunk numbers); the
        // pass with the AOVs alone traces none.
        let picked = step.map(|k| match k {
            Some(k) => scratch.step_samples(px0 * spp, npix * spp, k),
            None => Vec::new(),
        });
        let traced = picked.as_ref().map_or(npix * spp, Vec::len);
        let out = if traced == 0 {
            Ok(Some(crate::gpu::ChunkOut::default()))
        } else {
            gpu.shading.render_chunk(
                gpu.dev,
                gpu.stat,
                gpu.moving,
                &surf,
                &mats,
                &lts,
                &ems,
                env.as_ref(),
                &params,
                &chunk_camera,
                npix as u64,
                picked.as_deref(),
                capacity.max(2 * traced).min(max_capacity) as u64,
                want_hits,
            )
        };
        work.trace += clock.elapsed();
        let out = match out {
            Ok(Some(out)) => out,
            Ok(None) if capacity < max_capacity => {
                capacity = capacity.max(2 * traced).saturating_mul(2);
                continue;
            }
            Ok(None) | Err(GpuError::TooLarge { .. }) if y1 - y0 > 1 => {
                rows_per_chunk = (y1 - y0) / 2;
                capacity = 0;
                continue;
            }
            Ok(None) => {
                return Err(GpuError::TooLarge {
                    what: "the rays of one row of pixels (the frame path's levels)",
                    needed: (max_capacity * 48) as u64,
                    available: gpu.dev.max_binding(),
                    adapter: gpu.dev.describe(),
                })
            }
            Err(e) => return Err(e),
        };
        capacity = 0;
        work.rays.primary += traced as u64;
        work.rays.shadow += out.shadow_rays;
        work.rays.secondary += out.secondary_rays;
        let clock = Instant::now();
        match &picked {
            None => fb.rgba[px0..px0 + npix].copy_from_slice(&out.rgba),
            // A step's sums added to the steps' before (`finish_blurred` averages).
            Some(sel) if !sel.is_empty() => {
                for (px, c) in fb.rgba[px0..px0 + npix].iter_mut().zip(&out.rgba) {
                    *px = [px[0] + c[0], px[1] + c[1], px[2] + c[2], px[3] + c[3]];
                }
            }
            Some(_) => {}
        }
        if let (Some(passes), Some(lp)) = (&out.passes, fb.light_paths.as_mut()) {
            // Each pass averaged (or, for a step, summed and added) as the beauty is.
            let add = match &picked {
                None => Some(false),
                Some(sel) if !sel.is_empty() => Some(true),
                Some(_) => None,
            };
            if let Some(add) = add {
                for (k, pass) in lp.passes.iter_mut().enumerate() {
                    for (i, px) in pass[px0..px0 + npix].iter_mut().enumerate() {
                        let c = passes[i * 4 + k];
                        *px = if add {
                            [px[0] + c[0], px[1] + c[1], px[2] + c[2]]
                        } else {
                            [c[0], c[1], c[2]]
                        };
                    }
                }
            }
        }
        if let (Some(hits), Some(sel), Some(names)) = (&out.camera_hits, &picked, crypto) {
            // A step's samples: their ids kept until every step has traced.
            if fb.crypto.is_some() {
                scratch.keep_step_crypto(ctx, names, px0 * spp, sel, hits);
            }
        } else if let Some(hits) = &out.camera_hits {
            if any_aov && !centre_batch {
                // One sample a pixel: the camera rays are the centre rays, made again
                // here (the same bits: `camera_rays_are_the_cpus`).
                let rays: Vec<Ray> = (0..npix)
                    .into_par_iter()
                    .with_min_len(1024)
                    .map(|i| {
                        let p = px0 + i;
                        let (x, y) = (pixel((p % w) as u32), pixel((p / w) as u32));
                        let (ox, oy) = sample_offset(frame, x, y, 0, 1);
                        camera.ray(x as i32 as f32 + ox, y as i32 as f32 + oy)
                    })
                    .collect();
                write_aovs(ctx, &centre_inputs, fb, px0, &rays, hits);
            }
            if let (Some(names), Some(buf)) = (crypto, fb.crypto.as_mut()) {
                write_crypto(ctx, names, buf, px0, spp, hits);
            }
        }
        work.shade += clock.elapsed();
        if any_aov && centre_batch {
            let clock = Instant::now();
            let centre: Vec<Ray> = (0..npix)
                .into_par_iter()
                .with_min_len(1024)
                .map(|i| {
                    let p = px0 + i;
                    let (x, y) = (pixel((p % w) as u32), pixel((p / w) as u32));
                    camera.ray(x as i32 as f32 + 0.5, y as i32 as f32 + 0.5)
                })
                .collect();
            work.rays.primary += npix as u64;
            work.shade += clock.elapsed();
            let clock = Instant::now();
            let mut chits = vec![None; npix];
            GpuTracer::new(gpu.dev, gpu.stat, gpu.moving)
                .try_intersect_batch(&centre, &mut chits)?;
            work.trace += clock.elapsed();
            let clock = Instant::now();
            write_aovs(ctx, &centre_inputs, fb, px0, &centre, &chits);
            work.shade += clock.elapsed();
        }
        y0 = y1;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::options::MotionBlur;
    use crate::render::shade::MAX_PASSES;
    use crate::scene::TextureRef;

    /// A level that outgrows its room is refused (`None`), and the chunk traced with
    /// more room gives the same bytes whatever the room, in fresh buffers or in those a
    /// larger chunk left: 256 pixels of glass over a floor make 512 rays at the second
    /// level.
    #[test]
    fn a_level_that_outgrows_its_room_is_refused_and_room_changes_nothing() {
        use crate::gpu::{GpuMoving, GpuStatic};
        use crate::psf::{Psf, PsfParams};
        let Some(dev) = crate::gpu::test_device() else {
            return;
        };
        let mut tris: Vec<[Vec3; 3]> = Vec::new();
        let mut mat = Vec::new();
        // A cube of glass (material 0) around the origin, half size 0.5.
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let mut n = Vec3::ZERO;
                n[axis] = sign;
                let a = n.any_orthonormal_vector();
                let b = n.cross(a);
                let c = |s: f32, t: f32| (n + a * s + b * t) * 0.5;
                tris.push([c(-1.0, -1.0), c(1.0, -1.0), c(1.0, 1.0)]);
                tris.push([c(-1.0, -1.0), c(1.0, 1.0), c(-1.0, 1.0)]);
                mat.extend([0, 0]);
            }
        }
        // A floor (material 1).
        let f = |x: f32, z: f32| Vec3::new(x, -1.0, z);
        tris.push([f(-5.0, -5.0), f(-5.0, 5.0), f(5.0, 5.0)]);
        tris.push([f(-5.0, -5.0), f(5.0, 5.0), f(5.0, -5.0)]);
        mat.extend([1, 1]);
        let psf = Psf::build(&tris, &PsfParams::for_static(tris.len())).unwrap();
        let stat = GpuStatic::upload(&dev, &psf).unwrap();
        let mut moving = GpuMoving::new(&dev).unwrap();
        moving.update(&dev, &[]).unwrap();
        let surf: Vec<SurfaceTriangle> = tris
            .iter()
            .zip(&mat)
            .map(|(p, &m)| SurfaceTriangle::new(p, None, m))
            .collect();
        let shading = GpuShading::new(&dev, &surf).unwrap();
        let no_moving = shading.moving(&dev, &[]).unwrap();
        let scene = Scene {
            materials: vec![
                Material {
                    transmission: 1.0,
                    roughness: 0.0,
                    metallic: 0.0,
                    double_sided: true,
                    ..Material::default()
                },
                Material {
                    metallic: 0.0,
                    ..Material::default()
                },
            ],
            ..Scene::default()
        };
        let mats = materials(&scene);
        let lts = [ShadeLight {
            position: [2.0, 4.0, 3.0],
            kind: 1,
            power: [40.0; 3],
            ..ShadeLight::default()
        }];
        let params = ShadeParams {
            ambient: [0.05; 3],
            background: [0.2, 0.3, 0.4],
            extent: 10.0,
            max_depth: 4,
            min_weight: MIN_WEIGHT,
            light_samples: 8,
            diffuse_bounces: 0,
            cone: [0.0; 2],
            light_paths: false,
        };
        // Every pixel on the cube's front face.
        let camera = CameraModel {
            origin: Vec3::new(0.0, 0.1, 4.0),
            rotation: glam::Mat3::IDENTITY,
            tan_half: 0.1,
            aspect: 1.0,
            ortho: None,
            width: 16,
            height: 16,
        };
        let cam = camera_rays(&camera, 0, 1, 0);
        let run = |capacity: u64| {
            shading
                .render_chunk(
                    &dev,
                    &stat,
                    &moving,
                    &no_moving,
                    &mats,
                    &lts,
                    &[],
                    None,
                    &params,
                    &cam,
                    256,
                    None,
                    capacity,
                    true,
                )
                .unwrap()
        };
        assert!(run(256).is_none(), "512 rays in the room of 256");
        let snug = run(1024).unwrap();
        let roomy = run(1 << 14).unwrap();
        let bits = |o: &crate::gpu::ChunkOut| -> Vec<u32> {
            o.rgba.iter().flatten().map(|x| x.to_bits()).collect()
        };
        // Again in the room of 1024, in the buffers the last run left (16384 items
        // large, full of its numbers).
        let again = run(1024).unwrap();
        assert_eq!(bits(&snug), bits(&roomy));
        assert_eq!(bits(&snug), bits(&again));
        assert_eq!(snug.camera_hits, again.camera_hits);
        assert_eq!(snug.camera_hits, roomy.camera_hits);
        assert_eq!(
            (snug.shadow_rays, snug.secondary_rays),
            (roomy.shadow_rays, roomy.secondary_rays)
        );
        assert!(snug.secondary_rays >= 512, "{}", snug.secondary_rays);
        assert!(snug.rgba.iter().all(|p| p[3] == 1.0 && p[0] > 0.0));
    }

    /// The camera rays the GPU makes (`sample_offset`'s jitter, `CameraModel::ray`, the
    /// shear) are the CPU's to the bit: perspective and orthographic cameras turned
    /// every way, one to sixteen samples, with and without an overscan border.
    #[test]
    fn camera_rays_are_the_cpus() {
        let Some(dev) = crate::gpu::test_device() else {
            return;
        };
        let shading = GpuShading::new(&dev, &[]).unwrap();
        let rotation = glam::Mat3::from_quat(
            glam::Quat::from_rotation_y(0.7)
                * glam::Quat::from_rotation_x(-0.3)
                * glam::Quat::from_rotation_z(0.1),
        );
        for ortho in [None, Some((2.0, 1.3))] {
            let camera = CameraModel {
                origin: Vec3::new(1.25, -3.5, 7.1),
                rotation,
                tan_half: 0.41,
                aspect: 37.0 / 23.0,
                ortho,
                width: 37,
                height: 23,
            };
            for (spp, overscan) in [(1, 0), (1, 3), (3, 0), (4, 2), (16, 0)] {
                let cam = camera_rays(&camera, 7, spp, overscan);
                let (w, h) = (37 + 2 * overscan, 23 + 2 * overscan);
                let gpu = shading
                    .camera_rays_made_on_gpu(&dev, &cam, u64::from(w * h))
                    .unwrap();
                assert_eq!(gpu.len() as u32, w * h * spp);
                for (s, g) in gpu.iter().enumerate() {
                    let s = s as u32;
                    let (p, k) = (s / spp, s % spp);
                    let (x, y) = (
                        (p % w).wrapping_sub(overscan),
                        (p / w).wrapping_sub(overscan),
                    );
                    let (ox, oy) = sample_offset(7, x, y, k, spp);
                    let r = camera.ray(x as i32 as f32 + ox, y as i32 as f32 + oy);
                    assert_eq!(
                        *g,
                        crate::gpu::packed_on_cpu(&r),
                        "ortho {ortho:?}, spp {spp}, overscan {overscan}: sample {k} of ({x}, {y})"
                    );
                }
            }
        }
    }

    fn scene_with(m: Material) -> Scene {
        Scene {
            materials: vec![m],
            ..Scene::default()
        }
    }

    /// `m` in a scene of two 4×2 textures: 0 opaque, green bytes 100 to 244 (a
    /// roughness texture that reaches the glossy range), 1 with alpha 128 and green
    /// bytes 110 to 254 (from 0.43: too rough to reflect).
    fn textured(m: Material) -> Scene {
        let img = |alpha: u8, g0: u8| crate::scene::Image {
            name: None,
            width: 4,
            height: 2,
            rgba8: (0..8u8)
                .flat_map(|i| [i * 30, g0 + (i % 4) * 48, 200, alpha])
                .collect(),
        };
        let tex = |image| crate::scene::Texture {
            image,
            wrap_s: crate::scene::Wrap::Repeat,
            wrap_t: crate::scene::Wrap::Repeat,
            nearest: false,
        };
        Scene {
            materials: vec![m],
            images: vec![img(255, 100), img(128, 110)],
            textures: vec![tex(0), tex(1)],
            ..Scene::default()
        }
    }

    fn why(scene: &Scene, opts: &RenderOptions) -> Option<String> {
        outside_subset(scene, opts, 10, 10, 1 << 20)
    }

    /// The shading constants shade.wgsl writes out are the CPU's.
    #[test]
    fn the_kernels_constants_are_the_cpus() {
        let src = include_str!("../gpu/shade.wgsl");
        let constant = |name: &str| -> f32 {
            let line = src
                .lines()
                .find(|l| l.starts_with(&format!("const {name}: f32 = ")))
                .unwrap_or_else(|| panic!("no {name} in shade.wgsl"));
            line.trim_end_matches(';')
                .rsplit(' ')
                .next()
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{line}"))
        };
        assert_eq!(constant("GLOSSY_LIMIT"), GLOSSY_LIMIT);
        assert_eq!(constant("MIRROR_ALPHA"), MIRROR_ALPHA);
        assert_eq!(
            constant("MAX_SHININESS"),
            ShadeContext::shininess(0.0),
            "the cap"
        );
        assert_eq!(constant("MAX_PASSES"), f32::from(MAX_PASSES));
        assert_eq!(crate::gpu::MAX_PASSES, u32::from(MAX_PASSES), "the levels");
    }

    /// Every feature the frame path does not shade sends the scene to the CPU's
    /// shading, with its name; the subset's own materials do not, textured ones
    /// included.
    #[test]
    fn the_subset_and_what_falls_back() {
        let opts = RenderOptions::default();
        let inside = [
            Material::default(),
            Material {
                roughness: 0.0,
                metallic: 1.0,
                ..Material::default()
            },
            Material {
                roughness: 0.03,
                transmission: 1.0,
                double_sided: true,
                ..Material::default()
            },
            Material {
                roughness: 0.4,
                alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
                ..Material::default()
            },
        ];
        for m in inside {
            assert_eq!(why(&scene_with(m.clone()), &opts), None, "{m:?}");
        }
        let tex = |texture| {
            Some(TextureRef {
                texture,
                tex_coord: 0,
                transform: None,
            })
        };
        let textured_inside = [
            Material {
                base_color_texture: tex(0),
                normal_texture: tex(1),
                emissive_texture: tex(0),
                ..Material::default()
            },
            // An opaque texture under MASK and BLEND: the factor decides.
            Material {
                base_color_texture: tex(0),
                alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
                ..Material::default()
            },
            Material {
                base_color_texture: tex(0),
                alpha_mode: AlphaMode::Blend,
                ..Material::default()
            },
            // Roughness from 0.43 on: no reflection ray anywhere.
            Material {
                metallic_roughness_texture: tex(1),
                ..Material::default()
            },
            // A roughness factor that keeps every texel a mirror.
            Material {
                roughness: 0.03,
                metallic_roughness_texture: tex(0),
                ..Material::default()
            },
            // A texture the CPU does not read (no such texture): as without.
            Material {
                base_color_texture: tex(7),
                ..Material::default()
            },
            // A roughness that is glossy at some texels (a hit's own reflection ray).
            Material {
                metallic_roughness_texture: tex(0),
                ..Material::default()
            },
            // An emissive texture on a material that does not emit.
            Material {
                emissive_texture: tex(0),
                ..Material::default()
            },
        ];
        for m in textured_inside {
            assert_eq!(why(&textured(m.clone()), &opts), None, "{m:?}");
        }
        // Alpha below 1 (pass-through rays), from the factor or from the texture; the
        // table marks the materials that may pass rays through (the levels encoded).
        let half = glam::Vec4::new(1.0, 1.0, 1.0, 0.5);
        let alpha = [
            (
                textured(Material {
                    base_color_texture: tex(1),
                    alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
                    ..Material::default()
                }),
                [1.0, 0.5, 1.0, 1.0],
            ),
            (
                textured(Material {
                    base_color_texture: tex(0),
                    base_color: half,
                    alpha_mode: AlphaMode::Blend,
                    ..Material::default()
                }),
                [0.5, 0.0, 2.0, 1.0],
            ),
            (
                scene_with(Material {
                    base_color: half,
                    alpha_mode: AlphaMode::Mask { cutoff: 0.6 },
                    ..Material::default()
                }),
                [0.5, 0.6, 1.0, 1.0],
            ),
            // Opaque under MASK (the factor over the cutoff, the texture opaque).
            (
                textured(Material {
                    base_color_texture: tex(0),
                    base_color: half,
                    alpha_mode: AlphaMode::Mask { cutoff: 0.4 },
                    ..Material::default()
                }),
                [0.5, 0.4, 1.0, 0.0],
            ),
            (scene_with(Material::default()), [1.0, 0.0, 0.0, 0.0]),
        ];
        for (scene, table) in alpha {
            assert_eq!(why(&scene, &opts), None, "{:?}", scene.materials[0]);
            assert_eq!(
                materials(&scene)[0].alpha,
                table,
                "{:?}",
                scene.materials[0]
            );
        }
        // An area light with an emissive texture is inside (its samples read it).
        let lamp = textured(Material {
            emissive: Vec3::ONE,
            emissive_texture: tex(0),
            ..Material::default()
        });
        assert_eq!(why(&lamp, &opts), None);
        // Asked to shade on the CPU: outside, saying so.
        let asked = RenderOptions {
            cpu_shading: true,
            ..RenderOptions::default()
        };
        assert!(why(&lamp, &asked)
            .unwrap_or_default()
            .contains("SUBFIELD_GPU_SHADING=cpu"));
        // A material's own ambient colour is inside.
        let aff = scene_with(Material {
            ambient: Some(Vec3::ONE),
            ..Material::default()
        });
        assert_eq!(why(&aff, &opts), None);
        assert_eq!(materials(&aff)[0].aff, [1.0; 4]);
        // Glossy (GGX) reflection is inside: its numbers come from the items' seeds.
        let glossy = Material {
            roughness: 0.2,
            ..Material::default()
        };
        assert_eq!(why(&scene_with(glossy.clone()), &opts), None);
        assert_eq!(materials(&scene_with(glossy))[0].reflects, 2);
        // So are area lights, up to the samples a pixel their strata are numbered for.
        let lamp = scene_with(Material {
            emissive: Vec3::new(0.0, 0.0, 1.0),
            ..Material::default()
        });
        assert_eq!(why(&lamp, &opts), None);
        let many = RenderOptions {
            spp: MAX_AREA_SPP + 1,
            ..RenderOptions::default()
        };
        assert!(why(&lamp, &many)
            .unwrap()
            .contains("area lights at more than"));
        assert_eq!(why(&scene_with(Material::default()), &many), None);
        // Textures larger than one binding: the levels of 4×2, 2×1 and 1×1 texels in
        // each of two views (sRGB and linear), 88 bytes.
        let both = textured(Material {
            base_color_texture: tex(0),
            normal_texture: tex(0),
            ..Material::default()
        });
        assert_eq!(texel_count(&both), 2 * (8 + 2 + 1));
        let small = outside_subset(&both, &opts, 10, 10, 80);
        assert!(
            small
                .as_deref()
                .unwrap_or_default()
                .contains("the textures (88 bytes"),
            "{small:?}"
        );
        let plain = scene_with(Material::default());
        let blur = RenderOptions {
            motion_blur: Some(MotionBlur {
                shutter: 0.5,
                steps: 3,
            }),
            ..RenderOptions::default()
        };
        // Motion blur is inside: each time step a pass of its own samples.
        assert_eq!(why(&plain, &blur), None);
        let mut paths = RenderOptions::default();
        paths.aovs.specular = true;
        // The light-path passes are inside.
        assert_eq!(why(&plain, &paths), None);
        let mut bounces = RenderOptions::default();
        bounces.shading.diffuse_bounces = 1;
        // Diffuse bounces are inside.
        assert_eq!(why(&plain, &bounces), None);
        let big = outside_subset(&plain, &RenderOptions::default(), 1 << 20, 0, 1 << 20);
        assert!(big.unwrap().contains("static triangles' surfaces"));
    }
}
