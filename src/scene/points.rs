//! Point caches: a primitive whose points are given at sample times (a simulation cache,
//! USD's time-sampled `points`), possibly with a different face list at each sample
//! (changing topology, a fluid surface).
//!
//! Rules (USD's own, `UsdAttribute::Get` under linear interpolation, and what renderers
//! do with `velocities`):
//! * before the first sample the first holds, after the last the last;
//! * between two samples of the same topology (same face list, same point count) the
//!   points interpolate linearly;
//! * between two samples of different topology the earlier sample's points are carried
//!   by its `velocities` (units per second) when it has them, else held;
//! * normals are not cached: a cached primitive has flat normals from its posed
//!   triangles (the reader warns when time-varying normals are dropped).
//!
//! Posing works at any time `t` (sub-frame times for motion blur), not only at samples.

use glam::{Vec2, Vec3};

/// The triangles of one face list, and the per-vertex attributes that go with it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Topology {
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
    /// Which point each vertex shows (vertices split where a face-varying attribute
    /// needs it); `None`: vertex `i` is point `i`.
    pub vertex_point: Option<Vec<u32>>,
    /// Texture coordinates per vertex; `None` gives `(0, 0)`.
    pub uvs: Option<Vec<Vec2>>,
}

impl Topology {
    /// Number of vertices the triangles index.
    pub fn vertex_count(&self, points: usize) -> usize {
        self.vertex_point.as_ref().map_or(points, Vec::len)
    }
}

/// The points of one sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointSample {
    /// Points in the primitive's (mesh) space.
    pub points: Vec<Vec3>,
    /// Velocity of every point (units per second), when the file gives them.
    pub velocities: Option<Vec<Vec3>>,
    /// Index into [`PointCache::topologies`].
    pub topology: u32,
}

/// The time-sampled points of one primitive (`Scene::meshes[mesh].primitives[primitive]`,
/// whose own arrays hold the first sample, so code that does not pose still sees a mesh).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCache {
    pub mesh: usize,
    pub primitive: usize,
    /// Sample times in seconds, strictly increasing; as many as `samples`.
    pub times: Vec<f32>,
    pub samples: Vec<PointSample>,
    /// Distinct face lists, shared by the samples that use them.
    pub topologies: Vec<Topology>,
}

impl PointCache {
    /// The sample that holds at `t`: the last at or before it (the first before all).
    pub fn held(&self, t: f32) -> usize {
        self.times.partition_point(|&x| x <= t).saturating_sub(1)
    }

    /// The topology shown at `t`.
    pub fn topology_at(&self, t: f32) -> &Topology {
        let k = self.held(t);
        &self.topologies[self.samples[k].topology as usize]
    }

    /// Whether samples `a` and `b` can be interpolated (same face list and point count).
    fn same_shape(&self, a: usize, b: usize) -> bool {
        let (sa, sb) = (&self.samples[a], &self.samples[b]);
        sa.topology == sb.topology && sa.points.len() == sb.points.len()
    }

    /// The points at `t` of the topology shown at `shown` (normally `shown == t`; the
    /// motion AOV asks for the next frame's points of this frame's triangles). Where the
    /// topology at `t` is not the one at `shown`, the points of the sample held at
    /// `shown` are carried by its velocities to `t` (held without them). Into `out`,
    /// cleared first.
    pub fn points_at(&self, t: f32, shown: f32, out: &mut Vec<Vec3>) {
        out.clear();
        let k = self.held(shown);
        let j = self.held(t);
        if !self.same_shape(j, k) {
            return self.carry(k, t, out);
        }
        if t > self.times[j] && j + 1 < self.times.len() {
            if !self.same_shape(j, j + 1) {
                return self.carry(j, t, out);
            }
            let (t0, t1) = (self.times[j], self.times[j + 1]);
            let s = (t - t0) / (t1 - t0);
            let (a, b) = (&self.samples[j].points, &self.samples[j + 1].points);
            out.extend(a.iter().zip(b).map(|(&p, &q)| p * (1.0 - s) + q * s));
            return;
        }
        out.extend_from_slice(&self.samples[j].points);
    }

    /// The points of sample `k` carried by its velocities to `t` (held without them).
    fn carry(&self, k: usize, t: f32, out: &mut Vec<Vec3>) {
        let base = &self.samples[k];
        match &base.velocities {
            Some(v) => {
                let dt = t - self.times[k];
                out.extend(base.points.iter().zip(v).map(|(&p, &v)| p + v * dt));
            }
            None => out.extend_from_slice(&base.points),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(points: &[f32], velocities: Option<&[f32]>, topology: u32) -> PointSample {
        let v3 = |a: &[f32]| a.iter().map(|&x| Vec3::splat(x)).collect::<Vec<_>>();
        PointSample {
            points: v3(points),
            velocities: velocities.map(v3),
            topology,
        }
    }

    fn cache() -> PointCache {
        PointCache {
            mesh: 0,
            primitive: 0,
            times: vec![1.0, 2.0, 3.0, 4.0],
            samples: vec![
                sample(&[0.0, 10.0], None, 0),
                sample(&[2.0, 12.0], None, 0),
                sample(&[5.0, 6.0, 7.0], Some(&[1.0, 1.0, 1.0]), 1),
                sample(&[9.0], None, 2),
            ],
            topologies: vec![Topology::default(); 3],
        }
    }

    fn at(c: &PointCache, t: f32, shown: f32) -> Vec<f32> {
        let mut out = Vec::new();
        c.points_at(t, shown, &mut out);
        out.iter().map(|p| p.x).collect()
    }

    #[test]
    fn interpolates_within_a_topology_holds_outside() {
        let c = cache();
        assert_eq!(at(&c, 0.0, 0.0), [0.0, 10.0]);
        assert_eq!(at(&c, 1.5, 1.5), [1.0, 11.0]);
        assert_eq!(at(&c, 2.0, 2.0), [2.0, 12.0]);
        assert_eq!(at(&c, 9.0, 9.0), [9.0]);
        assert_eq!(c.held(2.5), 1);
        assert_eq!(c.held(0.5), 0);
    }

    #[test]
    fn a_topology_change_is_carried_by_velocities_or_held() {
        let c = cache();
        // Sample 2 has velocities: carried forward to 3.5, not blended into sample 3.
        assert_eq!(at(&c, 3.5, 3.5), [5.5, 6.5, 7.5]);
        // Sample 1 has none and the next differs: held.
        assert_eq!(at(&c, 2.5, 2.5), [2.0, 12.0]);
        // The next frame's points of this frame's triangles: carried across the change.
        assert_eq!(at(&c, 4.0, 3.0), [6.0, 7.0, 8.0]);
        // Same topology at both times: plain interpolation at the later time.
        assert_eq!(at(&c, 1.5, 1.0), [1.0, 11.0]);
    }
}
