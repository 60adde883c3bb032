//! The node hierarchy (transforms, parents), skins, camera definitions and
//! `KHR_lights_punctual` lights (a light of a type the extension does not define is
//! skipped with a warning, as the nodes that carry it).

use glam::{Mat4, Quat, Vec3};

use super::{ImportError, Importer};
use crate::scene::{
    CameraDef, Falloff, LightDef, LightKind, Node, NodeTransform, Projection, Skin, Trs,
    LUMENS_PER_WATT,
};

impl Importer<'_> {
    /// `light_slots` maps the file's light indices to the imported lights.
    pub(super) fn nodes(&self, light_slots: &[Option<usize>]) -> Result<Vec<Node>, ImportError> {
        let mut nodes: Vec<Node> = Vec::new();
        for (ni, n) in self.root.nodes.iter().enumerate() {
            let transform = match n.matrix {
                Some(m) => NodeTransform::Matrix(Mat4::from_cols_array(&m)),
                None => {
                    let rotation = n.rotation.unwrap_or([0.0, 0.0, 0.0, 1.0]);
                    let q = Quat::from_array(rotation);
                    // The spec asks for a unit quaternion; tolerate rounding, refuse zero.
                    if q.length().is_nan() || q.length() <= 1e-3 {
                        return Err(ImportError::Node {
                            path: self.path.to_path_buf(),
                            node: ni,
                            name: n.name.clone(),
                            reason: format!("rotation {rotation:?} is not a unit quaternion"),
                        });
                    }
                    NodeTransform::Trs(Trs {
                        translation: Vec3::from_array(n.translation.unwrap_or([0.0; 3])),
                        rotation: q.normalize(),
                        scale: Vec3::from_array(n.scale.unwrap_or([1.0; 3])),
                    })
                }
            };
            let light = n
                .extensions
                .as_ref()
                .and_then(|e| e.light.as_ref())
                .and_then(|l| l.light)
                .and_then(|l| light_slots.get(l).copied().flatten());
            nodes.push(Node {
                name: n.name.clone(),
                parent: None,
                children: n.children.clone(),
                transform,
                mesh: n.mesh,
                skin: n.skin,
                camera: n.camera,
                light,
                weights: n.weights.clone(),
            });
        }
        for p in 0..nodes.len() {
            for k in 0..nodes[p].children.len() {
                let c = nodes[p].children[k];
                let Some(child) = nodes.get_mut(c) else {
                    continue; // validated
                };
                if let Some(other) = child.parent {
                    return Err(ImportError::Node {
                        path: self.path.to_path_buf(),
                        node: c,
                        name: child.name.clone(),
                        reason: format!("is a child of both node {other} and node {p}"),
                    });
                }
                child.parent = Some(p);
            }
        }
        Ok(nodes)
    }

    pub(super) fn skins(&self) -> Result<Vec<Skin>, ImportError> {
        let mut out = Vec::new();
        for (si, s) in self.root.skins.iter().enumerate() {
            let joints: Vec<usize> = s.joints.clone().unwrap_or_default();
            let inverse_bind_matrices = match s.inverse_bind_matrices {
                Some(acc) => {
                    let usage = format!("skins[{si}].inverseBindMatrices");
                    let f = self.floats(acc, &usage, 16, false)?;
                    if f.len() / 16 < joints.len() {
                        return Err(self.acc_err(
                            acc,
                            &usage,
                            format!("{} matrices for {} joints", f.len() / 16, joints.len()),
                        ));
                    }
                    f.chunks_exact(16)
                        .take(joints.len())
                        .map(Mat4::from_cols_slice)
                        .collect()
                }
                None => vec![Mat4::IDENTITY; joints.len()],
            };
            out.push(Skin {
                name: s.name.clone(),
                joints,
                inverse_bind_matrices,
            });
        }
        Ok(out)
    }

    /// Camera definitions (placed later by the nodes that reference them).
    pub(super) fn cameras(&self) -> Vec<CameraDef> {
        self.root
            .cameras
            .iter()
            .map(|c| CameraDef {
                name: c.name.clone(),
                projection: match (&c.perspective, &c.orthographic, c.type_.as_deref()) {
                    (_, Some(o), Some("orthographic")) => Projection::Orthographic {
                        xmag: o.xmag.unwrap_or(1.0),
                        ymag: o.ymag.unwrap_or(1.0),
                        znear: o.znear.unwrap_or(0.0),
                        zfar: o.zfar.unwrap_or(1.0),
                    },
                    (Some(p), _, _) => Projection::Perspective {
                        yfov: p.yfov.unwrap_or(std::f32::consts::FRAC_PI_4),
                        aspect: p.aspect_ratio,
                        znear: p.znear.unwrap_or(0.01),
                        zfar: p.zfar,
                    },
                    // `check` requires the object that the type names.
                    _ => Projection::Perspective {
                        yfov: std::f32::consts::FRAC_PI_4,
                        aspect: None,
                        znear: 0.01,
                        zfar: None,
                    },
                },
            })
            .collect()
    }

    /// The lights we know the type of, and for each light of the file its slot among
    /// them (`None`: skipped with a warning).
    pub(super) fn lights(&mut self) -> (Vec<LightDef>, Vec<Option<usize>>) {
        let root = self.root;
        let Some(lights) = root
            .extensions
            .as_ref()
            .and_then(|e| e.lights_punctual.as_ref())
        else {
            return (Vec::new(), Vec::new());
        };
        let mut out = Vec::new();
        let mut slots = Vec::with_capacity(lights.lights.len());
        for (li, l) in lights.lights.iter().enumerate() {
            let spot = l.spot.as_ref();
            let kind = match l.type_.as_deref() {
                Some("point") => LightKind::Point,
                Some("directional") => LightKind::Directional,
                Some("spot") => LightKind::Spot {
                    inner_cone_angle: spot.map_or(0.0, |s| s.inner_cone_angle),
                    outer_cone_angle: spot
                        .map_or(std::f32::consts::FRAC_PI_4, |s| s.outer_cone_angle),
                },
                other => {
                    self.warn(format!(
                        "KHR_lights_punctual lights[{li}]: type {:?} is not point, spot or \
                         directional; the light is skipped",
                        other.unwrap_or("(none)")
                    ));
                    slots.push(None);
                    continue;
                }
            };
            // KHR_lights_punctual is inverse-square; subfield's writer records a light
            // without falloff (from AFF) as `extras.falloff: "none"`.
            let falloff = match l.extras.as_ref().and_then(|e| e.get("falloff")) {
                None => Falloff::InverseSquare,
                Some(v) if v == "none" => Falloff::None,
                Some(v) if v == "inverseSquare" => Falloff::InverseSquare,
                Some(v) => {
                    self.warn(format!(
                        "KHR_lights_punctual lights[{li}]: extras.falloff {v} is not \"none\" \
                         or \"inverseSquare\"; the light falls off with the inverse square"
                    ));
                    Falloff::InverseSquare
                }
            };
            slots.push(Some(out.len()));
            out.push(LightDef {
                name: l.name.clone(),
                kind,
                color: Vec3::from_array(l.color),
                // Candela and lux to W/sr and W/m² (the model's unit, see `LightDef`).
                intensity: (l.intensity / LUMENS_PER_WATT) as f32,
                range: l.range,
                falloff,
            });
        }
        (out, slots)
    }
}
