//! The writer's refusal of a scene it cannot write faithfully: whatever the border check
//! `import::validate` refuses, and what glTF itself cannot hold (an empty primitive,
//! primitives of one mesh with different morph target counts, extras that are not JSON
//! objects, a texture read with a coordinate set the model does not carry). It never
//! writes a file the importer would reject.

use super::ImportError;
use crate::scene::Scene;

/// The writer's refusal.
fn bad(reason: String) -> Result<(), ImportError> {
    Err(ImportError::Write { reason })
}

/// Refuses inconsistent input (the first problem found).
pub(super) fn check(scene: &Scene) -> Result<(), ImportError> {
    crate::import::validate(scene).map_err(|e| ImportError::Write {
        reason: match e {
            ImportError::Model { reason, .. } => reason,
            ImportError::Node {
                node, reason, name, ..
            } => match name {
                Some(n) => format!("nodes[{node}] ({n:?}): {reason}"),
                None => format!("nodes[{node}]: {reason}"),
            },
            other => other.to_string(),
        },
    })?;
    for (mi, m) in scene.meshes.iter().enumerate() {
        let targets = m.primitives.first().map_or(0, |p| p.morph_targets.len());
        for (pi, p) in m.primitives.iter().enumerate() {
            let at = format!("meshes[{mi}].primitives[{pi}]");
            if p.positions.is_empty() || p.triangles.is_empty() {
                return bad(format!("{at}: no vertices or no triangles"));
            }
            if p.morph_targets.len() != targets {
                return bad(format!(
                    "meshes[{mi}]: primitives differ in morph target count"
                ));
            }
        }
    }
    if scene.extras.materials.len() > scene.materials.len() {
        return bad(format!(
            "extras for {} materials, the scene has {}",
            scene.extras.materials.len(),
            scene.materials.len()
        ));
    }
    if let Some(i) = scene
        .extras
        .materials
        .iter()
        .position(|e| e.as_ref().is_some_and(|e| !e.is_object()))
    {
        return bad(format!("materials[{i}]: extras must be a JSON object"));
    }
    if let Some(i) = scene
        .images
        .iter()
        .position(|i| i.width == 0 || i.height == 0)
    {
        return bad(format!("images[{i}]: empty image"));
    }
    Ok(())
}
