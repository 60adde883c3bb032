//! Meshes and their primitives: positions, normals, `TEXCOORD_0`, skin influences,
//! indices (strips and fans unrolled) and morph targets.

use glam::{Vec2, Vec3};
use gltf::mesh::Mode;

use super::{ImportError, Importer};
use crate::scene::{Mesh, MorphTarget, Primitive};

/// Per-vertex skin influences: joints and weights, `sets` entries per vertex.
type Influences = (Vec<[u16; 4]>, Vec<[f32; 4]>);

impl Importer<'_> {
    pub(super) fn meshes(&mut self) -> Result<Vec<Mesh>, ImportError> {
        let mut skipped = Vec::new();
        let mut meshes = Vec::new();
        for mesh in self.doc.meshes() {
            let mi = mesh.index();
            let mut primitives = Vec::new();
            for prim in mesh.primitives() {
                let pi = prim.index();
                let mode = prim.mode();
                if matches!(
                    mode,
                    Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
                ) {
                    skipped.push(format!("meshes[{mi}].primitives[{pi}] ({mode:?})"));
                    continue;
                }
                primitives.push(self.primitive(&prim, mi, pi, mode)?);
            }
            meshes.push(Mesh {
                name: mesh.name().map(str::to_string),
                primitives,
                weights: mesh.weights().map(<[f32]>::to_vec).unwrap_or_default(),
            });
        }
        if !skipped.is_empty() {
            self.warn(format!(
                "skipped {} point/line primitive(s), only triangles are traced: {}",
                skipped.len(),
                skipped.join(", ")
            ));
        }
        Ok(meshes)
    }

    /// One triangle primitive; its accessors must agree with the POSITION count.
    pub(super) fn primitive(
        &mut self,
        prim: &gltf::Primitive,
        mi: usize,
        pi: usize,
        mode: Mode,
    ) -> Result<Primitive, ImportError> {
        let at = format!("meshes[{mi}].primitives[{pi}]");
        let get = |s: gltf::Semantic| prim.get(&s);
        let pos_acc = get(gltf::Semantic::Positions).ok_or_else(|| ImportError::Model {
            path: self.path.to_path_buf(),
            reason: format!("{at} has no POSITION"),
        })?;
        let positions = self.vec3s(&pos_acc, &format!("{at}.POSITION"))?;
        let nv = positions.len();
        let normals = match get(gltf::Semantic::Normals) {
            Some(acc) => {
                let usage = format!("{at}.NORMAL");
                self.same_count(&acc, &usage, nv)?;
                Some(self.vec3s(&acc, &usage)?)
            }
            None => None,
        };
        let uvs = match get(gltf::Semantic::TexCoords(0)) {
            Some(acc) => {
                let usage = format!("{at}.TEXCOORD_0");
                self.same_count(&acc, &usage, nv)?;
                let f = self.floats(&acc, &usage, 2, true)?;
                Some(f.chunks_exact(2).map(Vec2::from_slice).collect())
            }
            None => None,
        };
        let (joints, weights) = self.skin_influences(prim, &at, nv)?;
        let triangles = self.triangles(prim, &at, nv, mode)?;
        let morph_targets = self.morph_targets(prim, &at, nv)?;
        Ok(Primitive {
            positions,
            normals,
            uvs,
            triangles,
            material: prim.material().index().map_or(u32::MAX, |m| m as u32),
            joints,
            weights,
            morph_targets,
        })
    }

    /// An attribute accessor must have one element per vertex.
    fn same_count(&self, acc: &gltf::Accessor, usage: &str, nv: usize) -> Result<(), ImportError> {
        if acc.count() != nv {
            Err(self.acc_err(
                acc.index(),
                usage,
                format!("count {} differs from the POSITION count {nv}", acc.count()),
            ))
        } else {
            Ok(())
        }
    }

    /// Skin influences, every JOINTS_n/WEIGHTS_n pair, interleaved per vertex.
    fn skin_influences(
        &self,
        prim: &gltf::Primitive,
        at: &str,
        nv: usize,
    ) -> Result<Influences, ImportError> {
        let mut sets: Vec<(Vec<u32>, Vec<f32>)> = Vec::new();
        for s in 0u32.. {
            let (Some(j), Some(w)) = (
                prim.get(&gltf::Semantic::Joints(s)),
                prim.get(&gltf::Semantic::Weights(s)),
            ) else {
                break;
            };
            let (ju, wu) = (format!("{at}.JOINTS_{s}"), format!("{at}.WEIGHTS_{s}"));
            self.same_count(&j, &ju, nv)?;
            self.same_count(&w, &wu, nv)?;
            let joints = self.uints(&j, &ju, 4)?;
            if let Some(big) = joints.iter().find(|&&x| x > u32::from(u16::MAX)) {
                return Err(self.acc_err(j.index(), &ju, format!("joint {big} out of range")));
            }
            sets.push((joints, self.floats(&w, &wu, 4, true)?));
        }
        let mut joints = Vec::with_capacity(nv * sets.len());
        let mut weights = Vec::with_capacity(nv * sets.len());
        for v in 0..nv {
            for (j, w) in &sets {
                let j4 = &j[v * 4..v * 4 + 4];
                joints.push([j4[0] as u16, j4[1] as u16, j4[2] as u16, j4[3] as u16]);
                weights.push([w[v * 4], w[v * 4 + 1], w[v * 4 + 2], w[v * 4 + 3]]);
            }
        }
        Ok((joints, weights))
    }

    /// The indices (or `0..nv`), checked against the vertex count, as triangles: strips
    /// and fans unrolled, a trailing partial triangle dropped with a warning.
    fn triangles(
        &mut self,
        prim: &gltf::Primitive,
        at: &str,
        nv: usize,
        mode: Mode,
    ) -> Result<Vec<[u32; 3]>, ImportError> {
        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => {
                let usage = format!("{at}.indices");
                let idx = self.uints(&acc, &usage, 1)?;
                if let Some((k, &i)) = idx.iter().enumerate().find(|(_, &i)| i as usize >= nv) {
                    return Err(self.acc_err(
                        acc.index(),
                        &usage,
                        format!("index {i} (element {k}) is past the vertex count {nv}"),
                    ));
                }
                idx
            }
            None => (0..nv as u32).collect(),
        };
        Ok(match mode {
            Mode::Triangles => {
                if indices.len() % 3 != 0 {
                    self.warn(format!(
                        "{at}: {} indices is not a multiple of 3; the last {} dropped",
                        indices.len(),
                        indices.len() % 3
                    ));
                }
                indices
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect()
            }
            // Spec 3.7.2.1: strip triangle i is (v_i, v_{i+1+i%2}, v_{i+2-i%2}).
            Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
                .map(|i| {
                    let odd = i % 2;
                    [indices[i], indices[i + 1 + odd], indices[i + 2 - odd]]
                })
                .collect(),
            // Spec: fan triangle i is (v_{i+1}, v_{i+2}, v_0).
            Mode::TriangleFan => (0..indices.len().saturating_sub(2))
                .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
                .collect(),
            _ => Vec::new(),
        })
    }

    /// Morph targets: POSITION and NORMAL displacements (empty when absent).
    fn morph_targets(
        &self,
        prim: &gltf::Primitive,
        at: &str,
        nv: usize,
    ) -> Result<Vec<MorphTarget>, ImportError> {
        let mut morph_targets = Vec::new();
        for (ti, target) in prim.morph_targets().enumerate() {
            let read =
                |acc: Option<gltf::Accessor>, what: &str| -> Result<Vec<Vec3>, ImportError> {
                    match acc {
                        Some(acc) => {
                            let usage = format!("{at}.targets[{ti}].{what}");
                            self.same_count(&acc, &usage, nv)?;
                            self.vec3s(&acc, &usage)
                        }
                        None => Ok(Vec::new()),
                    }
                };
            let positions = read(target.positions(), "POSITION")?;
            let normals = read(target.normals(), "NORMAL")?;
            morph_targets.push(MorphTarget { positions, normals });
        }
        Ok(morph_targets)
    }
}
