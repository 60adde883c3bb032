//! Animation clips: channel targets, samplers, keyframes. A channel whose target has no
//! node is read through `KHR_animation_pointer` when its pointer names what we animate
//! (`/nodes/N/translation`, `rotation`, `scale`, `weights`); any other channel without a
//! node (a camera's field of view, a light's colour, a material) is skipped with a
//! warning, as the specification allows.

use super::{ImportError, Importer};
use crate::scene::{Animation, Channel, Interpolation, Property};

/// The node and property a `KHR_animation_pointer` pointer animates, when we animate it.
fn node_pointer(pointer: &str) -> Option<(usize, Property)> {
    let rest = pointer.strip_prefix("/nodes/")?;
    let (node, what) = rest.split_once('/')?;
    // JSON pointer array indices are plain decimal without leading zeros.
    if node.is_empty() || (node.len() > 1 && node.starts_with('0')) {
        return None;
    }
    let node: usize = node.parse().ok()?;
    let property = match what {
        "translation" => Property::Translation,
        "rotation" => Property::Rotation,
        "scale" => Property::Scale,
        "weights" => Property::Weights,
        _ => return None,
    };
    Some((node, property))
}

impl Importer<'_> {
    pub(super) fn animations(&mut self) -> Result<Vec<Animation>, ImportError> {
        let root = self.root;
        let mut out = Vec::new();
        for (ai, a) in root.animations.iter().enumerate() {
            let mut channels = Vec::new();
            let samplers = a.samplers.as_deref().unwrap_or(&[]);
            for (ci, ch) in a.channels.iter().flatten().enumerate() {
                let at = format!("animations[{ai}].channels[{ci}]");
                let err = |reason: String| ImportError::Animation {
                    path: self.path.to_path_buf(),
                    animation: ai,
                    channel: ci,
                    reason,
                };
                let Some(target) = &ch.target else {
                    return Err(err("no target".into()));
                };
                let path = target.path.as_deref().unwrap_or("");
                let pointer = target
                    .extensions
                    .as_ref()
                    .and_then(|e| e.pointer.as_ref())
                    .and_then(|p| p.pointer.as_deref());
                let aim = match (target.node, path) {
                    (Some(n), "translation") => Some((n, Property::Translation)),
                    (Some(n), "rotation") => Some((n, Property::Rotation)),
                    (Some(n), "scale") => Some((n, Property::Scale)),
                    (Some(n), "weights") => Some((n, Property::Weights)),
                    (None, "pointer") => pointer.and_then(node_pointer),
                    _ => None,
                };
                let Some((node, property)) = aim else {
                    let what = match (path, pointer) {
                        ("pointer", Some(p)) => format!("KHR_animation_pointer {p:?}"),
                        ("pointer", None) => "a pointer target without a pointer".to_string(),
                        (p, _) if target.node.is_none() => format!("path {p:?} without a node"),
                        (p, _) => format!("path {p:?}"),
                    };
                    self.warn(format!(
                        "{at}: {what} is not animated here; the channel is skipped"
                    ));
                    continue;
                };
                if node >= root.nodes.len() {
                    return Err(err(format!("target node {node} does not exist")));
                }
                let sampler = ch
                    .sampler
                    .and_then(|s| samplers.get(s))
                    .ok_or_else(|| err("sampler missing".into()))?;
                let (Some(input), Some(output)) = (sampler.input, sampler.output) else {
                    return Err(err("sampler without input or output".into()));
                };
                let times = self.floats(input, &format!("{at} input"), 1, false)?;
                let comps = self.components(output);
                let values = self.floats(output, &format!("{at} output"), comps, true)?;
                let interpolation = match sampler.interpolation.as_deref() {
                    Some("STEP") => Interpolation::Step,
                    Some("CUBICSPLINE") => Interpolation::CubicSpline,
                    _ => Interpolation::Linear,
                };
                channels.push(Channel {
                    node,
                    property,
                    interpolation,
                    times,
                    values,
                });
            }
            out.push(Animation {
                name: a.name.clone(),
                channels,
            });
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pointers_to_node_properties() {
        assert_eq!(
            node_pointer("/nodes/3/translation"),
            Some((3, Property::Translation))
        );
        assert_eq!(
            node_pointer("/nodes/0/weights"),
            Some((0, Property::Weights))
        );
        assert_eq!(node_pointer("/nodes/01/scale"), None);
        assert_eq!(node_pointer("/nodes//scale"), None);
        assert_eq!(node_pointer("/cameras/0/perspective/yfov"), None);
        assert_eq!(node_pointer("/nodes/2/extensions/x"), None);
    }
}
