//! A wavefront's bookkeeping: what a ray adds to which sample ([`Item`]), and what a
//! block of rays' shading hands on ([`BlockOut`]): contributions, shadow rays a light at
//! a time, and the next level's rays.

use glam::Vec3;

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
    pub(super) fn add_split(&mut self, sample: u32, c: Vec3, split: impl FnOnce() -> Split) {
        if c != Vec3::ZERO && c.is_finite() {
            self.add.push((sample, c));
            if self.light_paths {
                self.split.push((sample, split()));
            }
        }
    }
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
    pub(super) fn next(&mut self, ray: Ray, item: Item) {
        self.next_rays.push(ray);
        self.next_items.push(item);
    }
}
