//! The border check of the model: every index in range, every length consistent, every
//! float finite, the hierarchy a forest. Importers call it; everything after relies on it.
//!
//! The checks run in a fixed order (meshes, textures and images, skins, nodes, the forest,
//! camera / light / material parameters, animation, fps), one function per concept; the
//! first problem found is the error.

use crate::scene::{Interpolation, LightKind, NodeTransform, Projection, Property, Scene};

use super::ImportError;

/// Checks the model's invariants; every importer calls it before returning a scene.
pub fn validate(scene: &Scene) -> Result<(), ImportError> {
    let c = Check { scene };
    c.meshes()?;
    c.point_caches()?;
    c.textures()?;
    c.skins()?;
    c.nodes()?;
    c.forest()?;
    c.parameters()?;
    c.animations()?;
    c.fps()
}

struct Check<'a> {
    scene: &'a Scene,
}

impl Check<'_> {
    fn model(&self, reason: String) -> ImportError {
        ImportError::Model {
            path: self.scene.source.clone(),
            reason,
        }
    }

    fn node(&self, node: usize, reason: String) -> ImportError {
        ImportError::Node {
            path: self.scene.source.clone(),
            node,
            name: self.scene.nodes.get(node).and_then(|n| n.name.clone()),
            reason,
        }
    }

    /// Point caches: sorted and unique by primitive, which exists; times finite and
    /// increasing, one sample each; every point and velocity finite; every triangle's
    /// vertex, and every vertex's point, in range for every sample that shows it.
    fn point_caches(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        let mut last = None;
        for (ci, c) in scene.point_caches.iter().enumerate() {
            let at = format!(
                "point_caches[{ci}] (meshes[{}].primitives[{}])",
                c.mesh, c.primitive
            );
            let bad = |reason: &str| Err(self.model(format!("{at}: {reason}")));
            let exists = scene
                .meshes
                .get(c.mesh)
                .is_some_and(|m| c.primitive < m.primitives.len());
            if !exists {
                return bad("no such primitive");
            }
            if last >= Some((c.mesh, c.primitive)) {
                return bad("not sorted by primitive, or listed twice");
            }
            last = Some((c.mesh, c.primitive));
            if c.times.is_empty() || c.times.len() != c.samples.len() {
                return bad("needs one time per sample, and a sample at least");
            }
            if c.times.iter().any(|t| !t.is_finite()) || c.times.windows(2).any(|w| w[0] >= w[1]) {
                return bad("sample times not finite and strictly increasing");
            }
            for (ti, topo) in c.topologies.iter().enumerate() {
                if let Some(uv) = &topo.uvs {
                    if uv.iter().any(|v| !v.is_finite()) {
                        return bad(&format!("topologies[{ti}]: non-finite uv"));
                    }
                }
            }
            for (si, smp) in c.samples.iter().enumerate() {
                let Some(topo) = c.topologies.get(smp.topology as usize) else {
                    return bad(&format!(
                        "samples[{si}]: topology {} out of range",
                        smp.topology
                    ));
                };
                let np = smp.points.len();
                if smp.points.iter().any(|p| !p.is_finite()) {
                    return bad(&format!("samples[{si}]: non-finite point"));
                }
                if let Some(v) = &smp.velocities {
                    if v.len() != np || v.iter().any(|v| !v.is_finite()) {
                        return bad(&format!(
                            "samples[{si}]: velocities not finite or not one per point"
                        ));
                    }
                }
                let nv = topo.vertex_count(np);
                if topo
                    .vertex_point
                    .as_ref()
                    .is_some_and(|m| m.iter().any(|&p| p as usize >= np))
                {
                    return bad(&format!(
                        "samples[{si}]: a vertex shows a point past its {np}"
                    ));
                }
                if topo.triangles.iter().flatten().any(|&v| v as usize >= nv) {
                    return bad(&format!(
                        "samples[{si}]: a triangle index past its {nv} vertices"
                    ));
                }
                if topo.uvs.as_ref().is_some_and(|uv| uv.len() != nv) {
                    return bad(&format!("samples[{si}]: uvs not one per vertex"));
                }
            }
        }
        Ok(())
    }

    /// Primitives: finite attributes of matching counts, indices and materials in range,
    /// skin influences and morph targets consistent.
    fn meshes(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        for (mi, mesh) in scene.meshes.iter().enumerate() {
            if mesh.weights.iter().any(|w| !w.is_finite()) {
                return Err(self.model(format!("meshes[{mi}].weights: non-finite weight")));
            }
            for (pi, p) in mesh.primitives.iter().enumerate() {
                let at = format!("meshes[{mi}].primitives[{pi}]");
                let nv = p.positions.len();
                if p.positions.iter().any(|v| !v.is_finite()) {
                    return Err(self.model(format!("{at}: non-finite position")));
                }
                if let Some(n) = &p.normals {
                    if n.len() != nv || n.iter().any(|v| !v.is_finite()) {
                        return Err(self.model(format!("{at}: normals: wrong count or non-finite")));
                    }
                }
                if let Some(uv) = &p.uvs {
                    if uv.len() != nv || uv.iter().any(|v| !v.is_finite()) {
                        return Err(self.model(format!("{at}: uvs: wrong count or non-finite")));
                    }
                }
                if let Some(t) = p.triangles.iter().flatten().find(|&&i| i as usize >= nv) {
                    return Err(
                        self.model(format!("{at}: vertex index {t} past the vertex count {nv}"))
                    );
                }
                if p.material as usize >= scene.materials.len() {
                    return Err(self.model(format!("{at}: material {} missing", p.material)));
                }
                if p.joints.len() != p.weights.len()
                    || (nv > 0 && p.joints.len() % nv != 0)
                    || (nv == 0 && !p.joints.is_empty())
                {
                    return Err(self.model(format!("{at}: skin influences do not match vertices")));
                }
                if p.weights.iter().flatten().any(|w| !w.is_finite()) {
                    return Err(self.model(format!("{at}: non-finite skin weight")));
                }
                for (ti, t) in p.morph_targets.iter().enumerate() {
                    let ok = |v: &Vec<glam::Vec3>| {
                        (v.is_empty() || v.len() == nv) && v.iter().all(|x| x.is_finite())
                    };
                    if !ok(&t.positions) || !ok(&t.normals) {
                        return Err(self.model(format!(
                            "{at}: morph target {ti}: wrong count or non-finite"
                        )));
                    }
                }
                if p.morph_targets.len() != mesh.primitives[0].morph_targets.len() {
                    return Err(self.model(format!(
                        "{at}: primitives of one mesh must have the same number of morph targets"
                    )));
                }
            }
        }
        Ok(())
    }

    /// Textures name existing images, images hold their pixels, materials name existing
    /// textures.
    fn textures(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        for (ti, t) in scene.textures.iter().enumerate() {
            if t.image as usize >= scene.images.len() {
                return Err(self.model(format!("textures[{ti}]: image {} missing", t.image)));
            }
        }
        for (ii, im) in scene.images.iter().enumerate() {
            if im.rgba8.len() as u64 != u64::from(im.width) * u64::from(im.height) * 4 {
                return Err(self.model(format!("images[{ii}]: pixel data does not match size")));
            }
        }
        for (mi, m) in scene.materials.iter().enumerate() {
            for r in [
                m.base_color_texture,
                m.metallic_roughness_texture,
                m.emissive_texture,
            ]
            .into_iter()
            .flatten()
            {
                if r.texture as usize >= scene.textures.len() {
                    return Err(
                        self.model(format!("materials[{mi}]: texture {} missing", r.texture))
                    );
                }
                if r.transform.is_some_and(|t| !t.is_finite()) {
                    return Err(self.model(format!(
                        "materials[{mi}]: KHR_texture_transform of texture {} is not finite",
                        r.texture
                    )));
                }
            }
        }
        Ok(())
    }

    /// Skins: joints exist, one inverse bind matrix per joint, at most 65536 joints.
    fn skins(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        let n_nodes = scene.nodes.len();
        for (si, s) in scene.skins.iter().enumerate() {
            let skin_err = |reason: String| ImportError::Skin {
                path: scene.source.clone(),
                skin: si,
                reason,
            };
            if let Some(j) = s.joints.iter().find(|&&j| j >= n_nodes) {
                return Err(skin_err(format!("joint node {j} does not exist")));
            }
            if s.inverse_bind_matrices.len() != s.joints.len() {
                return Err(skin_err(format!(
                    "{} inverse bind matrices for {} joints",
                    s.inverse_bind_matrices.len(),
                    s.joints.len()
                )));
            }
            if s.joints.len() > usize::from(u16::MAX) + 1 {
                return Err(skin_err("more than 65536 joints".into()));
            }
        }
        Ok(())
    }

    /// Nodes: references in range, parent and children agree, finite transforms and
    /// weights, skinned meshes use only their skin's joints.
    fn nodes(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        let n_nodes = scene.nodes.len();
        // Parent and children must agree (reachability is `forest`).
        for (ni, node) in scene.nodes.iter().enumerate() {
            let check = |i: Option<usize>, len: usize, what: &str| match i {
                Some(i) if i >= len => Err(self.node(ni, format!("{what} {i} does not exist"))),
                _ => Ok(()),
            };
            check(node.mesh, scene.meshes.len(), "mesh")?;
            check(node.skin, scene.skins.len(), "skin")?;
            check(node.camera, scene.cameras.len(), "camera")?;
            check(node.light, scene.lights.len(), "light")?;
            check(node.parent, n_nodes, "parent")?;
            for &c in &node.children {
                if c >= n_nodes {
                    return Err(self.node(ni, format!("child {c} does not exist")));
                }
                if scene.nodes[c].parent != Some(ni) {
                    return Err(self.node(
                        c,
                        format!(
                            "listed as a child of node {ni} but its parent differs (two parents?)"
                        ),
                    ));
                }
            }
            if let Some(p) = node.parent {
                if !scene.nodes[p].children.contains(&ni) {
                    return Err(self.node(ni, format!("parent {p} does not list it")));
                }
            }
            let finite = match &node.transform {
                NodeTransform::Matrix(m) => m.is_finite(),
                NodeTransform::Trs(t) => {
                    t.translation.is_finite() && t.rotation.is_finite() && t.scale.is_finite()
                }
            };
            if !finite {
                return Err(self.node(ni, "non-finite transform".into()));
            }
            if let Some(w) = &node.weights {
                if w.iter().any(|x| !x.is_finite()) {
                    return Err(self.node(ni, "non-finite morph weight".into()));
                }
            }
            // Skinned meshes: every joint number used must exist in the skin.
            if let (Some(mi), Some(si)) = (node.mesh, node.skin) {
                let joints = scene.skins[si].joints.len();
                for (pi, p) in scene.meshes[mi].primitives.iter().enumerate() {
                    if let Some(j) = p
                        .joints
                        .iter()
                        .flatten()
                        .find(|&&j| usize::from(j) >= joints)
                    {
                        return Err(self.node(
                            ni,
                            format!(
                                "mesh {mi} primitive {pi} uses joint {j} but skins[{si}] has {joints} joints"
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The hierarchy is a forest: every node reached once from a parentless node; roots
    /// exist and have no parent.
    fn forest(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        let n_nodes = scene.nodes.len();
        let mut seen = vec![false; n_nodes];
        let mut stack: Vec<usize> = (0..n_nodes)
            .filter(|&i| scene.nodes[i].parent.is_none())
            .collect();
        while let Some(n) = stack.pop() {
            if std::mem::replace(&mut seen[n], true) {
                return Err(self.node(n, "reached twice in the hierarchy".into()));
            }
            stack.extend(scene.nodes[n].children.iter().copied());
        }
        if let Some(n) = seen.iter().position(|s| !s) {
            return Err(self.node(n, "part of a cycle in the node hierarchy".into()));
        }
        if let Some(&r) = scene.roots.iter().find(|&&r| r >= n_nodes) {
            return Err(self.model(format!("root node {r} does not exist")));
        }
        if let Some(&r) = scene
            .roots
            .iter()
            .find(|&&r| scene.nodes[r].parent.is_some())
        {
            return Err(self.node(r, "scene root has a parent".into()));
        }
        Ok(())
    }

    /// Cameras, lights and materials: every parameter finite.
    fn parameters(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        for (ci, c) in scene.cameras.iter().enumerate() {
            let ok = match c.projection {
                Projection::Perspective {
                    yfov,
                    aspect,
                    znear,
                    zfar,
                } => [yfov, aspect.unwrap_or(1.0), znear, zfar.unwrap_or(1.0)]
                    .iter()
                    .all(|x| x.is_finite()),
                Projection::Orthographic {
                    xmag,
                    ymag,
                    znear,
                    zfar,
                } => [xmag, ymag, znear, zfar].iter().all(|x| x.is_finite()),
            };
            if !ok {
                return Err(self.model(format!("cameras[{ci}]: non-finite parameter")));
            }
        }
        for (li, l) in scene.lights.iter().enumerate() {
            let cone = match l.kind {
                LightKind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => inner_cone_angle.is_finite() && outer_cone_angle.is_finite(),
                _ => true,
            };
            if !(cone
                && l.color.is_finite()
                && l.intensity.is_finite()
                && l.range.is_none_or(f32::is_finite))
            {
                return Err(self.model(format!("lights[{li}]: non-finite parameter")));
            }
        }
        for (mi, m) in scene.materials.iter().enumerate() {
            let scalars = [
                m.metallic,
                m.roughness,
                m.emissive_strength,
                m.transmission,
                m.ior,
            ];
            if !(m.base_color.is_finite()
                && m.emissive.is_finite()
                && scalars.iter().all(|x| x.is_finite()))
            {
                return Err(self.model(format!("materials[{mi}]: non-finite parameter")));
            }
        }
        Ok(())
    }

    /// Channels: target node exists, keyframes finite and non-decreasing, value count
    /// matching the property's width.
    fn animations(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        let n_nodes = scene.nodes.len();
        for (ai, a) in scene.animations.iter().enumerate() {
            for (ci, c) in a.channels.iter().enumerate() {
                let err = |reason: String| ImportError::Animation {
                    path: scene.source.clone(),
                    animation: ai,
                    channel: ci,
                    reason,
                };
                if c.node >= n_nodes {
                    return Err(err(format!("target node {} does not exist", c.node)));
                }
                if c.times.is_empty() {
                    return Err(err("no keyframes".into()));
                }
                if c.times.iter().any(|t| !t.is_finite()) || c.values.iter().any(|v| !v.is_finite())
                {
                    return Err(err("non-finite keyframe time or value".into()));
                }
                if c.times.windows(2).any(|w| w[1] < w[0]) {
                    return Err(err("keyframe times decrease".into()));
                }
                let per_key = match c.interpolation {
                    Interpolation::CubicSpline => 3,
                    _ => 1,
                };
                let width = match c.property {
                    Property::Translation | Property::Scale => 3,
                    Property::Rotation => 4,
                    Property::Weights => {
                        let targets = scene.nodes[c.node]
                            .mesh
                            .and_then(|m| scene.meshes[m].primitives.first())
                            .map_or(0, |p| p.morph_targets.len());
                        if targets == 0 {
                            return Err(err(format!(
                                "weights channel on node {} whose mesh has no morph targets",
                                c.node
                            )));
                        }
                        targets
                    }
                };
                if c.values.len() != c.times.len() * per_key * width {
                    return Err(err(format!(
                        "{} output values for {} keyframes of width {width}",
                        c.values.len(),
                        c.times.len()
                    )));
                }
            }
        }
        Ok(())
    }

    /// `extras.fps`, when present, is a positive number.
    fn fps(&self) -> Result<(), ImportError> {
        let scene = self.scene;
        if let Some(fps) = scene.fps {
            if !(fps.is_finite() && fps > 0.0) {
                return Err(self.model(format!("fps {fps} is not a positive number")));
            }
        }
        Ok(())
    }
}
