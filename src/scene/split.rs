//! The static/dynamic split (DESIGN.md §2): which primitive instances are baked once and
//! which are re-inserted every frame.
//!
//! An instance (node × primitive) is dynamic when, for the selected clips:
//! * a TRS channel that *varies* (see `channel_varies`: keyframes not all equal) drives its
//!   node or an ancestor — a constant channel only moves the node once, to where the
//!   static bake (taken at t = 0 of the same selection) already puts it;
//! * it is skinned (the node has a skin and the primitive carries joints), whatever the
//!   joints do — the rule of the issue, conservative and cheap to state;
//! * a varying weights channel drives its node and the primitive has morph targets;
//! * its points are time-sampled (a [`PointCache`](super::PointCache) of two samples or
//!   more), whatever the samples hold.
//!
//! Everything else is static.

use super::animation::{channel_varies, ClipSelection};
use super::{Property, Scene};

/// One primitive placed by one node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Instance {
    pub node: usize,
    pub mesh: usize,
    pub primitive: usize,
    /// Number of triangles it contributes.
    pub triangles: usize,
}

/// Counts for the CLI's report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SplitSummary {
    pub static_instances: usize,
    pub dynamic_instances: usize,
    pub static_triangles: usize,
    pub dynamic_triangles: usize,
}

impl std::fmt::Display for SplitSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "static: {} in {}; dynamic: {} in {}",
            crate::plural(self.static_triangles as u64, "triangle"),
            crate::plural(self.static_instances as u64, "instance"),
            crate::plural(self.dynamic_triangles as u64, "triangle"),
            crate::plural(self.dynamic_instances as u64, "instance"),
        )
    }
}

/// The instances of the shown scene, divided; both lists in scene order (depth first,
/// primitives in mesh order), so triangle ids are stable across frames.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Split {
    /// The clips the split was decided for; geometry extraction samples these.
    pub selection: ClipSelection,
    pub static_instances: Vec<Instance>,
    pub dynamic_instances: Vec<Instance>,
}

impl Split {
    pub fn summary(&self) -> SplitSummary {
        SplitSummary {
            static_instances: self.static_instances.len(),
            dynamic_instances: self.dynamic_instances.len(),
            static_triangles: self.static_instances.iter().map(|i| i.triangles).sum(),
            dynamic_triangles: self.dynamic_instances.iter().map(|i| i.triangles).sum(),
        }
    }
}

impl Scene {
    /// Every primitive instance of the shown scene, in scene order.
    pub fn instances(&self) -> Vec<Instance> {
        let mut out = Vec::new();
        for n in self.scene_nodes() {
            let Some(mesh) = self.nodes[n].mesh else {
                continue;
            };
            for (p, prim) in self.meshes[mesh].primitives.iter().enumerate() {
                out.push(Instance {
                    node: n,
                    mesh,
                    primitive: p,
                    triangles: prim.triangles.len(),
                });
            }
        }
        out
    }

    /// Decides static versus dynamic for every instance (rules in the module docs).
    pub fn split(&self, sel: ClipSelection) -> Split {
        let n = self.nodes.len();
        let mut moves = vec![false; n];
        let mut morphs = vec![false; n];
        for ch in self.selected_clips(sel).iter().flat_map(|a| &a.channels) {
            if ch.node >= n || !channel_varies(ch) {
                continue;
            }
            match ch.property {
                Property::Weights => morphs[ch.node] = true,
                _ => moves[ch.node] = true,
            }
        }
        // Motion is inherited: scene_nodes lists parents before children.
        let order: Vec<usize> = {
            let mut all = Vec::with_capacity(n);
            let mut stack: Vec<usize> =
                (0..n).filter(|&i| self.nodes[i].parent.is_none()).collect();
            while let Some(i) = stack.pop() {
                all.push(i);
                stack.extend(self.nodes[i].children.iter().copied());
            }
            all
        };
        for &i in &order {
            if let Some(p) = self.nodes[i].parent {
                moves[i] |= moves[p];
            }
        }
        let mut split = Split {
            selection: sel,
            static_instances: Vec::new(),
            dynamic_instances: Vec::new(),
        };
        for inst in self.instances() {
            let node = &self.nodes[inst.node];
            let prim = &self.meshes[inst.mesh].primitives[inst.primitive];
            let skinned = node.skin.is_some() && prim.influence_sets() > 0;
            let morphed = morphs[inst.node] && !prim.morph_targets.is_empty();
            let cached = self
                .point_cache(inst.mesh, inst.primitive)
                .is_some_and(|c| c.samples.len() > 1);
            if moves[inst.node] || skinned || morphed || cached {
                split.dynamic_instances.push(inst);
            } else {
                split.static_instances.push(inst);
            }
        }
        split
    }
}
