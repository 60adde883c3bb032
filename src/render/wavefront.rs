//! One frame traced as a wavefront (see `shade`): camera rays made per sample, each
//! depth level traced as one batch and shaded in parallel blocks, the shadow rays traced
//! one batch per light, the AOVs from the pixel-centre rays; and the frame's buffers,
//! ray counts and times.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::aov::{project, rank, CryptoNames};
use super::camera::CameraModel;
use super::memo::{levels_kept, lights_kept, Mode, StaticMemo};
use super::options::Aovs;
use super::replay::{
    block_records, block_slots, record_block, shade_kept, BlockSlots, ShadeReplay, PREFETCH_AHEAD,
};
use super::sampling::Seed;
use super::shade::{
    BlockOut, Cone, CryptoBuffers, FrameBuffers, FrameWork, Item, LightPathBuffers, ShadeContext,
    Split,
};
use super::stats::Kept;
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
/// Samples traced together (bounds the wavefront's memory), unless the options say
/// otherwise ([`RenderOptions::chunk_samples`](super::RenderOptions::chunk_samples)):
/// 2^19 traces a 640x480 frame as one chunk. Each chunk's batches pay their own set-up
/// (the point grids' plans, a few ms a batch): with 2^18 a 640x480 frame was two
/// chunks, and one chunk made 24-frame renders on 2 threads 6-7 % faster, at 1080p 3 %
/// (benches/PERF.md, issue 38, round 5; round 3 had found no difference).
const CHUNK_SAMPLES: usize = 1 << 19;

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
    /// The last level's blocks, where a level's rays are traced from the blocks' own
    /// lists (`trace_pass`: a camera that moves); swapped with `outs` a level at a time.
    outs_prev: Vec<BlockOut>,
    shadow_rays: Vec<Ray>,
    shadow_add: Vec<(u32, Vec3)>,
    shadow_split: Vec<Split>,
    /// Where each light's shadow rays start in `shadow_rays` (and end: one more).
    light_start: Vec<usize>,
    blocked: Vec<bool>,
    spare: Option<FrameBuffers>,
    /// The static answers of the last frame's camera and shadow rays.
    memo: StaticMemo,
    /// The last frame's shading, where a still camera's rays repeat.
    replay: ShadeReplay,
    /// Motion blur: the time step of each of the frame's samples, the samples of a
    /// chunk a step traces (chunk numbers), and each sample's Cryptomatte ids (object,
    /// material) until every step has traced.
    sample_steps: Vec<u8>,
    picked: Vec<u32>,
    crypto_ids: Vec<[Option<u32>; 2]>,
    /// Samples a chunk traces at most (0: [`CHUNK_SAMPLES`]).
    chunk_samples: usize,
    /// The memory the replay's slots may take (0, the default: none, the records alone).
    replay_bytes: usize,
}

impl FrameScratch {
    /// Buffers that trace `chunk_samples` samples at a time at most (0: the default,
    /// 2^19), and whose still camera's kept shading may take `replay_bytes` in slots (0,
    /// the default: none, only the records of the samples that settle are kept, see
    /// `render::replay`); the pixels depend on neither.
    pub fn with_budgets(chunk_samples: usize, replay_bytes: usize) -> FrameScratch {
        FrameScratch {
            chunk_samples,
            replay_bytes,
            ..FrameScratch::default()
        }
    }

    /// Whether this scratch keeps a whole frame's static hits for `camera`'s rays.
    pub(super) fn keeps_for(&self, camera: &CameraModel) -> bool {
        self.memo.holds(&camera.bits())
    }

    /// Takes the static hits and the shading `from` keeps (another frame in flight's),
    /// so that a frame through the same camera reuses them without filling its own.
    pub(super) fn copy_kept(&mut self, from: &FrameScratch) {
        self.memo.copy_kept(&from.memo);
        self.replay.copy_kept(&from.replay);
    }

    /// Keeps a written frame's buffers for the next frame of the same size and AOVs.
    pub fn recycle(&mut self, fb: FrameBuffers) {
        self.spare = Some(fb);
    }

    /// A blurred frame's samples of step `k` among the `n` from sample `base` on (chunk
    /// numbers, ascending), as `trace_pass` picks them (`begin_blurred`'s steps).
    #[cfg(feature = "gpu")]
    pub(super) fn step_samples(&self, base: usize, n: usize, k: u32) -> Vec<u32> {
        let steps = self.sample_steps.get(base..base + n).unwrap_or_default();
        steps
            .iter()
            .enumerate()
            .filter(|(_, &st)| u32::from(st) == k)
            .map(|(s, _)| s as u32)
            .collect()
    }

    /// Keeps the Cryptomatte ids of a step's samples `sel` (chunk numbers from sample
    /// `base`) from their camera hits, for `finish_blurred`.
    #[cfg(feature = "gpu")]
    pub(super) fn keep_step_crypto(
        &mut self,
        ctx: &ShadeContext<'_>,
        names: &CryptoNames,
        base: usize,
        sel: &[u32],
        hits: &[Option<Hit>],
    ) {
        keep_crypto_ids(ctx, names, &mut self.crypto_ids, base, sel, hits);
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
pub(super) fn primary_cone(camera: &CameraModel) -> Cone {
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
    let mut fb = scratch.buffers(camera, inputs);
    let mut work = FrameWork::default();
    let frame = FrameArgs {
        camera,
        frame,
        spp,
        max_depth,
        inputs,
        still_ahead: false,
    };
    trace_pass(scratch, &mut fb, &mut work, ctx, tracer, &frame, None);
    (fb, work)
}

/// A frame's values that every pass of it shares.
pub(super) struct FrameArgs<'a> {
    /// The camera of the pass (of its time, with motion blur).
    pub camera: &'a CameraModel,
    pub frame: u32,
    pub spp: u32,
    pub max_depth: u32,
    pub inputs: &'a AovInputs<'a>,
    /// The camera is the same to the bit at the frame this one's sequence renders
    /// next: only then does a frame fill the memo of static hits and keep its shading
    /// for the replay, for that frame to reuse (see `trace_pass`).
    pub still_ahead: bool,
}

/// One pass of a frame traced in time steps (motion blur, see
/// [`begin_blurred`]): the samples of step `samples` (none for `None`) and, with `aovs`,
/// the pixel-centre AOV rays, all through the scene posed at that step's time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct StepPass {
    pub samples: Option<u32>,
    pub aovs: bool,
}

/// Kensler's hashed permutation of `0..l` ("Correlated Multi-Jittered Sampling", Pixar
/// 2013): `i` in `0..l` goes to a distinct value in `0..l` chosen by `p` (cycle-walking
/// on the next power of two).
fn permute(mut i: u32, l: u32, p: u32) -> u32 {
    if l <= 1 {
        return 0;
    }
    let mut w = l - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    loop {
        i ^= p;
        i = i.wrapping_mul(0xe170_893d);
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i = i.wrapping_mul(0x0929_eb3f);
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i = i.wrapping_mul(1 | p >> 27);
        i = i.wrapping_mul(0x6935_fa69);
        i ^= (i & w) >> 11;
        i = i.wrapping_mul(0x74dc_b303);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0x9e50_1cc3);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0xc860_a3df);
        i &= w;
        i ^= i >> 5;
        if i < l {
            break;
        }
    }
    i.wrapping_add(p) % l
}

/// Salt of the step hash, beyond any sample number (`--spp` is at most 65536), so that
/// it is not the hash of a sample's jitter.
const STEP_SALT: u32 = 0x5173_0000;

/// Which of `steps` time steps sample `k` (of `spp`) of pixel `(x, y)` of `frame` traces:
/// the pixel's samples, in an order shuffled per pixel, dealt over the steps in turn from
/// a step drawn per pixel. So every step gets `spp / steps` samples of the pixel or one
/// more; with fewer samples than steps, neighbouring pixels cover the other steps; and a
/// step's samples are not those of one column of the jitter grid (which dealing them in
/// sample order would give when the grid is as wide as the step count).
pub fn sample_step(frame: u32, x: u32, y: u32, k: u32, spp: u32, steps: u32) -> u32 {
    let steps = steps.max(1);
    let h = hash([frame, x, y, STEP_SALT]);
    let first = (h % u64::from(steps)) as u32;
    let order = permute(k, spp.max(1), (h >> 32) as u32);
    ((u64::from(order) + u64::from(first)) % u64::from(steps)) as u32
}

/// Starts a frame traced in `steps` time steps (motion blur): its buffers, and which step
/// each sample traces (a byte a sample, `W × H × spp` bytes). Then one
/// [`render_pass_with`] a step (and one for the AOVs when no step is at the frame's own
/// time), then [`finish_blurred`].
pub(super) fn begin_blurred(
    scratch: &mut FrameScratch,
    camera: &CameraModel,
    frame: u32,
    spp: u32,
    steps: u32,
    inputs: &AovInputs<'_>,
) -> FrameBuffers {
    let fb = scratch.buffers(camera, inputs);
    let (w, h) = fb.data_size();
    let (w, spp) = (w as usize, spp.max(1) as usize);
    let n = w * h as usize * spp;
    let o = inputs.overscan;
    scratch.sample_steps.clear();
    scratch
        .sample_steps
        .par_extend((0..n).into_par_iter().with_min_len(4 * BLOCK).map(|s| {
            let p = s / spp;
            // The camera's pixel (wrapping in the border, as the seeds take it).
            let (x, y) = (
                ((p % w) as u32).wrapping_sub(o),
                ((p / w) as u32).wrapping_sub(o),
            );
            sample_step(frame, x, y, (s % spp) as u32, spp as u32, steps) as u8
        }));
    if fb.crypto.is_some() {
        refill(&mut scratch.crypto_ids, n, [None; 2]);
    }
    fb
}

/// A frame's buffers (of `camera`'s size, the AOVs `inputs` ask for), cleared, for
/// [`render_pass_with`] without blur.
pub(super) fn new_frame(
    scratch: &mut FrameScratch,
    camera: &CameraModel,
    inputs: &AovInputs<'_>,
) -> FrameBuffers {
    scratch.buffers(camera, inputs)
}

/// One pass of a frame: the whole frame into `fb` from [`new_frame`] (`pass` `None`, as
/// [`render_frame_with`]), or a step of a blurred frame begun with [`begin_blurred`],
/// `ctx`, `tracer` and `frame.camera` posed at the step's time, whose samples' radiance
/// and coverage are added to `fb` (summed, not yet averaged), with the AOVs when the
/// pass has them. `work` adds the pass's rays and times.
pub(super) fn render_pass_with<T: Intersector>(
    scratch: &mut FrameScratch,
    fb: &mut FrameBuffers,
    work: &mut FrameWork,
    ctx: &ShadeContext<'_>,
    tracer: &T,
    frame: &FrameArgs<'_>,
    pass: Option<StepPass>,
) {
    trace_pass(scratch, fb, work, ctx, tracer, frame, pass);
}

/// Ends a blurred frame: each pixel's sums over its samples (the beauty's and the
/// light-path passes') divided by `spp`, and the Cryptomatte ranks of all its samples,
/// whatever step each traced.
pub(super) fn finish_blurred(scratch: &FrameScratch, fb: &mut FrameBuffers, spp: u32) {
    let spp = spp.max(1) as usize;
    let inv = 1.0 / spp as f32;
    fb.rgba.par_iter_mut().with_min_len(BLOCK).for_each(|px| {
        *px = [
            px[0] * inv,
            px[1] * inv,
            px[2] * inv,
            (px[3] * inv).min(1.0),
        ]
    });
    if let Some(lp) = &mut fb.light_paths {
        for pass in &mut lp.passes {
            pass.par_iter_mut()
                .with_min_len(BLOCK)
                .for_each(|px| *px = (Vec3::from(*px) * inv).to_array());
        }
    }
    if let Some(buf) = fb.crypto.as_mut() {
        let levels = buf.levels;
        let ids = &scratch.crypto_ids;
        buf.object
            .par_chunks_mut(levels)
            .zip(buf.material.par_chunks_mut(levels))
            .zip(ids.par_chunks(spp))
            .with_min_len(BLOCK / spp + 1)
            .for_each(|((obj, mat), samples)| {
                let o: Vec<Option<u32>> = samples.iter().map(|s| s[0]).collect();
                let m: Vec<Option<u32>> = samples.iter().map(|s| s[1]).collect();
                rank(&o, levels, obj);
                rank(&m, levels, mat);
            });
    }
}

impl FrameScratch {
    /// A frame's buffers for `camera`'s image and the AOVs asked for, cleared, reusing a
    /// written frame's allocations when they fit.
    fn buffers(&mut self, camera: &CameraModel, inputs: &AovInputs<'_>) -> FrameBuffers {
        let aovs = inputs.aovs;
        // The buffers cover the data window: the image and the overscan border. Pixel
        // `(x, y)` of the buffers is the camera's pixel `(x − o, y − o)`.
        let o = inputs.overscan as usize;
        let (w, h) = (
            camera.width as usize + 2 * o,
            camera.height as usize + 2 * o,
        );
        let spare = self.spare.take().filter(|f| {
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
        let levels = aovs.crypto_levels.max(1) as usize;
        FrameBuffers {
            width: camera.width,
            height: camera.height,
            rgba,
            depth: refill_opt(depth, aovs.depth, w * h, f32::INFINITY),
            normal: refill_opt(normal, aovs.normal, w * h, [0.0; 3]),
            albedo: refill_opt(albedo, aovs.albedo, w * h, [0.0; 3]),
            position: refill_opt(position, aovs.position, w * h, [0.0; 3]),
            motion: refill_opt(motion, aovs.motion, w * h, [0.0; 2]),
            crypto: (inputs.crypto.is_some() && aovs.cryptomatte).then(|| CryptoBuffers {
                levels,
                object: vec![(0.0, 0.0); w * h * levels],
                material: vec![(0.0, 0.0); w * h * levels],
            }),
            light_paths: aovs.any_light_path().then(|| {
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
        }
    }
}

/// Traces and shades a frame's samples into `fb`: all of them, as one frame (`pass`
/// `None`), or those of one time step of a blurred frame.
fn trace_pass<T: Intersector>(
    scratch: &mut FrameScratch,
    fb: &mut FrameBuffers,
    work: &mut FrameWork,
    ctx: &ShadeContext<'_>,
    tracer: &T,
    args: &FrameArgs<'_>,
    pass: Option<StepPass>,
) {
    let FrameArgs {
        camera,
        frame,
        spp,
        max_depth,
        inputs,
        still_ahead,
    } = *args;
    let aovs = inputs.aovs;
    // The data window: the image and the overscan border (see `FrameScratch::buffers`).
    let o = inputs.overscan as usize;
    let (w, h) = (
        camera.width as usize + 2 * o,
        camera.height as usize + 2 * o,
    );
    let spp = spp.max(1) as usize;
    let light_paths = fb.light_paths.is_some();
    let FrameScratch {
        rays,
        items,
        hits,
        radiance,
        paths,
        coverage,
        outs,
        outs_prev,
        shadow_rays,
        shadow_add,
        shadow_split,
        light_start,
        blocked,
        spare: _,
        memo,
        replay,
        sample_steps,
        picked,
        crypto_ids,
        chunk_samples,
        replay_bytes,
    } = scratch;
    let layers = tracer.layers();
    // The memo keeps a still camera's rays from frame to frame; a blurred frame's steps
    // each trace other samples (and a moving camera other rays), so it stands aside.
    let mode = memo.begin(
        camera,
        spp,
        w * h,
        layers.is_some() && pass.is_none(),
        still_ahead,
    );
    // The shading of a still camera's rays, replayed where they repeat (one sample a
    // pixel, as the memo; not with the passes' split). Kept wherever the memo is: from
    // the frame that fills it (the sequence's next frame has the same camera), so that
    // frame replays instead of keeping, which had cost a still camera's second frame
    // 140 ms of CPU at 640x480 (benches/PERF.md, issue 38, round 6). A camera that
    // moves every frame allocates and fills nothing.
    let replayed = replay.begin(ctx, mode != Mode::Off && !light_paths, w * h, *replay_bytes);
    // Without the memo or the replay, which read a level's rays and bookkeeping as one
    // array, the levels below the camera rays are traced and shaded from the lists the
    // blocks of the level above made, and the shadow rays from the blocks' lists: their
    // copies into one array each were 6 % of a moving camera's frame (40 MB a 640x480
    // frame; `benches/PERF.md`, issue 38, round 17).
    let in_lists = mode == Mode::Off && replayed == 0;
    // Where the replay serves, the samples whose every kept ray misses the moving
    // triangles take the last frame's sums whole (`ShadeReplay::settled`).
    let moving_bounds = layers.and_then(|l| l.moving_bounds());
    let crypto = inputs.crypto.filter(|_| aovs.cryptomatte);
    // The centre-ray AOVs: every frame's, or the one pass of a blurred frame that has them.
    let any_aov = aovs.any_centre() && pass.is_none_or(|p| p.aovs);
    // One sample a pixel without blur: the centre rays are the camera rays themselves.
    let centre_batch = spp > 1 || pass.is_some();
    let step = pass.map(|p| p.samples);
    let aov_inputs = CentreInputs {
        camera,
        next: inputs.next.filter(|_| aovs.motion),
    };
    // The camera's pixel of buffer column or row `i` (negative in the border), as the
    // hashes of the jitter and the seeds take it (wrapping: the image's own pixels keep
    // the numbers they have without overscan).
    let pixel = |i: u32| i.wrapping_sub(o as u32);
    let chunk = if *chunk_samples > 0 {
        *chunk_samples
    } else {
        CHUNK_SAMPLES
    };
    let rows_per_chunk = (chunk / (w * spp)).max(1);
    let mut y0 = 0;
    while y0 < h {
        let y1 = (y0 + rows_per_chunk).min(h);
        let px0 = y0 * w;
        let npix = (y1 - y0) * w;
        let nsamples = npix * spp;

        // Primary rays.
        let clock = Instant::now();
        let walk = |s: usize| PixelWalk::at(px0, s, w, spp);
        let sample_ray = |at: &PixelWalk| {
            let (x, y) = (pixel(at.x), pixel(at.y));
            let (ox, oy) = sample_offset(frame, x, y, at.k, spp as u32);
            camera.ray(x as i32 as f32 + ox, y as i32 as f32 + oy)
        };
        rays.clear();
        // A blurred frame's pass: the chunk's samples of its step (chunk numbers).
        let sel: Option<&[u32]> = match step {
            None => {
                // In parallel into the kept buffer, each task stepping through its
                // pixels and samples without dividing (integer division was a tenth of
                // the rays' making), and without filling the buffer first (a serial
                // pass over 10 MB a frame).
                rays.par_extend((0..nsamples).into_par_iter().with_min_len(BLOCK).map_init(
                    || None,
                    |state: &mut Option<(usize, PixelWalk)>, s| {
                        // A task's samples come in order: step from the last one.
                        let at = match state.take() {
                            Some((next, at)) if next == s => at,
                            _ => walk(s),
                        };
                        let ray = sample_ray(&at);
                        let mut next = at;
                        next.advance();
                        *state = Some((s + 1, next));
                        ray
                    },
                ));
                None
            }
            Some(k) => {
                picked.clear();
                if let Some(k) = k {
                    let chunk = &sample_steps[px0 * spp..(px0 + npix) * spp];
                    picked.par_extend(
                        chunk
                            .par_iter()
                            .enumerate()
                            .with_min_len(4 * BLOCK)
                            .filter(|(_, &st)| u32::from(st) == k)
                            .map(|(s, _)| s as u32),
                    );
                }
                rays.par_extend(
                    picked
                        .par_iter()
                        .with_min_len(BLOCK)
                        .map(|&s| sample_ray(&walk(s as usize))),
                );
                Some(&picked[..])
            }
        };
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
            // Made only when a ray of the frame can read it (`ShadeContext::random`).
            seed: if ctx.random {
                Seed::camera(frame, pixel(at.x), pixel(at.y), at.k)
            } else {
                Seed::default()
            },
            cone,
            path: None,
        };
        items.clear();
        work.rays.primary += rays.len() as u64;
        refill(radiance, nsamples, Vec3::ZERO);
        if light_paths {
            refill(paths, nsamples, [Vec3::ZERO; 4]);
        }
        refill(coverage, nsamples, 0.0f32);
        work.shade += clock.elapsed();

        // The depth level: 0 for the camera rays.
        let mut level = 0usize;
        let mut settled_chunk: Option<Vec<bool>> = None;
        // The level's rays: `rays`, or (`in_lists`, below the camera rays) the
        // `next_rays` of the first `listed` blocks of `outs_prev`, `count` in all.
        let mut listed = 0usize;
        let mut count = rays.len();
        while count > 0 {
            let first = level == 0;
            let clock = Instant::now();
            hits.clear();
            hits.par_extend(
                (0..count)
                    .into_par_iter()
                    .with_min_len(4 * BLOCK)
                    .map(|_| None),
            );
            // The camera rays, the first levels below them and their shadow rays,
            // through what the memo keeps where it serves; any other batch through the
            // whole.
            let memo_layers = layers.filter(|_| mode != Mode::Off && level <= levels_kept(w * h));
            let whole = |r: &[Ray], h: &mut [Option<Hit>]| tracer.intersect_batch(r, h);
            match memo_layers {
                Some(l) if level == 0 => memo.primary(mode, l, &whole, px0, rays, hits),
                Some(l) => {
                    let sample = |i: usize| items[i].sample;
                    memo.closest(level, l, &whole, px0, w * h, rays, &sample, hits)
                }
                None if listed > 0 => {
                    let lists: Vec<&[Ray]> = outs_prev[..listed]
                        .iter()
                        .map(|o| &o.next_rays[..])
                        .collect();
                    tracer.intersect_lists(&lists, hits);
                }
                None => tracer.intersect_batch(rays, hits),
            }
            work.trace += clock.elapsed();

            let clock = Instant::now();
            if first && any_aov && !centre_batch {
                // The centre rays: the primary rays themselves with one sample, else
                // their own batch (traced below).
                write_aovs(ctx, &aov_inputs, fb, px0, rays, hits);
            }
            if first {
                match (crypto, sel) {
                    (Some(names), None) => {
                        if let Some(buf) = fb.crypto.as_mut() {
                            // The primary rays are the samples in order: rank each
                            // pixel's.
                            write_crypto(ctx, names, buf, px0, spp, hits);
                        }
                    }
                    (Some(names), Some(sel)) => {
                        // A step's samples: their ids kept until every step has traced.
                        keep_crypto_ids(ctx, names, crypto_ids, px0 * spp, sel, hits);
                    }
                    (None, _) => {}
                }
            }
            // The camera rays' samples that need no shading this frame.
            if first && sel.is_none() && replayed > 0 {
                let item = |i: usize| primary_item(i, &walk(i));
                if let Some((settled, (shadow, secondary))) =
                    replay.settled(px0, rays, hits, &item, moving_bounds, mode == Mode::Reuse)
                {
                    work.settled += settled.iter().filter(|&&s| s).count() as u64;
                    settled_chunk = Some(settled);
                    // The picture's rays: those the settled samples stand for too.
                    work.rays.shadow += shadow;
                    work.rays.secondary += secondary;
                }
            }
            let settled = settled_chunk.as_deref().filter(|_| first);

            // A block a list of the level above's, or a `BLOCK` of `rays`.
            let blocks = if listed > 0 {
                listed
            } else {
                rays.len().div_ceil(BLOCK)
            };
            if outs.len() < blocks {
                outs.resize_with(blocks, BlockOut::default);
            }
            // The kept shading of this level's samples, cut by the blocks that own them
            // (one sample a pixel: sample `s` of the chunk is slot `px0 + s`).
            let starts = || -> Vec<usize> {
                (0..blocks)
                    .map(|b| {
                        if first {
                            b * BLOCK
                        } else {
                            items[b * BLOCK].sample as usize
                        }
                    })
                    .collect()
            };
            let mut slots: Vec<Option<BlockSlots<'_>>> = if level >= replayed {
                (0..blocks).map(|_| None).collect()
            } else if let Some((kept, shadows, lights)) = replay.level(level) {
                let (kept, shadows) = (&mut kept[px0..], &mut shadows[px0 * lights..]);
                block_slots(kept, shadows, lights, &starts())
                    .into_iter()
                    .map(Some)
                    .collect()
            } else if let Some((settle, segments, lights)) = replay.records(level) {
                // Records only: the shading writes what a settled sample's check needs.
                let per = 2 * lights + 1;
                let (settle, segments) = (&mut settle[px0..], &mut segments[px0 * per..]);
                block_records(level, settle, segments, per, &starts())
                    .into_iter()
                    .map(Some)
                    .collect()
            } else {
                (0..blocks).map(|_| None).collect()
            };
            // A deeper ray's slot: only a sample's one ray at the level is kept.
            let alone = |i: usize| {
                let s = items[i].sample;
                (i == 0 || items[i - 1].sample != s)
                    && items.get(i + 1).is_none_or(|n| n.sample != s)
            };
            if first {
                match sel {
                    // The camera rays: ray `i` is sample `i`.
                    None => outs[..blocks]
                        .par_iter_mut()
                        .zip(rays.par_chunks(BLOCK))
                        .zip(hits.par_chunks(BLOCK))
                        .zip(slots.par_iter_mut())
                        .enumerate()
                        .for_each(|(b, (((out, r), hs), slots))| {
                            out.clear();
                            out.light_paths = light_paths;
                            let mut at = walk(b * BLOCK);
                            // Records (no slots to replay) are written after the lanes.
                            // Records (no slots to replay) are written from the block's
                            // lists once it is shaded, in lanes where it can be.
                            let records = slots.as_ref().is_some_and(|v| v.records_only());
                            if (slots.is_none() || records) && settled.is_none() && ctx.lanes(out) {
                                let item = |k: usize| {
                                    let item = primary_item(b * BLOCK + k, &at);
                                    at.advance();
                                    item
                                };
                                shade_in_fours(ctx, r, hs, item, max_depth, spp as u32, out);
                            } else {
                                for (k, (ray, hit)) in r.iter().zip(hs).enumerate() {
                                    let s = b * BLOCK + k;
                                    if settled.is_some_and(|v| v[s]) {
                                        at.advance();
                                        continue;
                                    }
                                    let item = primary_item(s, &at);
                                    if let Some(v) = slots.as_ref() {
                                        v.prefetch(s + PREFETCH_AHEAD);
                                    }
                                    let slot = match slots.as_mut() {
                                        Some(v) if !records => v.get(s),
                                        _ => None,
                                    };
                                    shade_kept(
                                        ctx, ray, &item, *hit, max_depth, spp as u32, out, slot,
                                    );
                                    at.advance();
                                }
                            }
                            if let Some(v) = slots.as_mut().filter(|_| records) {
                                let each = r.iter().zip(hs).enumerate();
                                let each = each.map(|(k, (r, h))| (b * BLOCK + k, r, *h, true));
                                let shaded = each.filter(|e| !settled.is_some_and(|v| v[e.0]));
                                record_block(ctx, v, shaded, out);
                            }
                        }),
                    // A step's camera rays: ray `i` is sample `sel[i]`.
                    Some(sel) => outs[..blocks]
                        .par_iter_mut()
                        .zip(rays.par_chunks(BLOCK))
                        .zip(hits.par_chunks(BLOCK))
                        .zip(sel.par_chunks(BLOCK))
                        .for_each(|(((out, r), hs), ss)| {
                            out.clear();
                            out.light_paths = light_paths;
                            for ((ray, hit), &s) in r.iter().zip(hs).zip(ss) {
                                let item = primary_item(s as usize, &walk(s as usize));
                                ctx.shade(ray, &item, *hit, max_depth, spp as u32, out);
                            }
                        }),
                }
            } else if listed > 0 {
                // Each list of the level above shaded as a block of its own, in order:
                // the same rays, in the same order, as the copies made one array.
                let mut parts = Vec::with_capacity(listed);
                let mut rest = &hits[..];
                for o in &outs_prev[..listed] {
                    let (head, tail) = rest.split_at(o.next_rays.len());
                    parts.push(head);
                    rest = tail;
                }
                outs[..blocks]
                    .par_iter_mut()
                    .zip(outs_prev[..listed].par_iter())
                    .zip(parts.into_par_iter())
                    .for_each(|((out, prev), hs)| {
                        out.clear();
                        out.light_paths = light_paths;
                        let (r, it) = (&prev.next_rays[..], &prev.next_items[..]);
                        if ctx.lanes(out) {
                            shade_in_fours(ctx, r, hs, |k| it[k], max_depth, spp as u32, out);
                            return;
                        }
                        for ((ray, item), hit) in r.iter().zip(it).zip(hs) {
                            shade_kept(ctx, ray, item, *hit, max_depth, spp as u32, out, None);
                        }
                    });
            } else {
                outs[..blocks]
                    .par_iter_mut()
                    .zip(rays.par_chunks(BLOCK))
                    .zip(items.par_chunks(BLOCK))
                    .zip(hits.par_chunks(BLOCK))
                    .zip(slots.par_iter_mut())
                    .enumerate()
                    .for_each(|(b, ((((out, r), it), hs), slots))| {
                        out.clear();
                        out.light_paths = light_paths;
                        let records = slots.as_ref().is_some_and(|v| v.records_only());
                        if (slots.is_none() || records) && ctx.lanes(out) {
                            shade_in_fours(ctx, r, hs, |k| it[k], max_depth, spp as u32, out);
                        } else {
                            for (k, ((ray, item), hit)) in r.iter().zip(it).zip(hs).enumerate() {
                                if let (Some(v), Some(ahead)) =
                                    (slots.as_ref(), it.get(k + PREFETCH_AHEAD))
                                {
                                    v.prefetch(ahead.sample as usize);
                                }
                                let slot = match slots.as_mut() {
                                    Some(v) if !records && alone(b * BLOCK + k) => {
                                        v.get(item.sample as usize)
                                    }
                                    _ => None,
                                };
                                shade_kept(ctx, ray, item, *hit, max_depth, spp as u32, out, slot);
                            }
                        }
                        if let Some(v) = slots.as_mut().filter(|_| records) {
                            let each = r.iter().zip(it).zip(hs).enumerate();
                            let each = each.map(|(k, ((r, i), h))| {
                                (i.sample as usize, r, *h, alone(b * BLOCK + k))
                            });
                            record_block(ctx, v, each, out);
                        }
                    });
            }
            level += 1;
            // The blocks' lists gathered in block order, on six tasks: the sums into the
            // samples (a sample's terms added in block order, as always), and each list
            // the next level reads copied on a task of its own (each the same elements
            // in the same order as one serial pass; `in_lists`, only the shadow rays'
            // contributions, the rays and bookkeeping staying in the blocks). Two tasks
            // before, 5.7 ms a frame at any thread count beyond two (benches/PERF.md,
            // issue 38). Nested joins, not `rayon::scope` with six spawns: that was 1-4
            // ms a frame slower on 2 threads (three alternating runs, museum class,
            // 640x480).
            let done = &outs[..blocks];
            // A light's rays together, in block order: each light's rays are one batch
            // through its point grid (which a batch mixing lights would not get).
            let lights = done.iter().map(|o| o.shadow.len()).max().unwrap_or(0);
            let shadow_lists =
                || (0..lights).flat_map(|l| done.iter().filter_map(move |o| o.shadow.get(l)));
            rayon::join(
                || {
                    for o in done {
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
                    }
                },
                || {
                    rayon::join(
                        || {
                            if in_lists {
                                return;
                            }
                            rayon::join(
                                || {
                                    rays.clear();
                                    for o in done {
                                        rays.extend_from_slice(&o.next_rays);
                                    }
                                },
                                || {
                                    items.clear();
                                    for o in done {
                                        items.extend_from_slice(&o.next_items);
                                    }
                                },
                            );
                        },
                        || {
                            rayon::join(
                                || {
                                    shadow_rays.clear();
                                    light_start.clear();
                                    let mut n = 0;
                                    for l in 0..lights {
                                        light_start.push(n);
                                        for list in done.iter().filter_map(|o| o.shadow.get(l)) {
                                            if !in_lists {
                                                shadow_rays.extend_from_slice(&list.rays);
                                            }
                                            n += list.rays.len();
                                        }
                                    }
                                    light_start.push(n);
                                },
                                || {
                                    rayon::join(
                                        || {
                                            shadow_add.clear();
                                            for list in shadow_lists() {
                                                shadow_add.extend_from_slice(&list.add);
                                            }
                                        },
                                        || {
                                            shadow_split.clear();
                                            for list in shadow_lists() {
                                                shadow_split.extend_from_slice(&list.split);
                                            }
                                        },
                                    )
                                },
                            )
                        },
                    )
                },
            );
            // The next level's rays, and the shadow rays, stay in the blocks' lists.
            if in_lists {
                std::mem::swap(outs, outs_prev);
                listed = blocks;
                count = outs_prev[..listed].iter().map(|o| o.next_rays.len()).sum();
            } else {
                count = rays.len();
            }
            let shadows = light_start.last().copied().unwrap_or(0);
            work.rays.secondary += count as u64;
            work.rays.shadow += shadows as u64;
            work.shade += clock.elapsed();

            let clock = Instant::now();
            // The shadow rays leave the hits of the level just shaded.
            let shadow_level = level - 1;
            refill(blocked, shadows, false);
            for (l, span) in light_start.windows(2).enumerate() {
                let (a, b) = (span[0], span[1]);
                if a >= b {
                    continue;
                }
                match memo_layers {
                    Some(layers) if l < ctx.punctual_lights().min(lights_kept(w * h)) => memo
                        .shadows(
                            shadow_level,
                            layers,
                            &|r: &[Ray], b: &mut [bool]| tracer.occluded_batch(r, b),
                            l,
                            px0,
                            w * h,
                            &shadow_rays[a..b],
                            &shadow_add[a..b],
                            &mut blocked[a..b],
                        ),
                    _ if in_lists => {
                        let lists: Vec<&[Ray]> = outs_prev[..listed]
                            .iter()
                            .filter_map(|o| o.shadow.get(l))
                            .map(|list| &list.rays[..])
                            .collect();
                        tracer.occluded_lists(&lists, &mut blocked[a..b]);
                    }
                    _ => tracer.occluded_batch(&shadow_rays[a..b], &mut blocked[a..b]),
                }
            }
            work.trace += clock.elapsed();

            let clock = Instant::now();
            add_unblocked(radiance, light_start, shadow_add, |r, i| {
                if !blocked[i] {
                    *r += shadow_add[i].1;
                }
            });
            if light_paths {
                add_unblocked(paths, light_start, shadow_add, |p, i| {
                    if !blocked[i] {
                        for (p, c) in p.iter_mut().zip(&shadow_split[i]) {
                            *p += *c;
                        }
                    }
                });
            }
            work.shade += clock.elapsed();
        }

        if any_aov && centre_batch {
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
            write_aovs(ctx, &aov_inputs, fb, px0, &centre, &chits);
            work.shade += clock.elapsed();
        }

        let clock = Instant::now();
        if replayed > 0 && sel.is_none() {
            replay.sums(
                px0,
                w * h,
                settled_chunk.as_deref(),
                &mut radiance[..nsamples],
                &mut coverage[..nsamples],
                moving_bounds,
            );
        }
        let sums = |i: usize| {
            let mut c = Vec3::ZERO;
            let mut a = 0.0;
            for s in i * spp..(i + 1) * spp {
                c += radiance[s];
                a += coverage[s];
            }
            (c, a)
        };
        let pixels = fb.rgba[px0..px0 + npix]
            .par_iter_mut()
            .enumerate()
            .with_min_len(BLOCK);
        match sel {
            None => {
                let inv = 1.0 / spp as f32;
                pixels.for_each(|(i, px)| {
                    let (c, a) = sums(i);
                    let c = c * inv;
                    *px = [c.x, c.y, c.z, (a * inv).min(1.0)];
                });
            }
            // A step's sums added to the steps' before (`finish_blurred` averages).
            Some(sel) if !sel.is_empty() => pixels.for_each(|(i, px)| {
                let (c, a) = sums(i);
                *px = [px[0] + c.x, px[1] + c.y, px[2] + c.z, px[3] + a];
            }),
            Some(_) => {}
        }
        if let Some(lp) = &mut fb.light_paths {
            // Each pass averaged (or, for a step, summed) as the beauty is: so they add
            // up to it, to the order of the float additions.
            let (inv, add) = match sel {
                None => (1.0 / spp as f32, false),
                Some(sel) if !sel.is_empty() => (1.0, true),
                Some(_) => (0.0, false),
            };
            if inv > 0.0 {
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
                            let c = c * inv;
                            *px = if add {
                                (Vec3::from(*px) + c).to_array()
                            } else {
                                c.to_array()
                            };
                        });
                }
            }
        }
        work.shade += clock.elapsed();
        y0 = y1;
    }
    memo.end(mode);
    work.kept = match mode {
        Mode::Off => Kept::None,
        Mode::Fill => Kept::Fill,
        Mode::Reuse => Kept::Reuse,
    };
}

/// Samples a task of [`add_unblocked`] owns.
const ADD_SAMPLES: usize = 16 * BLOCK;

/// A block's rays shaded four at a time where the frame allows
/// ([`ShadeContext::shade4`]: the same lists as one at a time), the last few one at a
/// time; `item(k)` is ray `k`'s bookkeeping, asked for in order.
fn shade_in_fours(
    ctx: &ShadeContext<'_>,
    rays: &[Ray],
    hits: &[Option<Hit>],
    mut item: impl FnMut(usize) -> Item,
    max_depth: u32,
    spp: u32,
    out: &mut BlockOut,
) {
    let n4 = rays.len() / 4 * 4;
    for (q, (r, h)) in rays[..n4]
        .chunks_exact(4)
        .zip(hits.chunks_exact(4))
        .enumerate()
    {
        let k = 4 * q;
        let items = [item(k), item(k + 1), item(k + 2), item(k + 3)];
        ctx.shade4(
            [&r[0], &r[1], &r[2], &r[3]],
            [&items[0], &items[1], &items[2], &items[3]],
            [h[0], h[1], h[2], h[3]],
            max_depth,
            spp,
            out,
        );
    }
    for (k, (ray, hit)) in rays.iter().zip(hits).enumerate().skip(n4) {
        ctx.shade(ray, &item(k), *hit, max_depth, spp, out);
    }
}

/// Adds each shadow ray's contribution to its sample (`add(&mut dst[sample], i)` for
/// ray `i`), in the order of one serial pass over the rays, in parallel over ranges of
/// samples. The rays are in light batches (`light_start`), and within a batch in the
/// order of the items that made them, which are in sample order; so each range's rays
/// of a batch are found by two binary searches, and every sample gets its terms in the
/// serial pass's order (the same bytes). A batch out of sample order (which the
/// wavefront does not make) is added by the serial pass itself. This pass was serial,
/// 1.1–1.8 ms of a frame at any thread count (benches/PERF.md, issue 38).
fn add_unblocked<D: Send>(
    dst: &mut [D],
    light_start: &[usize],
    shadow_add: &[(u32, Vec3)],
    add: impl Fn(&mut D, usize) + Sync,
) {
    let batches = || light_start.windows(2).map(|w| w[0]..w[1]);
    let sorted = batches().all(|r| {
        shadow_add[r]
            .par_windows(2)
            .with_min_len(4 * BLOCK)
            .all(|w| w[0].0 <= w[1].0)
    });
    if !sorted {
        for r in batches() {
            for i in r {
                add(&mut dst[shadow_add[i].0 as usize], i);
            }
        }
        return;
    }
    dst.par_chunks_mut(ADD_SAMPLES)
        .enumerate()
        .for_each(|(k, chunk)| {
            let lo = (k * ADD_SAMPLES) as u32;
            let hi = lo + chunk.len() as u32;
            for r in batches() {
                let batch = &shadow_add[r.clone()];
                let from = r.start + batch.partition_point(|e| e.0 < lo);
                let to = r.start + batch.partition_point(|e| e.0 < hi);
                for i in from..to {
                    add(&mut chunk[(shadow_add[i].0 - lo) as usize], i);
                }
            }
        });
}

/// The Cryptomatte ids of a step's camera hits (`hits[i]` is chunk sample `sel[i]`, the
/// chunk's first sample being `base`), kept in `ids` by the frame's sample number.
fn keep_crypto_ids(
    ctx: &ShadeContext<'_>,
    names: &CryptoNames,
    ids: &mut [[Option<u32>; 2]],
    base: usize,
    sel: &[u32],
    hits: &[Option<Hit>],
) {
    let lookup = |kind: &[u32], i: u32| kind.get(i as usize).copied();
    for (&s, h) in sel.iter().zip(hits) {
        let (o, m) = match h.and_then(|h| ctx.ids(&h)) {
            Some((n, m)) => (lookup(&names.object.ids, n), lookup(&names.material.ids, m)),
            None => (None, None),
        };
        if let Some(slot) = ids.get_mut(base + s as usize) {
            *slot = [o, m];
        }
    }
}

/// What the centre-ray AOVs read besides the shading context.
pub(super) struct CentreInputs<'a> {
    pub(super) camera: &'a CameraModel,
    pub(super) next: Option<(&'a TriangleSoup, CameraModel)>,
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
pub(super) fn write_aovs(
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
pub(super) fn write_crypto(
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

    /// The parallel pass adds exactly what one serial pass adds, in its order (bits
    /// compared), for batches in sample order and, through the fallback, out of it.
    #[test]
    fn unblocked_shadow_terms_add_as_one_serial_pass() {
        let n = 3 * ADD_SAMPLES + 77;
        for (seed, sorted) in [(1u64, true), (2, true), (3, false)] {
            let mut x = seed;
            let mut next = move || {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x
            };
            let mut adds = Vec::new();
            let mut light_start = vec![0];
            for _ in 0..3 {
                let mut batch: Vec<(u32, Vec3)> = (0..n / 2)
                    .map(|_| {
                        let v = (next() % 1000) as f32 * 1e-3 + 1e-7;
                        (
                            (next() % n as u64) as u32,
                            Vec3::new(v, v * 3.0, 1.0 / (v + 1.0)),
                        )
                    })
                    .collect();
                if sorted {
                    batch.sort_by_key(|e| e.0);
                }
                adds.extend(batch);
                light_start.push(adds.len());
            }
            let blocked: Vec<bool> = (0..adds.len()).map(|_| next() % 3 == 0).collect();
            let mut serial = vec![Vec3::splat(0.1); n];
            for (&(s, c), &b) in adds.iter().zip(&blocked) {
                if !b {
                    serial[s as usize] += c;
                }
            }
            let mut par = vec![Vec3::splat(0.1); n];
            add_unblocked(&mut par, &light_start, &adds, |r, i| {
                if !blocked[i] {
                    *r += adds[i].1;
                }
            });
            let bits = |v: &[Vec3]| {
                v.iter()
                    .flat_map(|c| c.to_array())
                    .map(f32::to_bits)
                    .collect::<Vec<_>>()
            };
            assert!(bits(&serial) == bits(&par), "seed {seed}, sorted {sorted}");
        }
    }

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

    #[test]
    fn permute_is_a_bijection() {
        for l in 1..=70u32 {
            for p in [0u32, 1, 0xdead_beef, 0x8000_0001] {
                let mut seen = vec![false; l as usize];
                for i in 0..l {
                    let j = permute(i, l, p);
                    assert!(j < l && !seen[j as usize], "l {l} p {p:#x}: {i} → {j}");
                    seen[j as usize] = true;
                }
            }
        }
    }

    /// Every step gets `spp / steps` samples of a pixel or one more; with fewer samples
    /// than steps, a row of pixels covers every step; and the steps' samples are not
    /// the same cells of the jitter grid in every pixel.
    #[test]
    fn sample_steps_are_balanced_and_shuffled() {
        for (spp, steps) in [(64u32, 8u32), (16, 5), (3, 8), (1, 5), (8, 1)] {
            let mut covered = vec![false; steps as usize];
            let mut first_cells = std::collections::HashSet::new();
            for x in 0..40 {
                let mut count = vec![0u32; steps as usize];
                for k in 0..spp {
                    let st = sample_step(9, x, 3, k, spp, steps);
                    count[st as usize] += 1;
                    covered[st as usize] = true;
                }
                let (lo, hi) = (spp / steps, spp.div_ceil(steps));
                assert!(
                    count.iter().all(|&c| c == lo || c == hi),
                    "spp {spp}, {steps} steps: {count:?}"
                );
                if spp >= steps && steps > 1 {
                    first_cells
                        .insert((0..spp).find(|&k| sample_step(9, x, 3, k, spp, steps) == 0));
                }
            }
            assert!(
                covered.iter().all(|&c| c),
                "spp {spp}, {steps} steps: a step unused"
            );
            if spp >= steps && steps > 1 {
                assert!(
                    first_cells.len() > 4,
                    "step 0 takes the same samples: {first_cells:?}"
                );
            }
        }
    }
}
