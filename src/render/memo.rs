//! What a frame's rays met in the static part, kept for the next frame: a camera that
//! stays put sends the same camera rays every frame (one sample a pixel: the pixel
//! centres), and where they hit static triangles the same shadow rays, whose static
//! answers cannot change either (the static triangles do not move). A frame then
//! traces those rays through the moving triangles alone ([`Layers`]).
//!
//! The same holds deeper: a mirror or a refraction off a static hit of an unmoved camera
//! ray is the same ray every frame, and so are its hit's shadow rays where that hit is
//! static. The first [`LEVELS_KEPT`] levels below the camera rays keep a static answer
//! per sample with the ray it answers, and reuse it for a ray equal to the bit
//! ([`StaticMemo::closest`], [`StaticMemo::shadows`] with `level` > 0).
//!
//! The hits are those of tracing the whole each frame: the static hit kept is the one
//! the static part gives that very ray (a camera ray is the same ray when the camera is
//! the same to the bit; a shadow ray is compared to the bit with the one kept), and the
//! whole's answer follows from the two parts' ([`closest_of`], or either blocking).

use glam::Vec3;
use rayon::prelude::*;

use super::camera::CameraModel;
use crate::geometry::{closest_of, Hit, Layers, Ray};

/// Lights whose shadow rays' static answers are kept, at most: the first so many of a
/// frame's punctual lights, fewer where [`SHADOW_BYTES`] would not hold them.
const MAX_LIGHTS: usize = 8;

/// The memory the kept shadow answers may take, every level's together (36 bytes a
/// pixel, light and level): with the camera rays' and two levels below them, eight
/// lights at 640x480, one at 1920x1080, none at 4096x2160 (where no level below the
/// camera rays is kept and the camera rays' shadows would need 319 MB a light).
///
/// What the memo holds at most, so: 512 + 256 + 256 MB; at 640x480 with one light,
/// 6 MB of camera-ray hits, 32 MB of the two levels' hits and 33 MB of shadow answers.
const SHADOW_BYTES: usize = 256 << 20;

/// The memory the kept camera-ray hits may take (20 bytes a pixel): beyond it (some 26
/// million pixels) nothing is kept.
const PRIMARY_BYTES: usize = 512 << 20;

/// Levels below the camera rays whose static answers are kept, at most (where
/// [`SECONDARY_BYTES`] holds them): a mirror's ray, and the ray off a second mirror.
const LEVELS_KEPT: usize = 2;

/// The memory the kept static hits of the deeper levels may take, all levels together
/// (52 bytes a pixel and level: 32 MB at 640x480, 216 MB at 1920x1080 for two levels).
const SECONDARY_BYTES: usize = 256 << 20;

/// How many levels below the camera rays keep their static answers at `pixels` (the
/// shadow rays of each such level as [`lights_kept`] says).
pub(super) fn levels_kept(pixels: usize) -> usize {
    (SECONDARY_BYTES / (std::mem::size_of::<(Ray, Option<Hit>)>() * pixels.max(1))).min(LEVELS_KEPT)
}

/// How many punctual lights' shadow answers a frame of `pixels` keeps at each level it
/// keeps (the camera rays' and [`levels_kept`] below them).
pub(super) fn lights_kept(pixels: usize) -> usize {
    let levels = 1 + levels_kept(pixels);
    (SHADOW_BYTES / (std::mem::size_of::<(Ray, bool)>() * pixels.max(1) * levels)).min(MAX_LIGHTS)
}

/// A batch's closest hits through the whole structure.
pub(super) type Whole<'a> = &'a dyn Fn(&[Ray], &mut [Option<Hit>]);

/// What a frame does with the memo.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mode {
    /// The whole traced as one, nothing kept: the structure has no static part of its
    /// own, pixels take several samples (jittered anew each frame), or nothing kept
    /// would serve (the camera has just moved, and the next frame's is another or
    /// there is none: a camera that moves every frame gains nothing).
    Off,
    /// The camera rays' static hits traced and kept, the moving part traced apart.
    Fill,
    /// The camera rays' static hits are those kept.
    Reuse,
}

/// The static answers kept from frame to frame, and the buffers of the split trace.
#[derive(Default)]
pub(super) struct StaticMemo {
    /// The camera whose rays `primary` answers (its bits), and whether it holds a whole
    /// frame's.
    camera: Option<[u32; CameraModel::BITS]>,
    filled: bool,
    /// The closest static hit of each pixel's camera ray.
    primary: Vec<Option<Hit>>,
    /// Per level and punctual light (`level * MAX_LIGHTS + light`), per pixel: the last
    /// shadow ray towards the light from the pixel's hit at that level, and whether a
    /// static triangle blocks it.
    shadow: Vec<Vec<(Ray, bool)>>,
    /// Per level below the camera rays (`level - 1`), per pixel: the last ray of that
    /// level of the pixel's sample, and its closest static hit.
    deeper: Vec<Vec<(Ray, Option<Hit>)>>,
    fresh: Vec<Option<Hit>>,
    fresh_flags: Vec<bool>,
    clipped: Vec<Ray>,
    moving: Vec<Option<Hit>>,
    need: Vec<u32>,
    gathered: Vec<Ray>,
    answers: Vec<bool>,
}

/// The same ray to the bit ([`Ray::bits`]).
#[inline]
fn same(a: &Ray, b: &Ray) -> bool {
    a.same_bits(b)
}

/// A slot no shadow ray has filled: a ray of zero direction, which every query answers
/// "not blocked", so that an equal ray would get the right answer from it.
const EMPTY: (Ray, bool) = (
    Ray {
        origin: Vec3::ZERO,
        dir: Vec3::ZERO,
        t_min: 0.0,
        t_max: 0.0,
    },
    false,
);

/// `need` as the indices of the `xs` that `pick` picks, in order.
fn select<T: Sync>(need: &mut Vec<u32>, xs: &[T], pick: impl Fn(&T) -> bool + Sync) {
    need.clear();
    need.par_extend(
        xs.par_iter()
            .enumerate()
            .with_min_len(1024)
            .filter(|(_, x)| pick(x))
            .map(|(i, _)| i as u32),
    );
}

/// `gathered` as the rays `need` names, in its order.
fn gather(gathered: &mut Vec<Ray>, need: &[u32], rays: &[Ray]) {
    gathered.clear();
    gathered.par_extend(need.par_iter().map(|&i| rays[i as usize]));
}

/// `dst` as a copy of `src`, copied on every thread: a still camera's kept answers are
/// some 70 MB at 640x480, and one thread's copy (its fresh pages zeroed first) held the
/// other lanes back.
pub(super) fn copy_par<T: Copy + Send + Sync>(dst: &mut Vec<T>, src: &[T]) {
    dst.clear();
    dst.par_extend(src.par_iter().with_min_len(1 << 14).copied());
}

/// `v` as `n` copies of `x`, written on every thread: a still camera's first frame
/// sets up some 170 MB of kept slots at 640x480 before it traces (the replay's and the
/// camera rays'), and one thread's fill (the kernel zeroing each fresh page first) was
/// 90 ms of a frame that the other threads waited for. (The deeper levels' and shadow
/// rays' slots, set up inside the trace, stay one thread's: filled this way, the frames
/// that reuse them traced 8 ms slower at 1 thread, for no reason found;
/// `benches/PERF.md`, issue 38, round 7.)
pub(super) fn fill_par<T: Copy + Send + Sync>(v: &mut Vec<T>, n: usize, x: T) {
    v.clear();
    v.par_extend(rayon::iter::repeat_n(x, n).with_min_len(1 << 14));
}

/// Each of `src`'s lists copied into `dst`'s ([`copy_par`]).
pub(super) fn copy_all<T: Copy + Send + Sync>(dst: &mut Vec<Vec<T>>, src: &[Vec<T>]) {
    dst.resize_with(src.len(), Vec::new);
    for (d, s) in dst.iter_mut().zip(src) {
        copy_par(d, s);
    }
}

/// Whether a frame of `pixels` samples of `spp` a pixel can keep its static hits at
/// all (one sample a pixel, within [`PRIMARY_BYTES`]); [`StaticMemo::begin`]'s test,
/// for a sequence deciding ahead of its frames.
pub(super) fn may_keep(spp: usize, pixels: usize) -> bool {
    spp == 1 && pixels * std::mem::size_of::<Option<Hit>>() <= PRIMARY_BYTES
}

impl StaticMemo {
    /// Whether the memo holds a whole frame's static hits for `camera`'s rays (a frame
    /// through it would reuse them).
    pub(super) fn holds(&self, camera: &[u32; CameraModel::BITS]) -> bool {
        self.filled && self.camera.as_ref() == Some(camera)
    }

    /// Takes what `from` keeps (its camera's static hits and the deeper levels' and
    /// shadow rays' answers), as if this memo had filled them: every kept answer is the
    /// static part's for the ray kept with it, so any frame may read them. Another
    /// frame in flight copies them instead of filling its own (a fill costs a still
    /// camera's frame five times a frame that reuses; `benches/PERF.md`, issue 38).
    /// The working buffers stay this memo's.
    pub(super) fn copy_kept(&mut self, from: &StaticMemo) {
        self.camera = from.camera;
        self.filled = from.filled;
        copy_par(&mut self.primary, &from.primary);
        copy_all(&mut self.shadow, &from.shadow);
        copy_all(&mut self.deeper, &from.deeper);
    }

    /// What this frame does: `pixels` of one sample each (`spp`), through a structure
    /// with (`layered`) or without a static part of its own; `ahead`: the frame the
    /// sequence renders next (on this memo) has the same camera to the bit. A frame
    /// fills the memo only then: a camera that moves on, or a last frame, would keep
    /// what no frame reads (the first frame of a dolly traced its batches twice over,
    /// 222 ms against 163 at 640x480; `benches/PERF.md`, issue 38, round 6).
    pub(super) fn begin(
        &mut self,
        camera: &CameraModel,
        spp: usize,
        pixels: usize,
        layered: bool,
        ahead: bool,
    ) -> Mode {
        if !layered || !may_keep(spp, pixels) {
            self.camera = None;
            self.filled = false;
            return Mode::Off;
        }
        let bits = camera.bits();
        let mode = match self.camera {
            Some(b) if b == bits && self.filled && self.primary.len() == pixels => Mode::Reuse,
            _ if ahead => Mode::Fill,
            _ => Mode::Off,
        };
        self.camera = Some(bits);
        self.filled = false;
        if mode == Mode::Fill {
            fill_par(&mut self.primary, pixels, None);
        }
        mode
    }

    /// The frame is done: what it filled serves the next.
    pub(super) fn end(&mut self, mode: Mode) {
        self.filled = matches!(mode, Mode::Fill | Mode::Reuse);
    }

    /// The closest hits of a chunk's camera rays (`rays`, from pixel `base` on, one
    /// sample each) into `hits`. `Fill`: traced through the whole (`whole`), the static
    /// hit kept where the hit is static or there is none, and traced through the static
    /// part where a moving triangle is in front. `Reuse`: the moving triangles traced up
    /// to the static hits kept.
    pub(super) fn primary(
        &mut self,
        mode: Mode,
        layers: &dyn Layers,
        whole: Whole<'_>,
        base: usize,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
    ) {
        let n = rays.len();
        let kept = &mut self.primary[base..base + n];
        if mode == Mode::Fill {
            whole(rays, hits);
            let statics = layers.static_count();
            kept.par_iter_mut()
                .zip(hits.par_iter())
                .with_min_len(1024)
                .for_each(|(k, h)| *k = h.filter(|h| (h.tri as usize) < statics));
            select(&mut self.need, hits, |h| {
                h.is_some_and(|h| h.tri as usize >= statics)
            });
            if self.need.is_empty() {
                return;
            }
            gather(&mut self.gathered, &self.need, rays);
            self.moving.clear();
            self.moving.resize(self.need.len(), None);
            layers.static_batch(&self.gathered, &mut self.moving);
            for (&i, &h) in self.need.iter().zip(&self.moving) {
                kept[i as usize] = h;
            }
            return;
        }
        self.clipped.clear();
        self.clipped
            .par_extend(rays.par_iter().zip(kept.par_iter()).map(|(r, h)| {
                let mut r = *r;
                if let Some(h) = h {
                    // A moving triangle beyond the static hit cannot be the closest;
                    // one at the same `t` loses the tie.
                    r.t_max = h.t;
                }
                r
            }));
        self.moving.clear();
        self.moving.resize(n, None);
        layers.moving_batch(&self.clipped, &mut self.moving);
        hits.par_iter_mut()
            .zip(kept.par_iter().zip(self.moving.par_iter()))
            .with_min_len(1024)
            .for_each(|(o, (s, m))| *o = closest_of(*s, *m));
    }

    /// The closest hits of a chunk's rays of `level` (1: the rays off the camera rays'
    /// hits; at most [`levels_kept`]) into `hits`: `rays[i]` belongs to the sample of
    /// pixel `base + sample(i)` (of `pixels`). A static hit is kept per pixel with its ray
    /// and reused for the same ray; a new ray is traced through the static part and its
    /// hit kept; then every ray through the moving triangles up to its static hit.
    /// Where most rays are new (a first frame), the batch is traced through the whole
    /// (`whole`) in one, and through the static part where a moving triangle is in
    /// front, to keep its static hit.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn closest(
        &mut self,
        level: usize,
        layers: &dyn Layers,
        whole: Whole<'_>,
        base: usize,
        pixels: usize,
        rays: &[Ray],
        sample: &(dyn Fn(usize) -> u32 + Sync),
        hits: &mut [Option<Hit>],
    ) {
        let n = rays.len();
        if self.deeper.len() < level {
            self.deeper.resize_with(level, Vec::new);
        }
        let kept = &mut self.deeper[level - 1];
        if kept.len() != pixels {
            kept.clear();
            kept.resize(pixels, (EMPTY.0, None));
        }
        let slot = |i: usize| base + sample(i) as usize;
        // One pass over the kept slots: a kept ray's static hit into `hits` and its
        // ray clipped there into `clipped`; a new ray marked (three passes over the
        // slots, 30 MB each at 640x480, were 11 ms of a 28 ms level).
        let clip = |r: &Ray, h: &Option<Hit>| match h {
            // A moving triangle beyond the static hit cannot be the closest; one at the
            // same `t` loses the tie.
            Some(h) => Ray { t_max: h.t, ..*r },
            None => *r,
        };
        self.fresh_flags.clear();
        self.fresh_flags.resize(n, false);
        {
            let kept = &*kept;
            self.clipped.clear();
            self.clipped.par_extend(
                rays.par_iter()
                    .zip(hits.par_iter_mut())
                    .zip(self.fresh_flags.par_iter_mut())
                    .enumerate()
                    .with_min_len(1024)
                    .map(|(i, ((r, h), new))| {
                        let (k, s) = &kept[slot(i)];
                        if same(k, r) {
                            *h = *s;
                            clip(r, s)
                        } else {
                            *h = None;
                            *new = true;
                            // Traced below, once its static hit is known.
                            EMPTY.0
                        }
                    }),
            );
        }
        select(&mut self.need, &self.fresh_flags, |&f| f);
        if 2 * self.need.len() > n {
            whole(rays, hits);
            let statics = layers.static_count();
            let is_moving = |h: &Option<Hit>| h.is_some_and(|h| h.tri as usize >= statics);
            self.gathered.clear();
            for &i in &self.need {
                let i = i as usize;
                if is_moving(&hits[i]) {
                    self.gathered.push(rays[i]);
                } else {
                    kept[slot(i)] = (rays[i], hits[i]);
                }
            }
            self.fresh.clear();
            self.fresh.resize(self.gathered.len(), None);
            layers.static_batch(&self.gathered, &mut self.fresh);
            let mut statics_of = self.fresh.iter();
            for &i in &self.need {
                let i = i as usize;
                if is_moving(&hits[i]) {
                    if let Some(&h) = statics_of.next() {
                        kept[slot(i)] = (rays[i], h);
                    }
                }
            }
            return;
        }
        // The new rays' static hits, kept (a batch of a few hundred rays through the
        // static part alone: the whole's set-up for it was 10 ms a frame here). Two new
        // rays of one pixel (a mirror's and a glass's) share a slot: the later keeps it.
        if !self.need.is_empty() {
            gather(&mut self.gathered, &self.need, rays);
            self.fresh.clear();
            self.fresh.resize(self.need.len(), None);
            layers.static_batch(&self.gathered, &mut self.fresh);
            for (&i, &h) in self.need.iter().zip(&self.fresh) {
                let i = i as usize;
                kept[slot(i)] = (rays[i], h);
                hits[i] = h;
                self.clipped[i] = clip(&rays[i], &h);
            }
        }
        // Every ray through the moving triangles up to its static hit.
        self.moving.clear();
        self.moving.resize(n, None);
        layers.moving_batch(&self.clipped, &mut self.moving);
        hits.par_iter_mut()
            .zip(self.moving.par_iter())
            .with_min_len(1024)
            .for_each(|(h, m)| *h = closest_of(*h, *m));
    }

    /// Whether each of a chunk's shadow rays towards punctual light `light` (below
    /// [`lights_kept`]) is blocked, into `blocked`: `rays[i]` leaves the hit at `level`
    /// (0: the camera rays'; at most [`levels_kept`]) of the sample of pixel
    /// `base + pixel[i].0` (of `pixels`). A static answer is kept per pixel with its
    /// ray and reused for the same ray, the moving triangles traced for the rays no
    /// static one blocks. Where most rays are new (a first frame), the batch is traced
    /// through the whole (`whole`) and the static part traced for the blocked new ones
    /// alone (an unblocked ray is blocked by nothing static).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn shadows(
        &mut self,
        level: usize,
        layers: &dyn Layers,
        whole: &dyn Fn(&[Ray], &mut [bool]),
        light: usize,
        base: usize,
        pixels: usize,
        rays: &[Ray],
        pixel: &[(u32, Vec3)],
        blocked: &mut [bool],
    ) {
        let bank = level * MAX_LIGHTS + light;
        if self.shadow.len() <= bank {
            self.shadow.resize_with(bank + 1, Vec::new);
        }
        let kept = &mut self.shadow[bank];
        if kept.len() != pixels {
            kept.clear();
            kept.resize(pixels, EMPTY);
        }
        // Each ray's kept static answer, and the rays that have none, in one pass over
        // the kept slots.
        self.fresh_flags.clear();
        self.fresh_flags.resize(rays.len(), false);
        {
            let kept = &*kept;
            blocked
                .par_iter_mut()
                .zip(self.fresh_flags.par_iter_mut())
                .zip(rays.par_iter().zip(pixel.par_iter()))
                .with_min_len(1024)
                .for_each(|((b, new), (r, &(s, _)))| {
                    let (k, answer) = &kept[base + s as usize];
                    // Not blocked and not kept read the same here; `new` tells them
                    // apart.
                    let same = same(k, r);
                    *b = same && *answer;
                    *new = !same;
                });
        }
        select(&mut self.need, &self.fresh_flags, |&f| f);
        if 2 * self.need.len() > rays.len() {
            whole(rays, blocked);
            // The new rays' static answers: false where nothing blocks them, else
            // traced.
            let mut traced = std::mem::take(&mut self.answers);
            self.gathered.clear();
            self.gathered.par_extend(
                self.need
                    .par_iter()
                    .filter(|&&i| blocked[i as usize])
                    .map(|&i| rays[i as usize]),
            );
            traced.clear();
            traced.resize(self.gathered.len(), false);
            layers.static_occluded_batch(&self.gathered, &mut traced);
            let mut answers = traced.iter();
            for &i in &self.need {
                let i = i as usize;
                let a = blocked[i] && answers.next().copied().unwrap_or(true);
                kept[base + pixel[i].0 as usize] = (rays[i], a);
            }
            self.answers = traced;
            return;
        }
        if !self.need.is_empty() {
            gather(&mut self.gathered, &self.need, rays);
            self.answers.clear();
            self.answers.resize(self.need.len(), false);
            layers.static_occluded_batch(&self.gathered, &mut self.answers);
            for (&i, &a) in self.need.iter().zip(&self.answers) {
                let i = i as usize;
                kept[base + pixel[i].0 as usize] = (rays[i], a);
                blocked[i] = a;
            }
        }
        // The moving triangles, for the rays no static one blocks.
        select(&mut self.need, blocked, |&b| !b);
        if self.need.is_empty() {
            return;
        }
        gather(&mut self.gathered, &self.need, rays);
        self.answers.clear();
        self.answers.resize(self.need.len(), false);
        layers.moving_occluded_batch(&self.gathered, &mut self.answers);
        for (&i, &a) in self.need.iter().zip(&self.answers) {
            blocked[i as usize] = a;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame fills the memo only where the sequence's next frame has its camera, and
    /// reuses what it holds whenever its camera is the one that filled it: a still
    /// stretch fills at its first frame and reuses from the second; a camera that moves
    /// on, a last frame and a frame rendered alone fill nothing.
    #[test]
    fn the_memo_fills_for_the_next_frame_only_and_reuses_while_the_camera_stays() {
        let cam = |x: f32| CameraModel::framing(Vec3::new(x, 0.0, 0.0), Vec3::ONE, 8, 6);
        let (a, b, c) = (cam(0.0), cam(0.5), cam(-0.5));
        let mut memo = StaticMemo::default();
        let pixels = 48;
        // (camera, the next frame's camera the same) -> mode
        let frames = [
            (a, true, Mode::Fill),
            (a, true, Mode::Reuse),
            // The stretch's last frame: what is held still serves it.
            (a, false, Mode::Reuse),
            // Moving on.
            (b, false, Mode::Off),
            // Stopping here: the next frame has this camera.
            (c, true, Mode::Fill),
            (c, true, Mode::Reuse),
        ];
        for (k, (camera, ahead, want)) in frames.into_iter().enumerate() {
            let mode = memo.begin(&camera, 1, pixels, true, ahead);
            assert_eq!(mode, want, "frame {k}");
            memo.end(mode);
        }
        // Rendered alone: nothing to keep for.
        assert_eq!(
            StaticMemo::default().begin(&a, 1, pixels, true, false),
            Mode::Off
        );
        // Several samples a pixel or no static part of its own: never.
        assert_eq!(
            StaticMemo::default().begin(&a, 4, pixels, true, true),
            Mode::Off
        );
        assert_eq!(
            StaticMemo::default().begin(&a, 1, pixels, false, true),
            Mode::Off
        );
    }

    /// The budgets the constants' docs state.
    #[test]
    fn what_is_kept_at_each_size_is_as_documented() {
        assert_eq!(std::mem::size_of::<(Ray, bool)>(), 36);
        assert_eq!(std::mem::size_of::<(Ray, Option<Hit>)>(), 52);
        let at = |w: usize, h: usize| (levels_kept(w * h), lights_kept(w * h));
        assert_eq!(at(640, 480), (2, 8));
        assert_eq!(at(1920, 1080), (2, 1));
        assert_eq!(at(4096, 2160), (0, 0));
    }
}
