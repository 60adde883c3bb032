//! The cache of static point grids: what a batch leaves for later batches ([`Keep`]),
//! the least recently used dropped beyond the capacity, and the static triangles' copy in
//! the test's form.

use std::sync::Arc;

use glam::Vec3;
use rayon::prelude::*;

use super::types::{Around, CacheState, PointCache, Sources, StaticGrid, KEPT};
use crate::geometry::TriPre;

impl Default for CacheState {
    fn default() -> Self {
        CacheState {
            grids: Vec::new(),
            stamp: 0,
            seen: Vec::new(),
            capacity: KEPT,
        }
    }
}

impl CacheState {
    /// Drops the least recently used grid.
    fn drop_oldest(&mut self) {
        let oldest = (0..self.grids.len())
            .min_by_key(|&i| self.grids[i].0)
            .unwrap_or(0);
        self.grids.remove(oldest);
    }
}

impl std::fmt::Debug for PointCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let grids = self.state.lock().map_or(0, |s| s.grids.len());
        f.debug_struct("PointCache").field("grids", &grids).finish()
    }
}

impl PointCache {
    /// `statics` (the static triangles this cache's PSF holds, always the same) in the
    /// test's form, made on first use (in parallel) and kept: the point grids test
    /// them so, and so does the parallel subfields' walk, where `intersect_pre` on
    /// them took fewer instructions than `intersect_triangle` on the plain vertices,
    /// with the same bits (benches/PERF.md, issue 38, round 9).
    pub(crate) fn pre_of(&self, statics: &[[Vec3; 3]]) -> &Arc<[TriPre]> {
        if let Some(p) = self.pre.get() {
            return p;
        }
        // Made outside any lock: two threads that both find it missing make equal
        // copies, and the one set first is kept.
        let p: Arc<[TriPre]> = statics.par_iter().map(TriPre::new).collect();
        self.pre.get_or_init(|| p)
    }

    /// The grids kept now.
    pub(crate) fn len(&self) -> usize {
        self.lock().grids.len()
    }

    /// How many grids are kept at most: [`KEPT`] unless set.
    pub(crate) fn capacity(&self) -> usize {
        self.lock().capacity
    }

    /// Keeps at most `capacity` grids from now on (0: none), dropping the least
    /// recently used beyond it now.
    pub(crate) fn set_capacity(&self, capacity: usize) {
        let mut st = self.lock();
        st.capacity = capacity;
        while st.grids.len() > capacity {
            st.drop_oldest();
        }
    }

    /// Drops every kept grid and the points seen; the capacity stays, and so does the
    /// static triangles' copy in the test's form (the parallel subfields' walk reads it).
    pub(crate) fn clear(&self) {
        let mut st = self.lock();
        let capacity = st.capacity;
        *st = CacheState {
            capacity,
            ..CacheState::default()
        };
    }

    pub(super) fn lock(&self) -> std::sync::MutexGuard<'_, CacheState> {
        // A panic elsewhere while the lock was held leaves a consistent state: every
        // change below is a single push, removal or assignment.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The static triangles in the test's form, made once and kept in the cache.
pub(super) fn static_pre(src: &Sources) -> Arc<[TriPre]> {
    src.cache.pre_of(src.statics).clone()
}

/// What a batch's grids leave in the cache for later batches.
pub(super) enum Keep {
    /// A point that took no grid: one of the points seen (the most recent [`KEPT`]).
    Seen(Around),
    /// A static grid built for the batch, kept (least recently used dropped beyond
    /// the capacity) in place of the one it `replaces`.
    Grid {
        fresh: Arc<StaticGrid>,
        replaces: Option<Arc<StaticGrid>>,
    },
}

impl Keep {
    pub(super) fn enter(self, cache: &PointCache) {
        let mut st = cache.lock();
        match self {
            Keep::Seen(at) => {
                st.seen.retain(|s| (s.c - at.c).length() > at.r);
                st.seen.push(at);
                if st.seen.len() > KEPT {
                    st.seen.remove(0);
                }
            }
            Keep::Grid { fresh, replaces } => {
                st.stamp += 1;
                let stamp = st.stamp;
                let at = fresh.at;
                st.seen.retain(|s| (s.c - at.c).length() > at.r);
                if let Some(g) = &replaces {
                    st.grids.retain(|(_, x)| !Arc::ptr_eq(x, g));
                }
                st.grids.push((stamp, fresh));
                if st.grids.len() > st.capacity {
                    st.drop_oldest();
                }
            }
        }
    }
}
