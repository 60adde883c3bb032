//! A still camera's shading, kept from frame to frame and replayed.
//!
//! Shading a ray ([`ShadeContext::shade`]) is a function of the ray, its bookkeeping
//! ([`Item`]), its hit and the frame's shading context: where the triangle hit is static
//! and the context has not changed (the same lights to the bit, the same scene extent,
//! no random numbers drawn), the same three give the same contributions, the same shadow
//! rays and the same next ray, to the bit. A camera that stays put sends the same camera
//! rays every frame, and most of them meet the same static triangle and spawn the same
//! mirror rays; so per sample and level the ray, item and hit are kept with what their
//! shading pushed, and a ray equal to the kept one in all three gets the kept pushes
//! instead of being shaded again (benches/PERF.md, issue 38, round 3). Anything else (a
//! moving triangle hit, a mover in front, a ray that pushed more than one of a kind) is
//! shaded as always, and kept for the next frame where it can be.
//!
//! Only for one sample a pixel (the sample is the pixel), without the light-path passes
//! or motion blur, and where the memo of static hits reuses what it kept (a camera that
//! has not moved since the frame before), or that fills it with the camera of the
//! sequence's next frame: a moving camera's rays never repeat, so keeping them would
//! only cost. So the first frame of a still camera keeps, the second replays.
//!
//! A sample can go further: where its kept shading would be replayed at every level
//! and none of its rays can meet a moving triangle this frame or the last, its sums are
//! the last frame's, and it is not shaded at all ([`ShadeReplay::settled`]): most
//! samples of a still camera's frame whose motion is clustered (302,000 of 307,200 on
//! the shared generator's scene at 640x480), which had each replayed two levels and sent
//! their rays again (benches/PERF.md, issue 38, round 11).
//!
//! Memory: 216 bytes a pixel and level ([`Kept`]) plus 52 a pixel, light and level,
//! within the budget a render gives the slots for every level together (`render
//! --replay-bytes`, hidden; none by default, below): with 256 MB, the camera rays and
//! the mirror level at 640x480 with one light (157 MB), the camera rays alone at
//! 1280x720 (247 MB); nothing either with more than [`REPLAY_LIGHTS`] lights. A test
//! holds these numbers.
//! The last frame's sums take 16 bytes a pixel besides, and the settled samples' records
//! ([`Settle`]) `20 + 32 · (2 · lights + 1)` (116 with one light, 34 MB at 640x480; none
//! beyond [`SETTLE_LIGHTS`] lights).
//!
//! Where no level's slots fit (always with the default budget, none), the records are
//! kept alone, within [`RECORD_BYTES`], and the shading writes them as it shades a
//! sample ([`ShadeReplay::records`]): what the settled check would have found in the
//! slots (the camera ray's static hit, the shadow rays of both levels, the mirror ray up
//! to its static hit, nothing sent further) is what the shading just pushed, so a
//! record made so is one the check would have made. Without slots nothing is replayed
//! for the samples that do not settle, and a record serves only a frame through the
//! camera it was made with. 132 bytes a pixel with the sums (274 MB at 1920x1080, one
//! light), against 536 for two levels of slots: a still camera's 1920x1080 frames on 2
//! threads went from 440 to 306–340 ms a frame (benches/PERF.md, issue 38, round 24).
//! At 640x480 too the slots' memory cost more than their replay saved: with the
//! records alone the benches' still camera on 2 threads took 0.59–0.63 s for 8 frames
//! against 0.79–0.82, 1.02–1.12 s for 24 against 1.23–1.48, and as long for 60 and 120,
//! in 418–562 MB against 832–886 MB (round 28). So the default gives the slots
//! nothing, at every size.

use glam::Vec3;

use rayon::prelude::*;

use super::memo::{copy_all, copy_par, fill_par};
use super::shade::{BlockOut, Item, ShadeContext, REPLAY_LIGHTS};
use crate::geometry::{same_words, Aabb, Hit, Ray};
use crate::psf::{BoxTest, Prim};

/// Levels whose shading is kept, at most (the camera rays' and the mirror's).
const REPLAY_LEVELS: usize = 2;

/// One sample's shading at one level: the ray, item and hit it was shaded for, and what
/// it pushed (at most one of each kind; its shadow rays are in [`ShadeReplay`]'s
/// `shadows`).
#[derive(Clone, Copy)]
pub(super) struct Kept {
    valid: bool,
    ray: Ray,
    item: Item,
    hit: Hit,
    add: Option<(u32, Vec3)>,
    cover: Option<(u32, f32)>,
    next: Option<(Ray, Item)>,
}

const EMPTY: Kept = Kept {
    valid: false,
    ray: Ray {
        origin: Vec3::ZERO,
        dir: Vec3::ZERO,
        t_min: 0.0,
        t_max: 0.0,
    },
    item: Item::NONE,
    hit: Hit {
        t: 0.0,
        tri: u32::MAX,
        u: 0.0,
        v: 0.0,
    },
    add: None,
    cover: None,
    next: None,
};

/// A kept shadow ray: the ray and what it adds to which sample when unblocked.
pub(super) type KeptShadow = Option<(Ray, (u32, Vec3))>;

/// The shading kept from the frames before (see the module's notes).
#[derive(Default)]
pub(super) struct ShadeReplay {
    /// The context the kept shading was made in: the scene's extent and the lights, as
    /// bits.
    key: Vec<u32>,
    /// Per level, per sample.
    kept: Vec<Vec<Kept>>,
    /// Per level, per sample and punctual light (`sample * lights + light`).
    shadows: Vec<Vec<KeptShadow>>,
    lights: usize,
    /// The last frame's radiance and coverage per sample, for the settled samples of the
    /// next ([`ShadeReplay::settled`]); `None` until a frame has kept them.
    last: Option<Last>,
    /// Per sample, what [`ShadeReplay::settled`] found when its slots last passed the
    /// whole check ([`Settle`]); empty where the lights are more than [`SETTLE_LIGHTS`].
    settle: Vec<Settle>,
    /// Per sample, [`Settle`]'s rays: the kept shadow rays of both levels, then (last of
    /// `2 · lights + 1`) the mirror ray up to its kept hit.
    segments: Vec<Ray>,
    /// Only the [`Settle`] records are kept, written by the shading itself (where two
    /// levels of slots would not fit: [`records_fit`]); `kept` and `shadows` are empty.
    records_only: bool,
}

/// What a settled sample's check needs of its slots, kept apart from them: later frames
/// read these 20 bytes and `2 · lights + 1` rays (116 bytes with one light) instead of
/// two levels' slots and shadow slots (536 bytes with one light), which the check had
/// streamed from memory for every sample of every frame (benches/PERF.md, issue 38,
/// round 12). Made when a sample's slots pass [`ShadeReplay::settled`]'s whole check;
/// `eligible` only while the slots stay as they were then: a sample not settled is
/// shaded, which may rewrite them, so it is made ineligible, and every sample is when the
/// camera is not the one of the lane's frame before (a camera ray is then another ray).
#[derive(Clone, Copy)]
pub(super) struct Settle {
    /// The camera ray's kept hit.
    hit: Hit,
    /// The kept shadow rays of both levels (the first `segments`; at most
    /// `2 · SETTLE_LIGHTS`).
    shadows: u8,
    /// Whether the kept shading sends a mirror ray (the last segment).
    mirror: bool,
    eligible: bool,
    /// Records only ([`ShadeReplay::records`]): the camera ray's shading was recorded
    /// this frame and its mirror ray's is still to come (not yet eligible).
    pending: bool,
}

const NOT_SETTLED: Settle = Settle {
    hit: EMPTY.hit,
    shadows: 0,
    mirror: false,
    eligible: false,
    pending: false,
};

/// The most punctual lights for which [`Settle`] records are kept: beyond, its rays
/// would take as many bytes as the slots.
const SETTLE_LIGHTS: usize = 2;

/// A frame's sums per sample (one sample a pixel) and the moving triangles' bounds it
/// was traced with.
struct Last {
    bounds: BoxTest,
    radiance: Vec<Vec3>,
    coverage: Vec<f32>,
    /// Samples written by this frame's chunks so far, in order (`usize::MAX` once a
    /// chunk came out of order).
    written: usize,
    /// The frame before wrote every sample: what the settled samples may take.
    complete: bool,
}

/// The levels whose slots fit within `budget` bytes (0 by default: none).
fn levels_within(samples: usize, lights: usize, budget: usize) -> usize {
    if lights > REPLAY_LIGHTS {
        return 0;
    }
    let per_level =
        samples.max(1) * (std::mem::size_of::<Kept>() + lights * std::mem::size_of::<KeptShadow>());
    (budget / per_level).min(REPLAY_LEVELS)
}

/// Whether a still camera's frames of `samples` samples have no room for slots within
/// `budget` (0, the default: none) even with one light, so that they keep the records
/// alone (or nothing): the frame that fills them is worth rendering alone and copying,
/// rather than one a frame in flight (`render::sequence`).
pub(super) fn slots_do_not_fit(samples: usize, budget: usize) -> bool {
    levels_within(samples, 1, budget) == 0
}

/// The memory a frame's [`Settle`] records may take where no slots are kept (records
/// only): 132 bytes a pixel with one light (the record, its three rays and the last
/// frame's sums), 274 MB at 1920x1080, 196 bytes with two.
pub(super) const RECORD_BYTES: usize = 512 << 20;

/// Whether `samples` samples' records and last sums, with `lights` punctual lights, fit
/// within `budget` bytes (none beyond [`SETTLE_LIGHTS`] lights).
fn records_fit(samples: usize, lights: usize, budget: usize) -> bool {
    let per = std::mem::size_of::<Settle>()
        + (2 * lights + 1) * std::mem::size_of::<Ray>()
        + std::mem::size_of::<Vec3>()
        + std::mem::size_of::<f32>();
    lights <= SETTLE_LIGHTS && samples.saturating_mul(per) <= budget
}

/// The bits of the shading context that may change from frame to frame.
fn key_of(ctx: &ShadeContext<'_>) -> Vec<u32> {
    let mut k = vec![ctx.extent.to_bits(), ctx.lights.len() as u32];
    for l in &ctx.lights {
        k.extend(l.bits());
    }
    k
}

impl ShadeReplay {
    /// Starts a frame of `samples` samples: `on` where the replay may serve (see the
    /// module's notes). Kept shading made in another context is dropped. The levels it
    /// keeps this frame.
    ///
    /// `budget`: the bytes the slots may take (none unless the options say
    /// otherwise). Where no level of slots fits (always with the default) but the
    /// [`Settle`] records do (within [`RECORD_BYTES`]), only the records are kept,
    /// written by the shading itself ([`ShadeReplay::records`]): the samples that settle
    /// are most of a still camera's frame, and what the slots add beyond them (shading
    /// replayed for the samples that do not settle) is not worth their 536 bytes a
    /// pixel (the module's notes). The levels returned are then the two the records
    /// cover.
    pub(super) fn begin(
        &mut self,
        ctx: &ShadeContext<'_>,
        on: bool,
        samples: usize,
        budget: usize,
    ) -> usize {
        let lights = ctx.punctual_lights();
        let allowed = on && !ctx.random;
        let mut levels = if allowed {
            levels_within(samples, lights, budget)
        } else {
            0
        };
        let records_only = allowed && levels == 0 && records_fit(samples, lights, RECORD_BYTES);
        if records_only {
            levels = REPLAY_LEVELS;
        }
        if levels == 0 {
            // Nothing kept while off: the memory goes back.
            *self = ShadeReplay::default();
            return 0;
        }
        let key = key_of(ctx);
        let fits = self.key == key
            && self.lights == lights
            && self.records_only == records_only
            && if records_only {
                self.settle.len() == samples
            } else {
                self.kept.len() == levels && self.kept.iter().all(|k| k.len() == samples)
            };
        if let Some(l) = &mut self.last {
            l.complete = l.written == samples && l.radiance.len() == samples;
            l.written = 0;
        }
        if !fits {
            self.last = None;
            self.key = key;
            self.lights = lights;
            self.records_only = records_only;
            if records_only {
                self.kept = Vec::new();
                self.shadows = Vec::new();
                self.fill_records(samples);
            } else {
                // Set up on every thread (`memo::fill_par`).
                self.kept.resize_with(levels, Vec::new);
                for k in &mut self.kept {
                    fill_par(k, samples, EMPTY);
                }
                self.shadows.resize_with(levels, Vec::new);
                for k in &mut self.shadows {
                    fill_par(k, samples * lights, None);
                }
                self.reset_settle(samples);
            }
        }
        levels
    }

    /// Every sample's record made ineligible and its rays emptied, `samples` of them.
    fn fill_records(&mut self, samples: usize) {
        fill_par(&mut self.settle, samples, NOT_SETTLED);
        fill_par(
            &mut self.segments,
            samples * (2 * self.lights + 1),
            EMPTY.ray,
        );
    }

    /// Takes what `from` keeps, as if this replay had kept it: each kept push is tied
    /// to the ray, item and hit it was shaded for and to the context's key, so any frame
    /// may replay it (see [`StaticMemo::copy_kept`](super::memo::StaticMemo::copy_kept)).
    ///
    /// Records alone are taken with `from`'s last frame's sums and moving bounds: an
    /// eligible record's rays were answered by the static triangles alone in the last
    /// frame that shaded its sample, and the sums `from` keeps are those answers' sums,
    /// whichever lane renders next; the settled check then holds the rays to `from`'s
    /// last frame's moving triangles and to this frame's, as it would in `from`. So the
    /// frame a lane renders after the copy settles its samples as `from`'s next would.
    pub(super) fn copy_kept(&mut self, from: &ShadeReplay) {
        self.key.clone_from(&from.key);
        copy_all(&mut self.kept, &from.kept);
        copy_all(&mut self.shadows, &from.shadows);
        self.lights = from.lights;
        self.records_only = from.records_only;
        if self.records_only {
            copy_par(&mut self.settle, &from.settle);
            copy_par(&mut self.segments, &from.segments);
            self.last = from.last.as_ref().map(|l| {
                let mut radiance = Vec::new();
                let mut coverage = Vec::new();
                copy_par(&mut radiance, &l.radiance);
                copy_par(&mut coverage, &l.coverage);
                Last {
                    bounds: l.bounds,
                    radiance,
                    coverage,
                    written: l.written,
                    complete: l.complete,
                }
            });
        } else {
            // The sums of this lane's last frame are not those of the kept shading
            // copied.
            self.last = None;
            self.reset_settle(self.kept.first().map_or(0, Vec::len));
        }
    }

    /// Every sample's [`Settle`] record made ineligible (none kept beyond
    /// [`SETTLE_LIGHTS`] lights).
    fn reset_settle(&mut self, samples: usize) {
        if self.lights <= SETTLE_LIGHTS && !self.kept.is_empty() {
            fill_par(&mut self.settle, samples, NOT_SETTLED);
            let empty = EMPTY.ray;
            fill_par(&mut self.segments, samples * (2 * self.lights + 1), empty);
        } else {
            self.settle = Vec::new();
            self.segments = Vec::new();
        }
    }

    /// Which of a chunk's camera rays (`rays`, samples `base..`, one a pixel; `hits`
    /// their closest hits this frame, `item(i)` their bookkeeping) are settled: their
    /// sample's sums this frame are the last frame's, to the bit, so that the sample
    /// need not be shaded at all (`None`: no sample is, as where nothing was kept).
    /// With them, the rays the settled samples stand for (their kept shadow and mirror
    /// rays, sent last frame and not this one), so that a frame's ray counts stay those
    /// of its picture: (shadow rays, secondary rays).
    ///
    /// Why. A sample's sums are a function of the rays its shading sends and their
    /// answers (shading is a function of ray, item, hit and the context, which
    /// [`ShadeReplay::begin`] holds to the kept one), summed in an order those rays fix.
    /// A sample is settled when its kept shading at level 0 is valid for this frame's
    /// camera ray, item and hit (a static hit, so no moving triangle is in front), the
    /// mirror ray it sends (if any) has a valid kept shading at level 1 that sends no
    /// ray further, and every shadow ray of both levels, and the mirror ray up to its
    /// kept static hit, miss the bounds of the moving triangles of this frame and of the
    /// last (`Layers::moving_bounds`: no moving triangle meets such a ray). A kept slot
    /// is rewritten whenever its sample is shaded (valid only for a static hit), so in
    /// the last frame those very rays were sent and answered by the static part alone,
    /// or the sample was settled then, with the same sums by the same argument; and this
    /// frame they would be again.
    ///
    /// `same_camera`: the camera is the one of this lane's frame before (the memo
    /// reuses), so each camera ray and item are the ones of that frame. Then a sample
    /// whose record ([`Settle`]) is eligible is checked by the record alone: its slots
    /// passed this whole check when it was made and have not changed since (a sample
    /// not settled drops its record, the camera being another drops every record), so
    /// only the hit and the moving bounds are left to compare.
    pub(super) fn settled(
        &mut self,
        base: usize,
        rays: &[Ray],
        hits: &[Option<Hit>],
        item: &(dyn Fn(usize) -> Item + Sync),
        bounds: Option<Aabb>,
        same_camera: bool,
    ) -> Option<(Vec<bool>, (u64, u64))> {
        let n = rays.len();
        let lights = self.lights;
        // Per sample: its record, its rays; `None` where none are kept.
        let m = 2 * lights + 1;
        let records = (self.settle.len() >= base + n && self.segments.len() >= (base + n) * m)
            .then(|| {
                (
                    &mut self.settle[base..base + n],
                    &mut self.segments[base * m..(base + n) * m],
                )
            });
        let ready = (|| {
            let last = self.last.as_ref().filter(|l| l.complete)?;
            Some((last.bounds, BoxTest::new(bounds?)))
        })();
        // Records alone (no slots to check them against) serve only where the camera
        // is the one they were made with.
        let ready = ready.filter(|_| !self.records_only || same_camera);
        // No slots with records alone: the whole check finds nothing, the quick one serves.
        let level0 = self.kept.first().map_or(&[][..], Vec::as_slice);
        let shadows0 = self.shadows.first().map_or(&[][..], Vec::as_slice);
        let Some((before, now)) = ready else {
            // No sample is settled: each is shaded, which may rewrite its slots.
            if let Some((records, _)) = records {
                records.par_iter_mut().for_each(|r| r.eligible = false);
            }
            return None;
        };
        let level1 = self.kept.get(1);
        let shadows1 = self.shadows.get(1);
        // Sample `p`'s shadow slots in a level's list, one a light.
        let slots = |p: usize| p * lights..(p + 1) * lights;
        // One test against the two frames' boxes together: a ray that misses their
        // union misses each, also as `BoxTest::misses` computes it (a box inside another
        // gets slab values inside the other's, rounding being monotonic), and a
        // sample's rays make two tests where they made four.
        let both = BoxTest::new(before.aabb().union(&now.aabb()));
        let misses_both = |r: &Ray| both.misses(r);
        let shadows_miss = |s: &[KeptShadow]| {
            s.iter()
                .all(|k| k.as_ref().is_none_or(|(r, _)| misses_both(r)))
        };
        let sent = |s: &[KeptShadow]| s.iter().filter(|k| k.is_some()).count() as u64;
        // The whole check of sample `p` (camera ray `ray`, its hit this frame `hit`),
        // reading its slots: `Some` with the rays a settled sample's kept shading
        // sends, and (where `seg` is given) its record made in `rec` and `seg`.
        let whole = |i: usize,
                     ray: &Ray,
                     hit: &Option<Hit>,
                     keep: Option<(&mut Settle, &mut [Ray])>|
         -> Option<(u64, u64)> {
            let p = base + i;
            let (k0, h, s0) = (level0.get(p)?, hit.as_ref()?, shadows0.get(slots(p))?);
            if !(k0.valid
                && same_words(&k0.hit.bits(), &h.bits())
                && k0.ray.same_bits(ray)
                && same_words(&k0.item.bits(), &item(i).bits())
                && shadows_miss(s0))
            {
                return None;
            }
            let (counts, s1, to_hit) = match k0.next {
                None => ((sent(s0), 0), None, None),
                Some((r1, i1)) => {
                    let (k1, s1) = (level1?.get(p)?, shadows1?.get(slots(p))?);
                    let to_hit = Ray {
                        t_max: k1.hit.t,
                        ..r1
                    };
                    let ok = k1.valid
                        && k1.next.is_none()
                        && k1.ray.same_bits(&r1)
                        && same_words(&k1.item.bits(), &i1.bits())
                        && now.misses(&to_hit)
                        && shadows_miss(s1);
                    if !ok {
                        return None;
                    }
                    ((sent(s0) + sent(s1), 1), Some(s1), Some(to_hit))
                }
            };
            if let Some((rec, seg)) = keep {
                let kept = s0.iter().chain(s1.into_iter().flatten());
                let mut k = 0;
                for (r, _) in kept.flatten() {
                    seg[k] = *r;
                    k += 1;
                }
                if let Some(r) = to_hit {
                    seg[m - 1] = r;
                }
                *rec = Settle {
                    hit: k0.hit,
                    shadows: k as u8,
                    mirror: to_hit.is_some(),
                    eligible: true,
                    pending: false,
                };
            }
            Some(counts)
        };
        // What a sample whose record is eligible needs: the same hit, and its rays
        // missing the moving triangles' bounds (as `whole` tests them).
        let quick = |rec: &Settle, seg: &[Ray], hit: &Option<Hit>| -> Option<(u64, u64)> {
            let h = hit.as_ref()?;
            let shadows = seg.get(..rec.shadows as usize)?;
            (same_words(&rec.hit.bits(), &h.bits())
                && shadows.iter().all(misses_both)
                && (!rec.mirror || now.misses(&seg[m - 1])))
            .then_some((rec.shadows.into(), rec.mirror.into()))
        };
        let prefetch = |p: usize| {
            prefetch_slot(level0.get(p), shadows0.get(p * lights));
            prefetch_slot(
                level1.and_then(|l| l.get(p)),
                shadows1.and_then(|l| l.get(p * lights)),
            );
        };
        let mut each: Vec<Option<(u64, u64)>> = vec![None; n];
        match records {
            Some((records, segments)) => {
                // A task's run of samples, so that it reads ahead (for the slots of the
                // samples its whole check will read) in records it owns.
                const RUN: usize = 1024;
                each.par_chunks_mut(RUN)
                    .zip(records.par_chunks_mut(RUN))
                    .zip(segments.par_chunks_mut(RUN * m))
                    .enumerate()
                    .for_each(|(c, ((out, recs), segs))| {
                        let i0 = c * RUN;
                        for k in 0..out.len() {
                            let i = i0 + k;
                            if let Some(ahead) = recs.get(k + PREFETCH_AHEAD) {
                                if !(same_camera && ahead.eligible) {
                                    prefetch(base + i + PREFETCH_AHEAD);
                                }
                            }
                            let (rec, seg) = (&mut recs[k], &mut segs[k * m..(k + 1) * m]);
                            out[k] = if same_camera && rec.eligible {
                                quick(rec, seg, &hits[i])
                            } else {
                                whole(i, &rays[i], &hits[i], Some((&mut *rec, &mut *seg)))
                            };
                            if out[k].is_none() {
                                // Shaded this frame: its slots may change.
                                rec.eligible = false;
                            }
                        }
                    });
            }
            None => each
                .par_iter_mut()
                .enumerate()
                .with_min_len(1024)
                .for_each(|(i, out)| {
                    prefetch(base + i + PREFETCH_AHEAD);
                    *out = whole(i, &rays[i], &hits[i], None);
                }),
        }
        let stood_for = each
            .par_iter()
            .flatten()
            .copied()
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        Some((each.par_iter().map(Option::is_some).collect(), stood_for))
    }

    /// After a chunk's levels (samples `base..` of a frame of `samples`, its sums in
    /// `radiance` and `coverage`): the settled samples take the last frame's sums, the
    /// others' are kept for the next frame. `settled`: [`ShadeReplay::settled`]'s answer
    /// for the chunk; `bounds`: this frame's moving bounds.
    pub(super) fn sums(
        &mut self,
        base: usize,
        samples: usize,
        settled: Option<&[bool]>,
        radiance: &mut [Vec3],
        coverage: &mut [f32],
        bounds: Option<Aabb>,
    ) {
        let Some(bounds) = bounds else {
            self.last = None;
            return;
        };
        let last = self.last.get_or_insert_with(|| Last {
            bounds: BoxTest::EMPTY,
            radiance: Vec::new(),
            coverage: Vec::new(),
            written: 0,
            complete: false,
        });
        if last.radiance.len() != samples {
            last.radiance = vec![Vec3::ZERO; samples];
            last.coverage = vec![0.0; samples];
            last.complete = false;
        }
        let n = radiance.len();
        if base != last.written || base + n > samples || coverage.len() != n {
            last.written = usize::MAX;
            return;
        }
        let (lr, lc) = (
            &mut last.radiance[base..base + n],
            &mut last.coverage[base..base + n],
        );
        radiance
            .par_iter_mut()
            .zip(coverage.par_iter_mut())
            .zip(lr.par_iter_mut().zip(lc.par_iter_mut()))
            .enumerate()
            .with_min_len(1024)
            .for_each(|(i, ((r, c), (lr, lc)))| {
                if settled.is_some_and(|s| s[i]) {
                    *r = *lr;
                    *c = *lc;
                } else {
                    *lr = *r;
                    *lc = *c;
                }
            });
        last.written = base + n;
        if last.written == samples {
            // The frame's last chunk: the next frame compares with these bounds.
            last.bounds = BoxTest::new(bounds);
        }
    }

    /// Level `level`'s kept shading and shadow rays, if it keeps any.
    pub(super) fn level(
        &mut self,
        level: usize,
    ) -> Option<(&mut [Kept], &mut [KeptShadow], usize)> {
        let lights = self.lights;
        match (self.kept.get_mut(level), self.shadows.get_mut(level)) {
            (Some(k), Some(s)) => Some((k, s, lights)),
            _ => None,
        }
    }

    /// Where only the records are kept, what level `level`'s shading writes them into
    /// (the camera rays' and their mirror rays'): the records and their rays, a sample's
    /// `2 · lights + 1` of them.
    pub(super) fn records(&mut self, level: usize) -> Option<(&mut [Settle], &mut [Ray], usize)> {
        (self.records_only && level < REPLAY_LEVELS)
            .then(|| (&mut self.settle[..], &mut self.segments[..], self.lights))
    }
}

/// A sample's kept shading at one level: its slot and shadow slots, or (records only,
/// [`ShadeReplay::records`]) its record and rays at level 0 or 1.
pub(super) enum Slot<'a> {
    Kept(&'a mut Kept, &'a mut [KeptShadow]),
    Record {
        level: usize,
        rec: &'a mut Settle,
        rays: &'a mut [Ray],
    },
}

/// Shades `ray` (its `item`, its `hit`) into `out`, or replays what `slot` kept for the
/// same three; keeps what the shading pushed in `slot` where it can (a static hit, at
/// most one push of each kind). `slot` `None`: shaded as always.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn shade_kept(
    ctx: &ShadeContext<'_>,
    ray: &Ray,
    item: &Item,
    hit: Option<Hit>,
    max_depth: u32,
    spp: u32,
    out: &mut BlockOut,
    slot: Option<Slot<'_>>,
) {
    // Records are written after the block's shading (`record_block`), not here.
    let Some(Slot::Kept(kept, shadows)) = slot else {
        ctx.shade(ray, item, hit, max_depth, spp, out);
        return;
    };
    let static_hit = hit.filter(|h| {
        matches!(
            Prim::from_index(h.tri, ctx.static_soup.len()),
            Prim::Static(_)
        )
    });
    let Some(h) = static_hit else {
        kept.valid = false;
        ctx.shade(ray, item, hit, max_depth, spp, out);
        return;
    };
    if kept.valid
        && same_words(&kept.hit.bits(), &h.bits())
        && kept.ray.same_bits(ray)
        && same_words(&kept.item.bits(), &item.bits())
    {
        if let Some(a) = kept.add {
            out.add.push(a);
        }
        if let Some(c) = kept.cover {
            out.cover.push(c);
        }
        for (light, s) in shadows.iter().enumerate() {
            if let Some((r, add)) = s {
                out.push_shadow(*r, light, *add);
            }
        }
        if let Some((r, i)) = kept.next {
            out.next(r, i);
        }
        return;
    }
    let before = out.lengths(shadows.len());
    ctx.shade(ray, item, hit, max_depth, spp, out);
    kept.valid = false;
    let Some(pushed) = out.pushed_since(&before, shadows.len()) else {
        return;
    };
    kept.ray = *ray;
    kept.item = *item;
    kept.hit = h;
    kept.add = pushed.add.then(|| out.add[out.add.len() - 1]);
    kept.cover = pushed.cover.then(|| out.cover[out.cover.len() - 1]);
    kept.next = pushed.next.then(|| {
        let n = out.next_rays.len() - 1;
        (out.next_rays[n], out.next_items[n])
    });
    for (light, s) in shadows.iter_mut().enumerate() {
        *s = out.last_shadow_since(&before, light);
    }
    kept.valid = true;
}

/// Records only: writes the records of a block's samples from what the block's shading
/// pushed (`out`, the block shaded in lanes or a ray at a time), what
/// [`ShadeReplay::settled`]'s whole check would have found in the slots: at level 0 (the
/// camera ray) its static hit and shadow rays, and whether it sends a mirror ray; at
/// level 1 (that mirror ray) the ray up to its static hit and its shadow rays. The
/// record is eligible once both are written, or after level 0 where no mirror ray is
/// sent, and only where every shading involved met a static triangle, pushed at most one
/// element of each kind and (at level 1) no ray further. A record is written whenever
/// its sample is shaded, so an eligible one describes the last frame that shaded it.
/// `rays` gives each of the block's rays that were shaded, in order: its sample, the
/// ray, its hit and whether it is its sample's only ray at the level. Each list of `out`
/// holds a ray's pushes after the ones of the rays before it, each tagged with the ray's
/// sample (the lanes push as the rays would one at a time), so a sample's pushes are the
/// run of its entries at each list's cursor.
pub(super) fn record_block<'r>(
    ctx: &ShadeContext<'_>,
    slots: &mut BlockSlots<'_>,
    rays: impl Iterator<Item = (usize, &'r Ray, Option<Hit>, bool)>,
    out: &BlockOut,
) {
    let Parts::Records { per, .. } = slots.parts else {
        return;
    };
    let lights = per / 2;
    // Lists the check does not cover (the passes' split, batches past the punctual
    // lights): nothing recorded.
    let covered = out.split.is_empty() && out.shadow.len() <= lights && lights <= SETTLE_LIGHTS;
    let (mut add, mut cover, mut next) = (0usize, 0usize, 0usize);
    let mut shadow = [0usize; 2 * SETTLE_LIGHTS];
    // The entries at `*at` on tagged with sample `s`: how many, the cursor moved past.
    fn run(at: &mut usize, len: usize, s: usize, tag: impl Fn(usize) -> u32) -> usize {
        let from = *at;
        while *at < len && tag(*at) as usize == s {
            *at += 1;
        }
        *at - from
    }
    for (s, ray, hit, alone) in rays {
        let n_add = run(&mut add, out.add.len(), s, |i| out.add[i].0);
        let n_cover = run(&mut cover, out.cover.len(), s, |i| out.cover[i].0);
        let n_next = run(&mut next, out.next_items.len(), s, |i| {
            out.next_items[i].sample
        });
        let mut sent: [Option<Ray>; 2 * SETTLE_LIGHTS] = [None; 2 * SETTLE_LIGHTS];
        let mut single = n_add <= 1 && n_cover <= 1 && n_next <= 1;
        for (l, list) in out.shadow.iter().enumerate().take(lights) {
            let at = &mut shadow[l];
            let before = *at;
            let n = run(at, list.add.len(), s, |i| list.add[i].0);
            single &= n <= 1;
            if n == 1 {
                sent[l] = list.rays.get(before).copied();
            }
        }
        let Some(Slot::Record { level, rec, rays }) = slots.get(s) else {
            continue;
        };
        let static_hit = hit.filter(|h| {
            matches!(
                Prim::from_index(h.tri, ctx.static_soup.len()),
                Prim::Static(_)
            )
        });
        let (Some(h), true, true, Some(last)) = (
            static_hit,
            single && covered,
            alone,
            rays.len().checked_sub(1),
        ) else {
            *rec = NOT_SETTLED;
            continue;
        };
        if level > 0 && !rec.pending {
            *rec = NOT_SETTLED;
            continue;
        }
        let mut k = if level == 0 { 0 } else { rec.shadows as usize };
        let mut fits = true;
        for r in sent.iter().take(lights).flatten() {
            match rays.get_mut(k).filter(|_| k < last) {
                Some(slot) => *slot = *r,
                None => fits = false,
            }
            k += 1;
        }
        if !fits {
            *rec = NOT_SETTLED;
        } else if level == 0 {
            *rec = Settle {
                hit: h,
                shadows: k as u8,
                mirror: n_next == 1,
                eligible: n_next == 0,
                pending: n_next == 1,
            };
        } else if n_next > 0 {
            *rec = NOT_SETTLED;
        } else {
            rays[last] = Ray { t_max: h.t, ..*ray };
            rec.shadows = k as u8;
            rec.eligible = true;
            rec.pending = false;
        }
    }
}

/// The kept slots (or records) one block of rays owns: from sample `start` on.
pub(super) struct BlockSlots<'a> {
    start: usize,
    parts: Parts<'a>,
}

enum Parts<'a> {
    Kept {
        kept: &'a mut [Kept],
        shadows: &'a mut [KeptShadow],
        lights: usize,
    },
    Records {
        level: usize,
        settle: &'a mut [Settle],
        rays: &'a mut [Ray],
        per: usize,
    },
}

/// Asks the cache for a kept slot's four lines and its first shadow slot (either may be
/// absent), which a loop will read some samples later.
#[inline(always)]
fn prefetch_slot(kept: Option<&Kept>, shadow: Option<&KeptShadow>) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        if let Some(k) = kept {
            let p = std::ptr::from_ref(k).cast::<i8>();
            for line in (0..std::mem::size_of::<Kept>()).step_by(64) {
                // SAFETY: `prefetch` only hints the cache: it reads nothing the program
                // sees, writes nothing and never faults, whatever the address;
                // `wrapping_add` makes the address without any claim that it is in
                // bounds.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(line)) };
            }
        }
        if let Some(sh) = shadow {
            let p = std::ptr::from_ref(sh).cast::<i8>();
            // SAFETY: as above, a hint that cannot fault or be observed.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (kept, shadow);
}

/// How many samples ahead [`BlockSlots::prefetch`] asks for a slot.
pub(super) const PREFETCH_AHEAD: usize = 8;

impl BlockSlots<'_> {
    /// Whether these are records, which the shading writes ([`record_block`]) and
    /// nothing replays: a block may then be shaded in lanes.
    pub(super) fn records_only(&self) -> bool {
        matches!(self.parts, Parts::Records { .. })
    }

    /// Asks the cache for sample `s`'s slot (its kept shading and shadow rays), which
    /// the loop will read [`PREFETCH_AHEAD`] samples later: a slot is 216 bytes, so a
    /// page holds 19 of them and the hardware's stream prefetcher, which stops at page
    /// boundaries, left the first read of each slot waiting on memory (11 % of a still
    /// camera's CPU at 640x480 on the `valid` flag's line; benches/PERF.md, issue 38,
    /// round 11). Records are written, not read: nothing to ask for.
    #[inline(always)]
    pub(super) fn prefetch(&self, s: usize) {
        let Some(i) = s.checked_sub(self.start) else {
            return;
        };
        if let Parts::Kept {
            kept,
            shadows,
            lights,
        } = &self.parts
        {
            prefetch_slot(kept.get(i), shadows.get(i * lights));
        }
    }

    /// Sample `s`'s slot, if this block owns it.
    #[inline]
    pub(super) fn get(&mut self, s: usize) -> Option<Slot<'_>> {
        let i = s.checked_sub(self.start)?;
        match &mut self.parts {
            Parts::Kept {
                kept,
                shadows,
                lights,
            } => {
                let kept = kept.get_mut(i)?;
                let shadows = shadows.get_mut(i * *lights..(i + 1) * *lights)?;
                Some(Slot::Kept(kept, shadows))
            }
            Parts::Records {
                level,
                settle,
                rays,
                per,
            } => {
                let rec = settle.get_mut(i)?;
                let rays = rays.get_mut(i * *per..(i + 1) * *per)?;
                Some(Slot::Record {
                    level: *level,
                    rec,
                    rays,
                })
            }
        }
    }
}

/// `a` (one element a sample) and `b` (`stride` a sample) cut into what each block owns:
/// block `b` the samples from `starts[b]` up to the next block's start (the last block up
/// to the end), with the first sample each part holds. `starts` must not decrease (a
/// level's rays are in sample order); a sample two blocks share belongs to the first,
/// and is not kept anyway (it has more than one ray).
fn owned<'a, A, B>(
    a: &'a mut [A],
    b: &'a mut [B],
    stride: usize,
    starts: &[usize],
) -> Vec<(usize, &'a mut [A], &'a mut [B])> {
    let mut out = Vec::with_capacity(starts.len());
    let (mut a, mut b) = (a, b);
    let mut at = starts.first().copied().unwrap_or(0).min(a.len());
    let skip = (at * stride).min(b.len());
    a = &mut a[at..];
    b = &mut b[skip..];
    for (k, &start) in starts.iter().enumerate() {
        let end = starts
            .get(k + 1)
            .copied()
            .unwrap_or(usize::MAX)
            .max(start)
            .min(at + a.len());
        let n = end.saturating_sub(at);
        let (x, rest) = std::mem::take(&mut a).split_at_mut(n);
        let cut = (n * stride).min(b.len());
        let (y, yrest) = std::mem::take(&mut b).split_at_mut(cut);
        out.push((at, x, y));
        a = rest;
        b = yrest;
        at = end;
    }
    out
}

/// A level's slots cut into what each block of rays owns ([`owned`]'s rule).
pub(super) fn block_slots<'a>(
    kept: &'a mut [Kept],
    shadows: &'a mut [KeptShadow],
    lights: usize,
    starts: &[usize],
) -> Vec<BlockSlots<'a>> {
    owned(kept, shadows, lights, starts)
        .into_iter()
        .map(|(start, kept, shadows)| BlockSlots {
            start,
            parts: Parts::Kept {
                kept,
                shadows,
                lights,
            },
        })
        .collect()
}

/// Level `level`'s records and their rays (`per` a sample) cut into what each block of
/// rays owns ([`owned`]'s rule), for the shading to write ([`ShadeReplay::records`]).
pub(super) fn block_records<'a>(
    level: usize,
    settle: &'a mut [Settle],
    rays: &'a mut [Ray],
    per: usize,
    starts: &[usize],
) -> Vec<BlockSlots<'a>> {
    owned(settle, rays, per, starts)
        .into_iter()
        .map(|(start, settle, rays)| BlockSlots {
            start,
            parts: Parts::Records {
                level,
                settle,
                rays,
                per,
            },
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The levels 256 MB of slots keep for `samples` samples and `lights` punctual
    /// lights (none beyond [`REPLAY_LIGHTS`] lights).
    fn levels_replayed(samples: usize, lights: usize) -> usize {
        levels_within(samples, lights, 256 << 20)
    }

    #[test]
    fn what_is_kept_at_each_size_is_as_documented() {
        let kept = std::mem::size_of::<Kept>();
        let shadow = std::mem::size_of::<KeptShadow>();
        println!("Kept: {kept} bytes, a shadow: {shadow} bytes");
        assert_eq!(levels_replayed(640 * 480, 1), 2);
        assert_eq!(levels_replayed(1280 * 720, 1), 1);
        assert_eq!(levels_replayed(1920 * 1080, 1), 0);
        assert_eq!(levels_replayed(640 * 480, REPLAY_LIGHTS + 1), 0);
        // Two levels at 640x480 with one light, in the module's notes: about 150 MB.
        let two = 2 * 640 * 480 * (kept + shadow);
        assert!((140 << 20..=160 << 20).contains(&two), "{two} bytes");
        // What a settled sample's check reads of it: its slots (536 bytes), or its
        // record and rays (116), one light.
        assert_eq!(2 * (kept + shadow), 536);
        let record = std::mem::size_of::<Settle>() + 3 * std::mem::size_of::<Ray>();
        assert_eq!(record, 116);
        let records = 640 * 480 * record;
        assert!((33 << 20..=35 << 20).contains(&records), "{records} bytes");
        // Records alone where no slots fit: 1920x1080 with one or two lights, not 4K
        // (the module's notes and `RECORD_BYTES`).
        let hd = 1920 * 1080;
        assert!(records_fit(hd, 1, RECORD_BYTES) && records_fit(hd, 2, RECORD_BYTES));
        assert!(!records_fit(hd, SETTLE_LIGHTS + 1, RECORD_BYTES));
        assert!(!records_fit(3840 * 2160, 1, RECORD_BYTES));
        let one = record + std::mem::size_of::<Vec3>() + std::mem::size_of::<f32>();
        assert_eq!(one, 132);
        assert!(
            (270_000_000..=275_000_000).contains(&(hd * one)),
            "{} bytes",
            hd * one
        );
    }

    #[test]
    fn each_block_owns_the_samples_from_its_start_to_the_next() {
        let mut kept = vec![EMPTY; 10];
        let mut shadows = vec![None; 20];
        let mut views = block_slots(&mut kept, &mut shadows, 2, &[1, 3, 3, 7]);
        let owned: Vec<Vec<usize>> = views
            .iter_mut()
            .map(|v| (0..12).filter(|&s| v.get(s).is_some()).collect())
            .collect();
        assert_eq!(
            owned,
            vec![vec![1, 2], vec![], vec![3, 4, 5, 6], vec![7, 8, 9]]
        );
        // Sample 4's two shadow slots are its own.
        let Some(Slot::Kept(_, sh)) = views[2].get(4) else {
            panic!("sample 4 has a slot")
        };
        assert_eq!(sh.len(), 2);
        sh[1] = Some((EMPTY.ray, (4, Vec3::ONE)));
        drop(views);
        assert!(shadows[9].is_some() && shadows.iter().filter(|s| s.is_some()).count() == 1);
    }
}
