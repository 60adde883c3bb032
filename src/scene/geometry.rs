//! World-space triangles for the tracer: morph targets, then skinning or the node's world
//! transform, then normals (inverse transpose; flat from the posed triangle where the file
//! has none, as the glTF spec asks).

use glam::{Mat3, Mat4, Vec2, Vec3};

use super::animation::{ClipSelection, Pose};
use super::split::{Instance, Split};
use super::Scene;

/// Flat per-triangle arrays, one entry per triangle, in world space. Kept across frames:
/// [`Scene::dynamic_triangles_at`] clears and refills it without giving memory back.
#[derive(Clone, Debug, Default)]
pub struct TriangleSoup {
    pub positions: Vec<[Vec3; 3]>,
    /// Unit shading normals per corner (zero for a degenerate triangle without normals).
    pub normals: Vec<[Vec3; 3]>,
    /// `TEXCOORD_0` per corner, `(0, 0)` where the primitive has none.
    pub uvs: Vec<[Vec2; 3]>,
    /// Index into [`Scene::materials`].
    pub material: Vec<u32>,
    /// The node that placed the triangle (index into [`Scene::nodes`](super::Scene)).
    pub node: Vec<u32>,
    scratch: Scratch,
}

/// Per-frame working memory, reused.
#[derive(Clone, Debug, Default)]
struct Scratch {
    pose: Pose,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    joints: Vec<Mat4>,
}

impl TriangleSoup {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    pub fn clear(&mut self) {
        self.positions.clear();
        self.normals.clear();
        self.uvs.clear();
        self.material.clear();
        self.node.clear();
    }

    /// Axis-aligned bounds of all corners, `None` when empty.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut it = self.positions.iter().flatten();
        let first = *it.next()?;
        Some(it.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))))
    }
}

impl Scene {
    /// The static instances of `split`, posed at t = 0 of `split.selection` (for static
    /// instances every t gives the same triangles: see the split rules).
    pub fn static_triangles(&self, split: &Split) -> TriangleSoup {
        let mut out = TriangleSoup::new();
        self.triangles_into(&split.static_instances, split.selection, 0.0, &mut out);
        out
    }

    /// The dynamic instances of `split` at time `t`, sampled with the clips the split was
    /// decided for (`split.selection`, so the two always agree). `out` is cleared and
    /// refilled; triangle count and order are the same at every `t`, except where a
    /// point cache changes its face list (a fluid surface): its triangles are those of
    /// the sample held at `t`.
    pub fn dynamic_triangles_at(&self, split: &Split, t: f32, out: &mut TriangleSoup) {
        self.triangles_shown(&split.dynamic_instances, split.selection, t, t, out);
    }

    /// The dynamic instances' triangles shown at time `shown`, posed at `t`: the same
    /// triangles in the same order as [`Scene::dynamic_triangles_at`] at `shown`, each
    /// where it is at `t` (the motion AOV's next frame). A point cache whose face list
    /// at `t` is another carries the points shown by their velocities (see
    /// [`PointCache::points_at`](super::PointCache::points_at)).
    pub fn dynamic_triangles_carried(
        &self,
        split: &Split,
        t: f32,
        shown: f32,
        out: &mut TriangleSoup,
    ) {
        self.triangles_shown(&split.dynamic_instances, split.selection, t, shown, out);
    }

    /// World-space bounds of every instance of the shown scene at time `t`.
    pub fn bounds_at(&self, sel: ClipSelection, t: f32) -> Option<(Vec3, Vec3)> {
        let mut soup = TriangleSoup::new();
        self.triangles_into(&self.instances(), sel, t, &mut soup);
        soup.bounds()
    }

    /// Triangles of `instances` posed at `t`, into `out` (cleared first).
    pub fn triangles_into(
        &self,
        instances: &[Instance],
        sel: ClipSelection,
        t: f32,
        out: &mut TriangleSoup,
    ) {
        self.triangles_shown(instances, sel, t, t, out);
    }

    /// Triangles of `instances` shown at `shown` and posed at `t`, into `out`.
    fn triangles_shown(
        &self,
        instances: &[Instance],
        sel: ClipSelection,
        t: f32,
        shown: f32,
        out: &mut TriangleSoup,
    ) {
        out.clear();
        let mut scratch = std::mem::take(&mut out.scratch);
        self.pose_into(sel, t, &mut scratch.pose);
        for inst in instances {
            match self.point_cache(inst.mesh, inst.primitive) {
                Some(cache) => self.append_cached(inst, cache, t, shown, &mut scratch, out),
                None => self.append_instance(inst, &mut scratch, out),
            }
        }
        out.scratch = scratch;
    }

    /// A primitive of time-sampled points: the face list shown at `shown`, its points
    /// at `t`, placed by the node's world transform; flat normals.
    fn append_cached(
        &self,
        inst: &Instance,
        cache: &super::PointCache,
        t: f32,
        shown: f32,
        s: &mut Scratch,
        out: &mut TriangleSoup,
    ) {
        let prim = &self.meshes[inst.mesh].primitives[inst.primitive];
        let topo = cache.topology_at(shown);
        cache.points_at(t, shown, &mut s.positions);
        let m = s.pose.world[inst.node];
        for p in &mut s.positions {
            *p = m.transform_point3(*p);
        }
        let points = &s.positions;
        let point = |v: u32| -> Vec3 {
            let i = match &topo.vertex_point {
                Some(map) => map.get(v as usize).map_or(usize::MAX, |&p| p as usize),
                None => v as usize,
            };
            // `validate` checks every index against every sample of its topology.
            points.get(i).copied().unwrap_or(Vec3::ZERO)
        };
        for &[a, b, c] in &topo.triangles {
            let tri = [point(a), point(b), point(c)];
            let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero();
            out.positions.push(tri);
            out.normals.push([n; 3]);
            out.uvs.push(match &topo.uvs {
                Some(uv) => [a, b, c].map(|v| uv.get(v as usize).copied().unwrap_or(Vec2::ZERO)),
                None => [Vec2::ZERO; 3],
            });
            out.material.push(prim.material);
            out.node.push(inst.node as u32);
        }
    }

    fn append_instance(&self, inst: &Instance, s: &mut Scratch, out: &mut TriangleSoup) {
        let node = &self.nodes[inst.node];
        let prim = &self.meshes[inst.mesh].primitives[inst.primitive];
        let nv = prim.positions.len();

        // Morph targets, in mesh space.
        s.positions.clear();
        s.positions.extend_from_slice(&prim.positions);
        s.normals.clear();
        if let Some(n) = &prim.normals {
            s.normals.extend_from_slice(n);
        }
        let has_normals = s.normals.len() == nv;
        for (target, &w) in prim
            .morph_targets
            .iter()
            .zip(s.pose.morph_weights(inst.node))
        {
            if w == 0.0 {
                continue;
            }
            for (p, d) in s.positions.iter_mut().zip(&target.positions) {
                *p += w * *d;
            }
            if has_normals {
                for (n, d) in s.normals.iter_mut().zip(&target.normals) {
                    *n += w * *d;
                }
            }
        }

        // Skinning (the node's own transform is ignored, glTF §3.7.3.3) or rigid.
        let skin = node
            .skin
            .and_then(|k| self.skins.get(k))
            .filter(|_| prim.influence_sets() > 0);
        if let Some(skin) = skin {
            s.joints.clear();
            s.joints.extend(
                skin.joints
                    .iter()
                    .zip(&skin.inverse_bind_matrices)
                    .map(|(&j, ibm)| s.pose.world[j] * *ibm),
            );
            let sets = prim.influence_sets();
            for v in 0..nv {
                let mut m = Mat4::ZERO;
                for k in v * sets..(v + 1) * sets {
                    for (&j, &w) in prim.joints[k].iter().zip(&prim.weights[k]) {
                        if w != 0.0 {
                            m += s.joints[usize::from(j)] * w;
                        }
                    }
                }
                s.positions[v] = m.transform_point3(s.positions[v]);
                if has_normals {
                    s.normals[v] = (normal_matrix(&m) * s.normals[v]).normalize_or_zero();
                }
            }
        } else {
            let m = s.pose.world[inst.node];
            let nm = normal_matrix(&m);
            for p in &mut s.positions {
                *p = m.transform_point3(*p);
            }
            if has_normals {
                for n in &mut s.normals {
                    *n = (nm * *n).normalize_or_zero();
                }
            }
        }

        for &[a, b, c] in &prim.triangles {
            let (a, b, c) = (a as usize, b as usize, c as usize);
            let tri = [s.positions[a], s.positions[b], s.positions[c]];
            out.positions.push(tri);
            out.normals.push(if has_normals {
                [s.normals[a], s.normals[b], s.normals[c]]
            } else {
                let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero();
                [n; 3]
            });
            out.uvs.push(match &prim.uvs {
                Some(uv) => [uv[a], uv[b], uv[c]],
                None => [Vec2::ZERO; 3],
            });
            out.material.push(prim.material);
            out.node.push(inst.node as u32);
        }
    }
}

/// The matrix that carries normals: the cofactor matrix of the upper 3×3 (the inverse
/// transpose times the determinant), sign-corrected so mirrored transforms keep normals
/// pointing out. Defined even for singular matrices, unlike the inverse.
fn normal_matrix(m: &Mat4) -> Mat3 {
    let a = m.x_axis.truncate();
    let b = m.y_axis.truncate();
    let c = m.z_axis.truncate();
    let cof = Mat3::from_cols(b.cross(c), c.cross(a), a.cross(b));
    if a.dot(b.cross(c)) < 0.0 {
        -cof
    } else {
        cof
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_matrix_is_inverse_transpose_up_to_scale() {
        let m = Mat4::from_scale_rotation_translation(
            Vec3::new(2.0, 0.5, 3.0),
            glam::Quat::from_rotation_y(0.7),
            Vec3::new(1.0, 2.0, 3.0),
        );
        let expected = Mat3::from_mat4(m).inverse().transpose();
        let n = Vec3::new(0.3, -0.4, 0.8).normalize();
        let got = (normal_matrix(&m) * n).normalize();
        let want = (expected * n).normalize();
        assert!(got.abs_diff_eq(want, 1e-6), "{got} vs {want}");
        let mirror = Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let got = (normal_matrix(&mirror) * Vec3::X).normalize();
        assert!(got.abs_diff_eq(-Vec3::X, 1e-6));
    }
}
