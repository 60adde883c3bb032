//! Animation sampling: clips → a [`Pose`] (local TRS, world matrices, morph weights) at a
//! time `t`, and the posed cameras and lights.
//!
//! Rules (glTF 2.0 §3.11, and DESIGN.md §4 for clip selection):
//! * before the first keyframe a channel holds its first value, after the last its last;
//! * LINEAR interpolates component-wise, rotations by slerp along the shorter arc;
//!   STEP holds the previous keyframe; CUBICSPLINE is the Hermite spline of the spec,
//!   tangents scaled by the keyframe interval; rotations are renormalised;
//! * by default ([`Scene::default_clips`]) every clip plays when no two clips drive the
//!   same property of the same node; otherwise the first clip plays alone. Where two
//!   channels of the selection drive one property, the later one in file order wins.

use glam::{Mat4, Quat, Vec3};

use super::{Camera, Channel, Interpolation, Light, Property, Scene, SceneError, Trs};

/// Which clips play.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash)]
#[non_exhaustive]
pub enum ClipSelection {
    /// Every clip together (the later clip wins where two drive the same property; the
    /// default selection picks this only when no two clips do, see
    /// [`Scene::default_clips`]).
    #[default]
    All,
    /// One clip, by index into [`Scene::animations`].
    One(usize),
}

/// The state of every node at one time.
#[derive(Clone, Debug, Default)]
pub struct Pose {
    /// Local TRS of every node (the rest transform where no channel drives it).
    pub local: Vec<Trs>,
    /// World-from-node matrix of every node.
    pub world: Vec<Mat4>,
    /// Effective morph weights per node (animated, else `node.weights`, else the mesh's
    /// defaults); empty for nodes without morph targets.
    pub weights: Vec<Vec<f32>>,
    animated: Vec<bool>,
    stack: Vec<usize>,
}

impl Pose {
    /// Morph weights of `node`; an empty slice means all zero.
    pub fn morph_weights(&self, node: usize) -> &[f32] {
        self.weights.get(node).map_or(&[], Vec::as_slice)
    }
}

impl Scene {
    /// Resolves `--animation NAME|INDEX`: an exact clip name first, then an index.
    pub fn resolve_clip(&self, name_or_index: &str) -> Result<ClipSelection, SceneError> {
        if let Some(i) = self
            .animations
            .iter()
            .position(|a| a.name.as_deref() == Some(name_or_index))
        {
            return Ok(ClipSelection::One(i));
        }
        match name_or_index.trim().parse::<usize>() {
            Ok(i) if i < self.animations.len() => Ok(ClipSelection::One(i)),
            _ => Err(SceneError::UnknownClip {
                requested: name_or_index.to_string(),
                available: self.clip_names(),
            }),
        }
    }

    /// The clips played without `--animation`: all of them when no two clips animate the
    /// same target (node and property), else the first clip alone, with a warning (one
    /// line, no `warning: ` prefix) that names the clips left out and `--animation`.
    pub fn default_clips(&self) -> (ClipSelection, Option<String>) {
        let mut owner: std::collections::HashMap<(usize, Property), usize> =
            std::collections::HashMap::new();
        let mut shared = None;
        'clips: for (i, clip) in self.animations.iter().enumerate() {
            for ch in &clip.channels {
                match owner.entry((ch.node, ch.property)) {
                    std::collections::hash_map::Entry::Occupied(e) if *e.get() != i => {
                        shared = Some((*e.get(), i, ch.node, ch.property));
                        break 'clips;
                    }
                    std::collections::hash_map::Entry::Occupied(_) => {}
                    std::collections::hash_map::Entry::Vacant(e) => {
                        e.insert(i);
                    }
                }
            }
        }
        let Some((a, b, node, property)) = shared else {
            return (ClipSelection::All, None);
        };
        let label = |i: usize| match &self.animations[i].name {
            Some(n) => format!("{i} {n:?}"),
            None => format!("{i} (unnamed)"),
        };
        let node_name = match self.nodes.get(node).and_then(|n| n.name.as_deref()) {
            Some(n) => format!("node {node} {n:?}"),
            None => format!("node {node}"),
        };
        let others: Vec<String> = (1..self.animations.len()).map(label).collect();
        let warning = format!(
            "clips {} and {} both animate the {} of {node_name}, so they cannot play together: \
             playing the first clip, {}, alone; not played: {} (choose one with --animation NAME|INDEX)",
            label(a),
            label(b),
            match property {
                Property::Translation => "translation",
                Property::Rotation => "rotation",
                Property::Scale => "scale",
                Property::Weights => "morph weights",
            },
            label(0),
            others.join(", "),
        );
        (ClipSelection::One(0), Some(warning))
    }

    /// The clips that `sel` plays, in file order (empty for an index out of range).
    pub fn selected_clips(&self, sel: ClipSelection) -> &[super::Animation] {
        match sel {
            ClipSelection::All => &self.animations,
            ClipSelection::One(i) => self.animations.get(i..i + 1).unwrap_or(&[]),
        }
    }

    /// Latest keyframe time of the selected clips; 0 without animation.
    pub fn duration(&self, sel: ClipSelection) -> f32 {
        let keys = self
            .selected_clips(sel)
            .iter()
            .flat_map(|a| &a.channels)
            .filter_map(|c| c.times.last().copied());
        let caches = self
            .point_caches
            .iter()
            .filter_map(|c| c.times.last().copied());
        let range = self.time_range.map(|(_, end)| end);
        keys.chain(caches).chain(range).fold(0.0, f32::max)
    }

    /// Earliest and latest keyframe times of the selected clips and of the point caches
    /// (seconds): the authored span a render covers by default; `None` without keys. A
    /// scene's own [`Scene::time_range`] (a USD stage's) takes precedence.
    pub fn key_span(&self, sel: ClipSelection) -> Option<(f32, f32)> {
        if let Some(range) = self.time_range {
            return Some(range);
        }
        let caches = self
            .point_caches
            .iter()
            .filter_map(|c| Some((*c.times.first()?, *c.times.last()?)));
        self.selected_clips(sel)
            .iter()
            .flat_map(|a| &a.channels)
            .filter_map(|c| Some((*c.times.first()?, *c.times.last()?)))
            .chain(caches)
            .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
    }

    /// The pose at time `t` (seconds).
    pub fn pose_at(&self, sel: ClipSelection, t: f32) -> Pose {
        let mut pose = Pose::default();
        self.pose_into(sel, t, &mut pose);
        pose
    }

    /// [`Scene::pose_at`] into an existing pose, reusing its memory.
    pub fn pose_into(&self, sel: ClipSelection, t: f32, pose: &mut Pose) {
        let n = self.nodes.len();
        pose.local.clear();
        pose.local
            .extend(self.nodes.iter().map(|node| node.transform.trs()));
        pose.animated.clear();
        pose.animated.resize(n, false);
        pose.weights.resize(n, Vec::new());
        for (i, node) in self.nodes.iter().enumerate() {
            let w = &mut pose.weights[i];
            w.clear();
            let targets = node
                .mesh
                .and_then(|m| self.meshes.get(m))
                .and_then(|m| m.primitives.first())
                .map_or(0, |p| p.morph_targets.len());
            if targets > 0 {
                let defaults = node.weights.as_deref().or_else(|| {
                    node.mesh
                        .and_then(|m| self.meshes.get(m))
                        .map(|m| m.weights.as_slice())
                });
                w.resize(targets, 0.0);
                if let Some(d) = defaults {
                    for (dst, src) in w.iter_mut().zip(d) {
                        *dst = *src;
                    }
                }
            }
        }

        let mut buf = [0.0f32; 4];
        for clip in self.selected_clips(sel) {
            for ch in &clip.channels {
                let Some(local) = pose.local.get_mut(ch.node) else {
                    continue;
                };
                match ch.property {
                    Property::Translation => {
                        sample(ch, t, &mut buf[..3]);
                        local.translation = Vec3::from_slice(&buf[..3]);
                    }
                    Property::Scale => {
                        sample(ch, t, &mut buf[..3]);
                        local.scale = Vec3::from_slice(&buf[..3]);
                    }
                    Property::Rotation => {
                        sample(ch, t, &mut buf[..4]);
                        let q = Quat::from_slice(&buf[..4]);
                        local.rotation = if q.length_squared() > 0.0 {
                            q.normalize()
                        } else {
                            Quat::IDENTITY
                        };
                    }
                    Property::Weights => {
                        let w = &mut pose.weights[ch.node];
                        if w.len() == ch.width() {
                            sample(ch, t, w);
                        }
                        continue;
                    }
                }
                pose.animated[ch.node] = true;
            }
        }

        // World matrices, parents before children. A node not driven by any channel keeps
        // its exact rest matrix (a glTF matrix need not be a pure TRS).
        pose.world.clear();
        pose.world.resize(n, Mat4::IDENTITY);
        pose.stack.clear();
        pose.stack
            .extend((0..n).filter(|&i| self.nodes[i].parent.is_none()));
        while let Some(i) = pose.stack.pop() {
            let node = &self.nodes[i];
            let local = if pose.animated[i] {
                pose.local[i].matrix()
            } else {
                node.transform.matrix()
            };
            pose.world[i] = match node.parent {
                Some(p) => pose.world[p] * local,
                None => local,
            };
            pose.stack.extend(node.children.iter().copied());
        }
    }

    /// The camera at time `t`: the one named `which` (camera name, else node name; else,
    /// when `which` is a number, the first node showing the file's camera of that index),
    /// or the first camera met walking the shown scene. `None` when there is none.
    pub fn camera_at(&self, sel: ClipSelection, t: f32, which: Option<&str>) -> Option<Camera> {
        let order = self.scene_nodes();
        let named = |n: &usize, name: &str| -> bool {
            let node = &self.nodes[*n];
            node.camera.is_some_and(|c| {
                self.cameras[c].name.as_deref() == Some(name) || node.name.as_deref() == Some(name)
            })
        };
        let node = match which {
            None => order
                .into_iter()
                .find(|&n| self.nodes[n].camera.is_some())?,
            // A name first; else an index into the file's cameras (its first placement).
            Some(name) => match order.iter().copied().find(|n| named(n, name)) {
                Some(n) => n,
                None => {
                    let i = name.trim().parse::<usize>().ok()?;
                    order
                        .into_iter()
                        .find(|&n| self.nodes[n].camera == Some(i))?
                }
            },
        };
        let def = &self.cameras[self.nodes[node].camera?];
        let pose = self.pose_at(sel, t);
        let (_, rotation, position) = pose.world[node].to_scale_rotation_translation();
        let rotation = rotation.normalize();
        Some(Camera {
            name: def.name.clone(),
            node,
            world_from_camera: Mat4::from_rotation_translation(rotation, position),
            position,
            rotation,
            projection: def.projection,
        })
    }

    /// Names of the cameras placed in the shown scene (camera name, else node name).
    pub fn camera_names(&self) -> Vec<String> {
        self.scene_nodes()
            .into_iter()
            .filter_map(|n| {
                let node = &self.nodes[n];
                let c = node.camera?;
                Some(
                    self.cameras[c]
                        .name
                        .clone()
                        .or_else(|| node.name.clone())
                        .unwrap_or_else(|| format!("camera {c} (node {n})")),
                )
            })
            .collect()
    }

    /// Every light placed in the shown scene, posed at time `t`.
    pub fn lights_at(&self, sel: ClipSelection, t: f32) -> Vec<Light> {
        let pose = self.pose_at(sel, t);
        self.scene_nodes()
            .into_iter()
            .filter_map(|n| {
                let def = &self.lights[self.nodes[n].light?];
                let world = pose.world[n];
                let direction = world.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
                Some(Light {
                    name: def.name.clone(),
                    node: n,
                    kind: def.kind,
                    color: def.color,
                    intensity: def.intensity,
                    range: def.range,
                    falloff: def.falloff,
                    position: world.w_axis.truncate(),
                    direction: if direction == Vec3::ZERO {
                        Vec3::NEG_Z
                    } else {
                        direction
                    },
                })
            })
            .collect()
    }
}

/// Samples `ch` at `t` into `out` (`out.len()` is the channel's width).
pub(super) fn sample(ch: &Channel, t: f32, out: &mut [f32]) {
    let w = out.len();
    let times = &ch.times;
    let cubic = ch.interpolation == Interpolation::CubicSpline;
    // Offset of keyframe k's value (CUBICSPLINE stores in-tangent, value, out-tangent).
    let value_at = |k: usize| if cubic { (3 * k + 1) * w } else { k * w };
    let Some(&last) = times.last() else {
        return;
    };
    if ch.values.len() < value_at(times.len() - 1) + w {
        return; // validated at import; keep the hot path panic-free all the same
    }
    let copy_key = |k: usize, out: &mut [f32]| {
        out.copy_from_slice(&ch.values[value_at(k)..value_at(k) + w]);
    };
    if times.len() == 1 || t <= times[0] {
        return copy_key(0, out);
    }
    if t >= last {
        return copy_key(times.len() - 1, out);
    }
    // times[k] <= t < times[k + 1]
    let k = times.partition_point(|&x| x <= t) - 1;
    let (t0, t1) = (times[k], times[k + 1]);
    let td = t1 - t0;
    if td <= 0.0 {
        return copy_key(k + 1, out);
    }
    let s = (t - t0) / td;
    match ch.interpolation {
        Interpolation::Step => copy_key(k, out),
        Interpolation::Linear => {
            let (a, b) = (value_at(k), value_at(k + 1));
            if ch.property == Property::Rotation && w == 4 {
                let qa = Quat::from_slice(&ch.values[a..a + 4]);
                let qb = Quat::from_slice(&ch.values[b..b + 4]);
                out.copy_from_slice(&slerp(qa, qb, s).to_array());
            } else {
                for (c, o) in out.iter_mut().enumerate() {
                    *o = ch.values[a + c] * (1.0 - s) + ch.values[b + c] * s;
                }
            }
        }
        Interpolation::CubicSpline => {
            // Spec appendix C: p(s) = h00 v_k + h10 td b_k + h01 v_{k+1} + h11 td a_{k+1},
            // b_k = out-tangent of k, a_{k+1} = in-tangent of k + 1.
            let (s2, s3) = (s * s, s * s * s);
            let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
            let h10 = s3 - 2.0 * s2 + s;
            let h01 = -2.0 * s3 + 3.0 * s2;
            let h11 = s3 - s2;
            let v0 = value_at(k);
            let b0 = v0 + w;
            let v1 = value_at(k + 1);
            let a1 = v1 - w;
            for (c, o) in out.iter_mut().enumerate() {
                *o = h00 * ch.values[v0 + c]
                    + h10 * td * ch.values[b0 + c]
                    + h01 * ch.values[v1 + c]
                    + h11 * td * ch.values[a1 + c];
            }
        }
    }
}

/// Spherical linear interpolation along the shorter arc (exact `acos`, unlike glam's
/// approximation, so sampled rotations match hand computations to float precision).
pub(super) fn slerp(a: Quat, b: Quat, s: f32) -> Quat {
    let (a, mut b) = (a.normalize(), b.normalize());
    let mut dot = a.dot(b);
    if dot < 0.0 {
        b = -b;
        dot = -dot;
    }
    if dot > 0.9995 {
        return (a * (1.0 - s) + b * s).normalize();
    }
    let theta = dot.min(1.0).acos();
    let sin = theta.sin();
    let wa = ((1.0 - s) * theta).sin() / sin;
    let wb = (s * theta).sin() / sin;
    (a * wa + b * wb).normalize()
}

/// Whether a channel's output changes over time (a channel whose keyframes are all the
/// same value, with zero tangents for CUBICSPLINE, holds still and does not make its node
/// dynamic).
pub(super) fn channel_varies(ch: &Channel) -> bool {
    let w = ch.width();
    if w == 0 || ch.times.len() < 2 {
        return false;
    }
    match ch.interpolation {
        Interpolation::CubicSpline => {
            let first = &ch.values[w..2 * w];
            ch.values.chunks_exact(3 * w).any(|key| {
                &key[w..2 * w] != first
                    || key[..w].iter().any(|&x| x != 0.0)
                    || key[2 * w..].iter().any(|&x| x != 0.0)
            })
        }
        _ => {
            let first = &ch.values[..w];
            ch.values.chunks_exact(w).any(|key| key != first)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(
        interpolation: Interpolation,
        property: Property,
        times: &[f32],
        values: &[f32],
    ) -> Channel {
        Channel {
            node: 0,
            property,
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
        }
    }

    #[test]
    fn linear_step_and_clamping() {
        let ch = channel(
            Interpolation::Linear,
            Property::Translation,
            &[1.0, 3.0],
            &[0.0, 0.0, 0.0, 4.0, 2.0, -2.0],
        );
        let mut out = [0.0; 3];
        sample(&ch, 2.0, &mut out);
        assert_eq!(out, [2.0, 1.0, -1.0]);
        sample(&ch, 0.0, &mut out);
        assert_eq!(out, [0.0, 0.0, 0.0]);
        sample(&ch, 9.0, &mut out);
        assert_eq!(out, [4.0, 2.0, -2.0]);
        let step = Channel {
            interpolation: Interpolation::Step,
            ..ch
        };
        sample(&step, 2.9, &mut out);
        assert_eq!(out, [0.0, 0.0, 0.0]);
        sample(&step, 3.0, &mut out);
        assert_eq!(out, [4.0, 2.0, -2.0]);
    }

    #[test]
    fn cubic_spline_hits_keys_and_follows_hermite() {
        // One component: v0 = 0, out-tangent b0 = 1; v1 = 1, in-tangent a1 = 0; td = 2.
        let ch = channel(
            Interpolation::CubicSpline,
            Property::Weights,
            &[0.0, 2.0],
            &[9.0, 0.0, 1.0, 0.0, 1.0, 9.0],
        );
        let mut out = [0.0];
        sample(&ch, 0.0, &mut out);
        assert_eq!(out[0], 0.0);
        sample(&ch, 2.0, &mut out);
        assert_eq!(out[0], 1.0);
        // s = 0.5: h00 = .5, h10 = .125, h01 = .5, h11 = -.125 → 0.125*2*1 + 0.5*1 = 0.75
        sample(&ch, 1.0, &mut out);
        assert!((out[0] - 0.75).abs() < 1e-6, "{}", out[0]);
    }

    #[test]
    fn slerp_takes_the_short_arc_and_matches_axis_angle() {
        let a = Quat::IDENTITY;
        let b = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let m = slerp(a, b, 0.5);
        assert!(m.abs_diff_eq(Quat::from_rotation_z(std::f32::consts::FRAC_PI_4), 1e-6));
        let m2 = slerp(a, -b, 0.5); // same rotation, other sign: same result
        assert!(m2.abs_diff_eq(m, 1e-6) || m2.abs_diff_eq(-m, 1e-6));
    }

    #[test]
    fn constant_channels_do_not_vary() {
        let still = channel(
            Interpolation::Linear,
            Property::Translation,
            &[0.0, 1.0],
            &[1.0, 2.0, 3.0, 1.0, 2.0, 3.0],
        );
        assert!(!channel_varies(&still));
        let moving = channel(
            Interpolation::Linear,
            Property::Translation,
            &[0.0, 1.0],
            &[1.0, 2.0, 3.0, 1.0, 2.0, 4.0],
        );
        assert!(channel_varies(&moving));
        let wiggle = channel(
            Interpolation::CubicSpline,
            Property::Weights,
            &[0.0, 1.0],
            &[0.0, 5.0, 1.0, 0.0, 5.0, 0.0],
        );
        assert!(channel_varies(&wiggle));
    }
}
