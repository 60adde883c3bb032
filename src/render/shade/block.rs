//! A wavefront's bookkeeping: what a ray adds to which sample ([`Item`]), and what a
//! block of rays' shading hands on ([`BlockOut`]): contributions, shadow rays a light at
//! a time, and the next level's rays.

use glam::{Vec3, Vec3A};

use super::LightPath;
use super::{Cone, Split};
use crate::geometry::Ray;
use crate::render::sampling::Seed;

/// A ray's bookkeeping: which sample it adds to, with what weight.
#[derive(Clone, Copy, Debug)]
pub(in crate::render) struct Item {
    pub(in crate::render) sample: u32,
    pub(in crate::render) weight: Vec3,
    /// Share of the sample's coverage (alpha) this ray decides (primary rays and their
    /// pass-through continuations; 0 for secondary rays).
    pub(in crate::render) coverage: f32,
    pub(in crate::render) depth: u32,
    pub(in crate::render) passes: u16,
    /// Diffuse bounces taken on the way to this ray (`--diffuse-bounces`).
    pub(in crate::render) bounces: u8,
    /// The ray leaves a diffuse bounce: what it meets of the emitters was counted by the
    /// bounce's own shadow rays to them, so it adds no emission (no double counting).
    pub(in crate::render) diffuse: bool,
    /// The ray's own random numbers.
    pub(in crate::render) seed: Seed,
    pub(in crate::render) cone: Cone,
    /// The light-path pass this ray's light goes to; `None` for a camera ray (and its
    /// pass-through continuations) until its hit decides (see [`LightPath`]).
    pub(in crate::render) path: Option<LightPath>,
}

impl Item {
    /// No ray's bookkeeping (a placeholder).
    pub(in crate::render) const NONE: Item = Item {
        sample: u32::MAX,
        weight: Vec3::ZERO,
        coverage: 0.0,
        depth: 0,
        passes: 0,
        bounces: 0,
        diffuse: false,
        seed: Seed(0),
        cone: Cone {
            width: 0.0,
            spread: 0.0,
        },
        path: None,
    };

    /// The bits of every field, for an exact comparison.
    #[inline]
    pub(in crate::render) fn bits(&self) -> [u32; 12] {
        [
            self.sample,
            self.weight.x.to_bits(),
            self.weight.y.to_bits(),
            self.weight.z.to_bits(),
            self.coverage.to_bits(),
            self.depth,
            u32::from(self.passes) | u32::from(self.bounces) << 16 | u32::from(self.diffuse) << 24,
            self.seed.0 as u32,
            (self.seed.0 >> 32) as u32,
            self.cone.width.to_bits(),
            self.cone.spread.to_bits(),
            self.path.map_or(u32::MAX, |p| p as u32),
        ]
    }
}

/// The most punctual lights whose shadow rays [`BlockOut::lengths`] follows (and the
/// replay of a still camera's shading keeps, `render::replay`).
pub(in crate::render) const REPLAY_LIGHTS: usize = 8;

/// The lengths of a [`BlockOut`]'s lists at some point, to see what one ray's shading
/// pushed.
pub(in crate::render) struct Lengths {
    add: usize,
    split: usize,
    cover: usize,
    next: usize,
    shadow: [usize; REPLAY_LIGHTS],
    shadow_lists: usize,
}

impl Lengths {
    /// Shadow batch `i`'s length (0 for a batch that was not there yet).
    fn shadow_at(&self, i: usize) -> usize {
        if i < self.shadow_lists {
            self.shadow.get(i).copied().unwrap_or(usize::MAX)
        } else {
            0
        }
    }
}

/// Which of a [`BlockOut`]'s lists one ray's shading pushed to (one element each).
pub(in crate::render) struct Pushed {
    pub(in crate::render) add: bool,
    pub(in crate::render) cover: bool,
    pub(in crate::render) next: bool,
}

/// A block's shadow rays towards one light, each with what it adds to which sample
/// when unblocked.
#[derive(Default)]
pub(in crate::render) struct ShadowList {
    pub(in crate::render) rays: Vec<Ray>,
    pub(in crate::render) add: Vec<(u32, Vec3)>,
    /// `add`'s contributions split over the light-path passes (only when
    /// [`BlockOut::light_paths`]).
    pub(in crate::render) split: Vec<Split>,
}

#[derive(Default)]
pub(in crate::render) struct BlockOut {
    /// Whether the light-path passes are traced: then every contribution also goes,
    /// split, to `split` (and the shadow lists' `split`).
    pub(in crate::render) light_paths: bool,
    pub(in crate::render) add: Vec<(u32, Vec3)>,
    pub(in crate::render) split: Vec<(u32, Split)>,
    pub(in crate::render) cover: Vec<(u32, f32)>,
    /// The shadow rays a light at a time (index: the light's batch, see
    /// [`ShadeContext::shade`]'s lights and the area lights' batch after them).
    pub(in crate::render) shadow: Vec<ShadowList>,
    pub(in crate::render) next_rays: Vec<Ray>,
    pub(in crate::render) next_items: Vec<Item>,
}

impl BlockOut {
    /// Empties every list, keeping their capacity (a frame's blocks are reused).
    pub(in crate::render) fn clear(&mut self) {
        self.add.clear();
        self.split.clear();
        self.cover.clear();
        for l in &mut self.shadow {
            l.rays.clear();
            l.add.clear();
            l.split.clear();
        }
        self.next_rays.clear();
        self.next_items.clear();
    }

    /// `c` to the beauty of `sample` and, when the passes are traced, `split()` (`c`
    /// split over them) to the passes; nothing when `c` is 0 or not finite.
    #[inline]
    pub(super) fn add_split(&mut self, sample: u32, c: Vec3A, split: impl FnOnce() -> Split) {
        // `c != 0` (NaN included) and finite, in lanes, without a branch between them.
        if c.cmpne(Vec3A::ZERO).any() & c.is_finite() {
            self.add.push((sample, c.into()));
            if self.light_paths {
                self.split.push((sample, split()));
            }
        }
    }
    #[inline]
    pub(super) fn cover(&mut self, sample: u32, c: f32) {
        if c > 0.0 {
            self.cover.push((sample, c));
        }
    }
    /// A shadow ray towards batch `light` that adds `c` (split: `split()`) to `sample`
    /// when unblocked.
    #[inline]
    pub(super) fn shadow(
        &mut self,
        ray: Ray,
        light: usize,
        sample: u32,
        c: Vec3,
        split: impl FnOnce() -> Split,
    ) {
        if self.shadow.len() <= light {
            self.shadow.resize_with(light + 1, ShadowList::default);
        }
        let l = &mut self.shadow[light];
        l.rays.push(ray);
        l.add.push((sample, c));
        if self.light_paths {
            l.split.push(split());
        }
    }
    #[inline]
    pub(in crate::render) fn next(&mut self, ray: Ray, item: Item) {
        self.next_rays.push(ray);
        self.next_items.push(item);
    }

    /// A shadow ray towards batch `light` that adds `add.1` to sample `add.0` when
    /// unblocked (without the passes' split: not for [`BlockOut::light_paths`]).
    #[inline]
    pub(in crate::render) fn push_shadow(&mut self, ray: Ray, light: usize, add: (u32, Vec3)) {
        if self.shadow.len() <= light {
            self.shadow.resize_with(light + 1, ShadowList::default);
        }
        let l = &mut self.shadow[light];
        l.rays.push(ray);
        l.add.push(add);
    }

    /// The lists' lengths now (the shadow lists of the first `lights` batches, at most
    /// [`REPLAY_LIGHTS`]).
    pub(in crate::render) fn lengths(&self, lights: usize) -> Lengths {
        let mut shadow = [0; REPLAY_LIGHTS];
        for (n, l) in shadow.iter_mut().zip(self.shadow.iter().take(lights)) {
            *n = l.rays.len();
        }
        Lengths {
            add: self.add.len(),
            split: self.split.len(),
            cover: self.cover.len(),
            next: self.next_rays.len(),
            shadow,
            shadow_lists: self.shadow.len(),
        }
    }

    /// What was pushed since `before`, where that was at most one element to each list
    /// and nothing to the passes' splits or to a shadow batch past the first `lights`;
    /// else `None`.
    pub(in crate::render) fn pushed_since(
        &self,
        before: &Lengths,
        lights: usize,
    ) -> Option<Pushed> {
        let grew = |now: usize, then: usize| now.checked_sub(then).filter(|d| *d <= 1);
        let add = grew(self.add.len(), before.add)?;
        let cover = grew(self.cover.len(), before.cover)?;
        let next = grew(self.next_rays.len(), before.next)?;
        // Without random numbers (the replay's condition) no area light is sampled, so
        // the punctual lights' batches are all there are.
        if self.split.len() != before.split || lights > REPLAY_LIGHTS || self.shadow.len() > lights
        {
            return None;
        }
        for (i, l) in self.shadow.iter().enumerate() {
            grew(l.rays.len(), before.shadow_at(i))?;
        }
        Some(Pushed {
            add: add == 1,
            cover: cover == 1,
            next: next == 1,
        })
    }

    /// The shadow ray batch `light` got since `before` (one at most, see
    /// [`BlockOut::pushed_since`]), with its contribution.
    pub(in crate::render) fn last_shadow_since(
        &self,
        before: &Lengths,
        light: usize,
    ) -> Option<(Ray, (u32, Vec3))> {
        let l = self.shadow.get(light)?;
        let then = before.shadow_at(light);
        (l.rays.len() > then).then(|| (l.rays[l.rays.len() - 1], l.add[l.add.len() - 1]))
    }
}
