//! Animation clips, read from the JSON (channel targets, samplers, keyframes).

use super::{ImportError, Importer};
use crate::scene::{Animation, Channel, Interpolation, Property};

impl Importer<'_> {
    /// Read from the JSON rather than the `gltf` wrappers: the crate's validation does not
    /// check channel targets, and its accessors unwrap them.
    pub(super) fn animations(&self) -> Result<Vec<Animation>, ImportError> {
        use gltf::json::validation::Checked;
        let json = self.doc.as_json();
        let mut out = Vec::new();
        for (ai, a) in json.animations.iter().enumerate() {
            let mut channels = Vec::new();
            for (ci, ch) in a.channels.iter().enumerate() {
                let err = |reason: String| ImportError::Animation {
                    path: self.path.to_path_buf(),
                    animation: ai,
                    channel: ci,
                    reason,
                };
                let sampler = a
                    .samplers
                    .get(ch.sampler.value())
                    .ok_or_else(|| err(format!("sampler {} missing", ch.sampler.value())))?;
                let accessor = |i: usize| {
                    self.doc
                        .accessors()
                        .nth(i)
                        .ok_or_else(|| err(format!("accessor {i} missing")))
                };
                let (input, output) = (
                    accessor(sampler.input.value())?,
                    accessor(sampler.output.value())?,
                );
                let at = format!("animations[{ai}].channels[{ci}]");
                let times = self.floats(&input, &format!("{at} input"), 1, false)?;
                let comps = output.dimensions().multiplicity();
                let values = self.floats(&output, &format!("{at} output"), comps, true)?;
                use gltf::json::animation::{Interpolation as I, Property as P};
                let property = match ch.target.path {
                    Checked::Valid(P::Translation) => Property::Translation,
                    Checked::Valid(P::Rotation) => Property::Rotation,
                    Checked::Valid(P::Scale) => Property::Scale,
                    Checked::Valid(P::MorphTargetWeights) => Property::Weights,
                    Checked::Invalid => return Err(err("unknown target path".into())),
                };
                let interpolation = match sampler.interpolation {
                    Checked::Valid(I::Step) => Interpolation::Step,
                    Checked::Valid(I::Linear) => Interpolation::Linear,
                    Checked::Valid(I::CubicSpline) => Interpolation::CubicSpline,
                    Checked::Invalid => return Err(err("unknown interpolation".into())),
                };
                channels.push(Channel {
                    // Range-checked by import::validate.
                    node: ch.target.node.value(),
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
