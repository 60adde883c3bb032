//! The writer's refusal of inconsistent input: an index out of range, a length mismatch,
//! a non-finite number (it never writes a file the importer would reject).

use super::{GltfBuilder, ImportError};
use crate::scene::{Interpolation, Property};

/// The writer's refusal, as the result of a check.
fn bad(reason: String) -> Result<(), ImportError> {
    Err(ImportError::Write { reason })
}

fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// An optional index is absent or below `len`.
fn in_range(i: Option<u32>, len: usize) -> bool {
    i.is_none_or(|i| (i as usize) < len)
}

impl GltfBuilder {
    /// Refuses inconsistent input (the first problem found, in the order below).
    pub(super) fn check(&self) -> Result<(), ImportError> {
        self.check_meshes()?;
        self.check_materials()?;
        self.check_nodes()?;
        self.check_animations()?;
        self.check_fps()
    }

    /// Primitives: positions present and finite, attribute counts, whole triangles, indices
    /// and materials in range, morph targets and weights consistent.
    fn check_meshes(&self) -> Result<(), ImportError> {
        for (mi, m) in self.meshes.iter().enumerate() {
            for (pi, p) in m.primitives.iter().enumerate() {
                let at = format!("mesh {mi} primitive {pi}");
                let nv = p.positions.len();
                if nv == 0 {
                    return bad(format!("{at}: no positions"));
                }
                let flat: Vec<f32> = p.positions.iter().flat_map(|v| v.to_array()).collect();
                if !finite(&flat) {
                    return bad(format!("{at}: non-finite position"));
                }
                if p.normals.as_ref().is_some_and(|n| n.len() != nv)
                    || p.uvs.as_ref().is_some_and(|n| n.len() != nv)
                    || p.morph_targets.iter().any(|t| t.len() != nv)
                    || p.morph_normals.iter().any(|t| t.len() != nv)
                {
                    return bad(format!("{at}: attribute count differs from positions"));
                }
                let idx_len = p.indices.as_ref().map_or(nv, Vec::len);
                if idx_len % 3 != 0 {
                    return bad(format!(
                        "{at}: {idx_len} indices/vertices is not whole triangles"
                    ));
                }
                if let Some(i) = p.indices.iter().flatten().find(|&&i| i as usize >= nv) {
                    return bad(format!("{at}: index {i} past the vertex count {nv}"));
                }
                if !in_range(p.material, self.materials.len()) {
                    return bad(format!("{at}: material missing"));
                }
                if !p.morph_normals.is_empty() && p.morph_normals.len() != p.morph_targets.len() {
                    return bad(format!("{at}: morph normals for some targets only"));
                }
                if p.morph_targets.len() != m.primitives[0].morph_targets.len() {
                    return bad(format!(
                        "mesh {mi}: primitives differ in morph target count"
                    ));
                }
            }
            let targets = m.primitives.first().map_or(0, |p| p.morph_targets.len());
            if !m.weights.is_empty() && m.weights.len() != targets {
                return bad(format!(
                    "mesh {mi}: {} weights for {targets} targets",
                    m.weights.len()
                ));
            }
        }
        Ok(())
    }

    /// Materials name existing textures, textures existing images; images are PNG or JPEG.
    fn check_materials(&self) -> Result<(), ImportError> {
        for (mi, m) in self.materials.iter().enumerate() {
            if !in_range(m.base_color_texture, self.textures.len()) {
                return bad(format!("material {mi}: texture missing"));
            }
            if m.extras.as_ref().is_some_and(|e| !e.is_object()) {
                return bad(format!("material {mi}: extras must be an object"));
            }
        }
        for (ti, t) in self.textures.iter().enumerate() {
            if t.image as usize >= self.images.len() {
                return bad(format!("texture {ti}: image {} missing", t.image));
            }
        }
        for (ii, i) in self.images.iter().enumerate() {
            if i.bytes.is_empty() || !matches!(i.mime_type.as_str(), "image/png" | "image/jpeg") {
                return bad(format!("image {ii}: empty, or not image/png or image/jpeg"));
            }
        }
        Ok(())
    }

    /// Nodes: references in range, finite transforms, one parent at most; roots exist and
    /// have none.
    fn check_nodes(&self) -> Result<(), ImportError> {
        let mut parent = vec![None; self.nodes.len()];
        for (ni, n) in self.nodes.iter().enumerate() {
            if !in_range(n.mesh, self.meshes.len())
                || !in_range(n.camera, self.cameras.len())
                || !in_range(n.light, self.lights.len())
            {
                return bad(format!("node {ni}: mesh, camera or light missing"));
            }
            let trs = [n.translation.to_array(), n.scale.to_array()].concat();
            if !finite(&trs) || !n.rotation.is_finite() {
                return bad(format!("node {ni}: non-finite transform"));
            }
            for &c in &n.children {
                match parent.get_mut(c as usize) {
                    None => return bad(format!("node {ni}: child {c} missing")),
                    Some(Some(_)) => return bad(format!("node {c} has two parents")),
                    Some(p) => *p = Some(ni),
                }
            }
        }
        for &r in &self.roots {
            match parent.get(r as usize) {
                None => return bad(format!("root {r} missing")),
                Some(Some(p)) => return bad(format!("root {r} is a child of node {p}")),
                Some(None) => {}
            }
        }
        Ok(())
    }

    /// Channels: node exists, value count matching the property's width, finite increasing
    /// times.
    fn check_animations(&self) -> Result<(), ImportError> {
        for (ai, a) in self.animations.iter().enumerate() {
            for (ci, c) in a.channels.iter().enumerate() {
                let at = format!("animation {ai} channel {ci}");
                let Some(node) = self.nodes.get(c.node as usize) else {
                    return bad(format!("{at}: node {} missing", c.node));
                };
                let width = match c.property {
                    Property::Translation | Property::Scale => 3,
                    Property::Rotation => 4,
                    Property::Weights => node
                        .mesh
                        .and_then(|m| self.meshes.get(m as usize))
                        .and_then(|m| m.primitives.first())
                        .map_or(0, |p| p.morph_targets.len()),
                };
                let per_key = if c.interpolation == Interpolation::CubicSpline {
                    3
                } else {
                    1
                };
                if width == 0
                    || c.times.is_empty()
                    || c.values.len() != c.times.len() * width * per_key
                {
                    return bad(format!(
                        "{at}: {} values for {} keys of width {width}",
                        c.values.len(),
                        c.times.len()
                    ));
                }
                if !finite(&c.times)
                    || !finite(&c.values)
                    || c.times.windows(2).any(|w| w[1] < w[0])
                {
                    return bad(format!(
                        "{at}: times must be finite and increasing, values finite"
                    ));
                }
            }
        }
        Ok(())
    }

    /// `fps`, when set, is positive.
    fn check_fps(&self) -> Result<(), ImportError> {
        if let Some(fps) = self.fps {
            if !(fps.is_finite() && fps > 0.0) {
                return bad(format!("fps {fps} is not positive"));
            }
        }
        Ok(())
    }
}
