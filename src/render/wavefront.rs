//! One frame traced as a wavefront (see `shade`): camera rays made per sample, each
//! depth level traced as one batch and shaded in parallel blocks, the shadow rays traced
//! one batch per light, the AOVs from the pixel-centre rays; and the frame's buffers,
//! ray counts and times.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::aov::{project, rank, CryptoNames};
use super::camera::CameraModel;
use super::memo::{lights_kept, Mode, StaticMemo};
use super::options::Aovs;
use super::sampling::Seed;
use super::shade::{
    BlockOut, Cone, CryptoBuffers, FrameBuffers, FrameWork, Item, LightPathBuffers, ShadeContext,
    Split,
};
use crate::geometry::{Hit, Intersector, Ray};
use crate::psf::Prim;
use crate::scene::TriangleSoup;

/// Which AOVs a frame has, what those beyond the shading need (given only when they
/// are asked for), and the border traced beyond the image.
#[derive(Clone, Copy, Default)]
pub struct AovInputs<'a> {
    pub aovs: Aovs,
    /// `--overscan`: pixels traced beyond every edge of the image, on the same image
    /// plane (pixel `(x, y)` of the border is the camera's pixel `(x, y)`, `x` from
    /// `−overscan`), so the image's own pixels are the frame without it, to the bit.
    pub overscan: u32,
    /// For `motion`: the moving triangles posed at the next frame's time (same order as
    /// this frame's) and the camera of that time.
    pub next: Option<(&'a TriangleSoup, CameraModel)>,
    /// For `cryptomatte`: the ids of the scene's nodes and materials.
    pub crypto: Option<&'a CryptoNames>,
}

/// Rays shaded by one task.
const BLOCK: usize = 1024;
/// Samples traced together (bounds the wavefront's memory).
const CHUNK_SAMPLES: usize = 1 << 18;

/// A frame's working buffers, kept from one frame to the next by a sequence
/// ([`render_frame_with`]): their capacity stays, so once the first frame is done a
/// frame's wavefront allocates nothing large, and the kernel zeroes no fresh pages for
/// it (the page faults of a frame's 80 MB or so of fresh buffers were a tenth of the
/// CPU time of a 640x480 frame; `benches/PERF.md`, issue 23, step 2). The frame's own image
/// buffers are handed back through [`recycle`](Self::recycle) once written.
#[derive(Default)]
pub struct FrameScratch {
    rays: Vec<Ray>,
    items: Vec<Item>,
    hits: Vec<Option<Hit>>,
    radiance: Vec<Vec3>,
    /// Each sample's radiance split over the light-path passes (when traced).
    paths: Vec<Split>,
    coverage: Vec<f32>,
    outs: Vec<BlockOut>,
    shadow_rays: Vec<Ray>,
    shadow_add: Vec<(u32, Vec3)>,
    shadow_split: Vec<Split>,
    /// Where each light's shadow rays start in `shadow_rays` (and end: one more).
    light_start: Vec<usize>,
    blocked: Vec<bool>,
    spare: Option<FrameBuffers>,
    /// The static answers of the last frame's camera and shadow rays.
    memo: StaticMemo,
}

impl FrameScratch {
    /// Keeps a written frame's buffers for the next frame of the same size and AOVs.
    pub fn recycle(&mut self, fb: FrameBuffers) {
        self.spare = Some(fb);
    }
}

/// `v` as `n` copies of `x`, reusing its allocation.
fn refill<T: Clone>(v: &mut Vec<T>, n: usize, x: T) {
    v.clear();
    v.resize(n, x);
}

/// `v` (`Some` when wanted) as `n` copies of `x`, reusing `old`'s allocation.
fn refill_opt<T: Clone>(old: Option<Vec<T>>, wanted: bool, n: usize, x: T) -> Option<Vec<T>> {
    wanted.then(|| {
        let mut v = old.unwrap_or_default();
        refill(&mut v, n, x);
        v
    })
}

/// A 64-bit mix of the inputs (SplitMix64 finaliser over a running combination).
fn hash(values: [u32; 4]) -> u64 {
    let mut h = 0x9E37_79B9_7F4A_7C15u64;
    for v in values {
        h ^= u64::from(v);
        h = h.wrapping_add(0x9E37_79B9_7F4A_7C15);
        h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 31;
    }
    h
}

/// Position of sample `k` of `spp` inside pixel `(x, y)` of `frame`, in `[0, 1)²`:
/// the centre for one sample, else a jittered point in cell `k` of a
/// `ceil(√spp) × ceil(spp / ceil(√spp))` grid.
pub fn sample_offset(frame: u32, x: u32, y: u32, k: u32, spp: u32) -> (f32, f32) {
    if spp <= 1 {
        return (0.5, 0.5);
    }
    let sx = (spp as f64).sqrt().ceil() as u32;
    let sy = spp.div_ceil(sx);
    let h = hash([frame, x, y, k]);
    let rx = (h >> 40) as f32 / (1u64 << 24) as f32;
    let ry = ((h >> 16) & 0xFF_FFFF) as f32 / (1u64 << 24) as f32;
    (
        (((k % sx) as f32 + rx) / sx as f32).min(0.999_999_9),
        (((k / sx) as f32 + ry) / sy as f32).min(0.999_999_9),
    )
}

/// Where sample `s` of a chunk is: pixel `(x, y)` and its sample `k`, stepped forward
/// one sample at a time (the samples of a pixel, then the pixels of a row, then rows).
#[derive(Clone, Copy)]
struct PixelWalk {
    x: u32,
    y: u32,
    k: u32,
    w: u32,
    spp: u32,
}

impl PixelWalk {
    /// Sample `s` of the chunk whose first pixel is `px0`, in an image `w` wide with
    /// `spp` samples a pixel.
    fn at(px0: usize, s: usize, w: usize, spp: usize) -> PixelWalk {
        let p = px0 + s / spp;
        PixelWalk {
            x: (p % w) as u32,
            y: (p / w) as u32,
            k: (s % spp) as u32,
            w: w as u32,
            spp: spp as u32,
        }
    }

    #[inline]
    fn advance(&mut self) {
        self.k += 1;
        if self.k == self.spp {
            self.k = 0;
            self.x += 1;
            if self.x == self.w {
                self.x = 0;
                self.y += 1;
            }
        }
    }
}

/// The cone of a camera ray: a pixel wide, from a point (perspective: the angle a pixel
/// spans at the image centre) or a pixel wide and parallel (orthographic).
fn primary_cone(camera: &CameraModel) -> Cone {
    let h = camera.height.max(1) as f32;
    match camera.ortho {
        Some((_, ymag)) => Cone {
            width: 2.0 * ymag / h,
            spread: 0.0,
        },
        None => Cone {
            width: 0.0,
            spread: 2.0 * camera.tan_half / h,
        },
    }
}

/// Traces and shades one frame.
pub fn render_frame<T: Intersector>(
    ctx: &ShadeContext<'_>,
    tracer: &T,
    camera: &CameraModel,
    frame: u32,
    spp: u32,
    max_depth: u32,
    inputs: &AovInputs<'_>,
) -> (FrameBuffers, FrameWork) {
    let mut scratch = FrameScratch::default();
    render_frame_with(
        &mut scratch,
        ctx,
        tracer,
        camera,
        frame,
        spp,
        max_depth,
        inputs,
    )
}

/// [`render_frame`] with working buffers kept from the frame before (a sequence's).
/// The frame is the same whatever `scratch` held.
#[allow(clippy::too_many_arguments)]
pub fn render_frame_with<T: Intersector>(
    scratch: &mut FrameScratch,
    ctx: &ShadeContext<'_>,
    tracer: &T,
    camera: &CameraModel,
    frame: u32,
    spp: u32,
    max_depth: u32,
    inputs: &AovInputs<'_>,
) -> (FrameBuffers, FrameWork) {
    let aovs = inputs.aovs;
    // The buffers cover the data window: the image and the overscan border. Pixel
    // `(x, y)` of the buffers is the camera's pixel `(x − o, y − o)`.
    let o = inputs.overscan as usize;
    let (w, h) = (
        camera.width as usize + 2 * o,
        camera.height as usize + 2 * o,
    );
    let spp = spp.max(1) as usize;
    let mut work = FrameWork::default();
    let spare = scratch.spare.take().filter(|f| {
        f.width == camera.width && f.height == camera.height && f.overscan == inputs.overscan
    });
    let (rgba, depth, normal, albedo, position, motion, kept_paths) = match spare {
        Some(f) => (
            f.rgba,
            f.depth,
            f.normal,
            f.albedo,
            f.position,
            f.motion,
            f.light_paths,
        ),
        None => Default::default(),
    };
    let mut rgba = rgba;
    refill(&mut rgba, w * h, [0.0; 4]);
    let light_paths = aovs.any_light_path();
    let mut fb = FrameBuffers {
        width: camera.width,
        height: camera.height,
        rgba,
        depth: refill_opt(depth, aovs.depth, w * h, f32::INFINITY),
        normal: refill_opt(normal, aovs.normal, w * h, [0.0; 3]),
        albedo: refill_opt(albedo, aovs.albedo, w * h, [0.0; 3]),
        position: refill_opt(position, aovs.position, w * h, [0.0; 3]),
        motion: refill_opt(motion, aovs.motion, w * h, [0.0; 2]),
        crypto: None,
        light_paths: light_paths.then(|| {
            let mut passes = kept_paths.map(|p| p.passes).unwrap_or_default();
            for p in &mut passes {
                refill(p, w * h, [0.0; 3]);
            }
            LightPathBuffers {
                passes,
                written: aovs.light_paths(),
            }
        }),
        overscan: inputs.overscan,
    };
    let FrameScratch {
        rays,
        items,
        hits,
        radiance,
        paths,
        coverage,
        outs,
        shadow_rays,
        shadow_add,
        shadow_split,
        light_start,
        blocked,
        spare: _,
        memo,
    } = scratch;
    let layers = tracer.layers();
    let mode = memo.begin(camera, spp, w * h, layers.is_some());
    let crypto = inputs.crypto.filter(|_| aovs.cryptomatte);
    let levels = aovs.crypto_levels.max(1) as usize;
    if crypto.is_some() {
        fb.crypto = Some(CryptoBuffers {
            levels,
            object: vec![(0.0, 0.0); w * h * levels],
            material: vec![(0.0, 0.0); w * h * levels],
        });
    }
    let any_aov = aovs.any_centre();
    let aov_inputs = CentreInputs {
        camera,
        next: inputs.next.filter(|_| aovs.motion),
    };
    // The camera's pixel of buffer column or row `i` (negative in the border), as the
    // hashes of the jitter and the seeds take it (wrapping: the image's own pixels keep
    // the numbers they have without overscan).
    let pixel = |i: u32| i.wrapping_sub(o as u32);
    let rows_per_chunk = (CHUNK_SAMPLES / (w * spp)).max(1);
    let mut y0 = 0;
    while y0 < h {
        let y1 = (y0 + rows_per_chunk).min(h);
        let px0 = y0 * w;
        let npix = (y1 - y0) * w;
        let nsamples = npix * spp;

        // Primary rays.
        let clock = Instant::now();
        // In parallel into the kept buffer, each task stepping through its pixels and
        // samples without dividing (integer division was a tenth of the rays' making),
        // and without filling the buffer first (a serial pass over 10 MB a frame).
        let walk = |s: usize| PixelWalk::at(px0, s, w, spp);
        rays.clear();
        rays.par_extend((0..nsamples).into_par_iter().with_min_len(BLOCK).map_init(
            || None,
            |state: &mut Option<(usize, PixelWalk)>, s| {
                // A task's samples come in order: step from the last one.
                let at = match state.take() {
                    Some((next, at)) if next == s => at,
                    _ => walk(s),
                };
                let (x, y) = (pixel(at.x), pixel(at.y));
                let (ox, oy) = sample_offset(frame, x, y, at.k, spp as u32);
                let ray = camera.ray(x as i32 as f32 + ox, y as i32 as f32 + oy);
                let mut next = at;
                next.advance();
                *state = Some((s + 1, next));
                ray
            },
        ));
        let cone = primary_cone(camera);
        // A camera ray's bookkeeping, made where it is shaded rather than stored: a
        // frame's 300,000 of them were 15 MB written and read again for values that
        // follow from the sample's number (`benches/PERF.md`, issue 23, step 7).
        let primary_item = |s: usize, at: &PixelWalk| Item {
            sample: s as u32,
            weight: Vec3::ONE,
            coverage: 1.0,
            depth: 0,
            passes: 0,
            bounces: 0,
            diffuse: false,
            seed: Seed::camera(frame, pixel(at.x), pixel(at.y), at.k),
            cone,
            path: None,
        };
        items.clear();
        work.rays.primary += nsamples as u64;
        refill(radiance, nsamples, Vec3::ZERO);
        if light_paths {
            refill(paths, nsamples, [Vec3::ZERO; 4]);
        }
        refill(coverage, nsamples, 0.0f32);
        work.shade += clock.elapsed();

        let mut first = true;
        while !rays.is_empty() {
            let clock = Instant::now();
            hits.clear();
            hits.par_extend(
                (0..rays.len())
                    .into_par_iter()
                    .with_min_len(4 * BLOCK)
                    .map(|_| None),
            );
            // The camera rays and their shadow rays, through what the memo keeps where
            // it serves; any other batch through the whole.
            let memo_layers = layers.filter(|_| first && mode != Mode::Off);
            match memo_layers {
                Some(l) => {
                    let whole = |r: &[Ray], h: &mut [Option<Hit>]| tracer.intersect_batch(r, h);
                    memo.primary(mode, l, &whole, px0, rays, hits)
                }
                None => tracer.intersect_batch(rays, hits),
            }
            work.trace += clock.elapsed();

            let clock = Instant::now();
            if first && any_aov {
                // The centre rays: the primary rays themselves with one sample, else
                // their own batch (traced below).
                if spp == 1 {
                    write_aovs(ctx, &aov_inputs, &mut fb, px0, rays, hits);
                }
            }
            if first {
                if let (Some(names), Some(buf)) = (crypto, fb.crypto.as_mut()) {
                    // The primary rays are the samples in order: rank each pixel's.
                    write_crypto(ctx, names, buf, px0, spp, hits);
                }
            }
            let blocks = rays.len().div_ceil(BLOCK);
            if outs.len() < blocks {
                outs.resize_with(blocks, BlockOut::default);
            }
            if first {
                // The camera rays: ray `i` is sample `i`.
                outs[..blocks]
                    .par_iter_mut()
                    .zip(rays.par_chunks(BLOCK))
                    .zip(hits.par_chunks(BLOCK))
                    .enumerate()
                    .for_each(|(b, ((out, r), hs))| {
                        out.clear();
                        out.light_paths = light_paths;
                        let mut at = walk(b * BLOCK);
                        for (k, (ray, hit)) in r.iter().zip(hs).enumerate() {
                            let item = primary_item(b * BLOCK + k, &at);
                            ctx.shade(ray, &item, *hit, max_depth, spp as u32, out);
                            at.advance();
                        }
                    });
            } else {
                outs[..blocks]
                    .par_iter_mut()
                    .zip(rays.par_chunks(BLOCK))
                    .zip(items.par_chunks(BLOCK))
                    .zip(hits.par_chunks(BLOCK))
                    .for_each(|(((out, r), it), hs)| {
                        out.clear();
                        out.light_paths = light_paths;
                        for ((ray, item), hit) in r.iter().zip(it).zip(hs) {
                            ctx.shade(ray, item, *hit, max_depth, spp as u32, out);
                        }
                    });
            }
            first = false;
            // The blocks' lists gathered in block order, the shadow side and the rest
            // as two tasks (each list in the same order either way).
            let outs = &outs[..blocks];
            rayon::join(
                || {
                    // A light's rays together, in block order: each light's rays are
                    // one batch through its point grid (which a batch mixing lights
                    // would not get).
                    shadow_rays.clear();
                    shadow_add.clear();
                    shadow_split.clear();
                    light_start.clear();
                    let lights = outs.iter().map(|o| o.shadow.len()).max().unwrap_or(0);
                    for l in 0..lights {
                        light_start.push(shadow_rays.len());
                        for list in outs.iter().filter_map(|o| o.shadow.get(l)) {
                            shadow_rays.extend_from_slice(&list.rays);
                            shadow_add.extend_from_slice(&list.add);
                            shadow_split.extend_from_slice(&list.split);
                        }
                    }
                    light_start.push(shadow_rays.len());
                },
                || {
                    rays.clear();
                    items.clear();
                    for o in outs {
                        for &(s, c) in &o.add {
                            radiance[s as usize] += c;
                        }
                        for (s, split) in &o.split {
                            let p = &mut paths[*s as usize];
                            for (p, c) in p.iter_mut().zip(split) {
                                *p += *c;
                            }
                        }
                        for &(s, c) in &o.cover {
                            coverage[s as usize] += c;
                        }
                        rays.extend_from_slice(&o.next_rays);
                        items.extend_from_slice(&o.next_items);
                    }
                },
            );
            work.rays.secondary += rays.len() as u64;
            work.rays.shadow += shadow_rays.len() as u64;
            work.shade += clock.elapsed();

            let clock = Instant::now();
            refill(blocked, shadow_rays.len(), false);
            for (l, span) in light_start.windows(2).enumerate() {
                let (a, b) = (span[0], span[1]);
                if a >= b {
                    continue;
                }
                match memo_layers {
                    Some(layers) if l < ctx.punctual_lights().min(lights_kept(w * h)) => memo
                        .shadows(
                            layers,
                            &|r: &[Ray], b: &mut [bool]| tracer.occluded_batch(r, b),
                            l,
                            px0,
                            w * h,
                            &shadow_rays[a..b],
                            &shadow_add[a..b],
                            &mut blocked[a..b],
                        ),
                    _ => tracer.occluded_batch(&shadow_rays[a..b], &mut blocked[a..b]),
                }
            }
            work.trace += clock.elapsed();

            let clock = Instant::now();
            for (&(s, c), &b) in shadow_add.iter().zip(blocked.iter()) {
                if !b {
                    radiance[s as usize] += c;
                }
            }
            if light_paths {
                for ((&(s, _), split), &b) in shadow_add.iter().zip(&*shadow_split).zip(&*blocked) {
                    if !b {
                        let p = &mut paths[s as usize];
                        for (p, c) in p.iter_mut().zip(split) {
                            *p += *c;
                        }
                    }
                }
            }
            work.shade += clock.elapsed();
        }

        if any_aov && spp > 1 {
            let clock = Instant::now();
            let centre: Vec<Ray> = (0..npix)
                .into_par_iter()
                .with_min_len(BLOCK)
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
            tracer.intersect_batch(&centre, &mut chits);
            work.trace += clock.elapsed();
            let clock = Instant::now();
            write_aovs(ctx, &aov_inputs, &mut fb, px0, &centre, &chits);
            work.shade += clock.elapsed();
        }

        let clock = Instant::now();
        let inv = 1.0 / spp as f32;
        fb.rgba[px0..px0 + npix]
            .par_iter_mut()
            .enumerate()
            .with_min_len(BLOCK)
            .for_each(|(i, px)| {
                let mut c = Vec3::ZERO;
                let mut a = 0.0;
                for s in i * spp..(i + 1) * spp {
                    c += radiance[s];
                    a += coverage[s];
                }
                let c = c * inv;
                *px = [c.x, c.y, c.z, (a * inv).min(1.0)];
            });
        if let Some(lp) = &mut fb.light_paths {
            // Each pass averaged as the beauty is: so they add up to it, to the order of
            // the float additions.
            for (k, pass) in lp.passes.iter_mut().enumerate() {
                pass[px0..px0 + npix]
                    .par_iter_mut()
                    .enumerate()
                    .with_min_len(BLOCK)
                    .for_each(|(i, px)| {
                        let mut c = Vec3::ZERO;
                        for split in &paths[i * spp..(i + 1) * spp] {
                            c += split[k];
                        }
                        *px = (c * inv).to_array();
                    });
            }
        }
        work.shade += clock.elapsed();
        y0 = y1;
    }
    memo.end(mode);
    (fb, work)
}

/// What the centre-ray AOVs read besides the shading context.
struct CentreInputs<'a> {
    camera: &'a CameraModel,
    next: Option<(&'a TriangleSoup, CameraModel)>,
}

/// Screen motion of the centre ray's hit to the next frame: the hit point carried by its
/// own triangle (a static one stays; a moving one is posed at the next time with the
/// same barycentrics), projected by the next frame's camera, minus its projection now.
fn motion_of(ctx: &ShadeContext<'_>, inp: &CentreInputs<'_>, hit: &Hit, point: Vec3) -> [f32; 2] {
    let Some((next_soup, next_cam)) = &inp.next else {
        return [0.0; 2];
    };
    let later = match Prim::from_index(hit.tri, ctx.static_soup.len()) {
        Prim::Static(_) => point,
        Prim::Moving(i) => match next_soup.positions.get(i as usize) {
            Some(p) => p[0] * (1.0 - hit.u - hit.v) + p[1] * hit.u + p[2] * hit.v,
            None => point,
        },
    };
    match (project(inp.camera, point), project(next_cam, later)) {
        (Some(a), Some(b)) => (b - a).to_array(),
        _ => [0.0; 2],
    }
}

/// AOVs of the pixels `px0..px0 + rays.len()` from their centre rays.
fn write_aovs(
    ctx: &ShadeContext<'_>,
    inp: &CentreInputs<'_>,
    fb: &mut FrameBuffers,
    px0: usize,
    rays: &[Ray],
    hits: &[Option<Hit>],
) {
    let n = rays.len();
    if let Some(depth) = &mut fb.depth {
        depth[px0..px0 + n]
            .par_iter_mut()
            .zip(rays.par_iter().zip(hits))
            .for_each(|(z, (r, h))| {
                *z = h.map_or(f32::INFINITY, |h| h.t * r.dir.length());
            });
    }
    if fb.normal.is_none() && fb.albedo.is_none() && fb.position.is_none() && fb.motion.is_none() {
        return;
    }
    let motion = fb.motion.is_some();
    let vals: Vec<(super::shade::CentreAov, [f32; 2])> = rays
        .par_iter()
        .zip(hits)
        .with_min_len(BLOCK)
        .map(|(r, h)| match h {
            None => Default::default(),
            Some(h) => {
                let a = ctx.aov(r, h);
                let m = if motion {
                    motion_of(ctx, inp, h, a.point)
                } else {
                    [0.0; 2]
                };
                (a, m)
            }
        })
        .collect();
    if let Some(normal) = &mut fb.normal {
        for (d, v) in normal[px0..px0 + n].iter_mut().zip(&vals) {
            *d = v.0.normal;
        }
    }
    if let Some(albedo) = &mut fb.albedo {
        for (d, v) in albedo[px0..px0 + n].iter_mut().zip(&vals) {
            *d = v.0.albedo;
        }
    }
    if let Some(position) = &mut fb.position {
        for (d, v) in position[px0..px0 + n].iter_mut().zip(&vals) {
            *d = v.0.point.to_array();
        }
    }
    if let Some(m) = &mut fb.motion {
        for (d, v) in m[px0..px0 + n].iter_mut().zip(&vals) {
            *d = v.1;
        }
    }
}

/// Cryptomatte ranks of the pixels from `px0` on, from the primary hits of all their
/// samples (`spp` a pixel, in order).
fn write_crypto(
    ctx: &ShadeContext<'_>,
    names: &CryptoNames,
    buf: &mut CryptoBuffers,
    px0: usize,
    spp: usize,
    hits: &[Option<Hit>],
) {
    let levels = buf.levels;
    let npix = hits.len() / spp;
    let range = px0 * levels..(px0 + npix) * levels;
    buf.object[range.clone()]
        .par_chunks_mut(levels)
        .zip(buf.material[range].par_chunks_mut(levels))
        .zip(hits.par_chunks(spp))
        .with_min_len(BLOCK / spp.max(1) + 1)
        .for_each(|((obj, mat), hs)| {
            let ids: Vec<Option<(u32, u32)>> =
                hs.iter().map(|h| h.and_then(|h| ctx.ids(&h))).collect();
            let lookup = |kind: &[u32], i: u32| kind.get(i as usize).copied();
            let o: Vec<Option<u32>> = ids
                .iter()
                .map(|x| x.and_then(|(n, _)| lookup(&names.object.ids, n)))
                .collect();
            let m: Vec<Option<u32>> = ids
                .iter()
                .map(|x| x.and_then(|(_, m)| lookup(&names.material.ids, m)))
                .collect();
            rank(&o, levels, obj);
            rank(&m, levels, mat);
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_are_stratified_and_centred_for_one() {
        assert_eq!(sample_offset(3, 1, 2, 0, 1), (0.5, 0.5));
        let mut cells = [false; 4];
        for k in 0..4 {
            let (x, y) = sample_offset(7, 10, 20, k, 4);
            assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
            cells[(x * 2.0) as usize + 2 * (y * 2.0) as usize] = true;
        }
        assert!(cells.iter().all(|&c| c), "one sample in each quarter");
        assert_ne!(
            sample_offset(7, 10, 20, 0, 4),
            sample_offset(8, 10, 20, 0, 4)
        );
    }
}
