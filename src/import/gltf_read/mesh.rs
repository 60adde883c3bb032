//! Meshes and their primitives: positions, normals, the texture-coordinate set the
//! material's textures use, skin influences, indices (strips and fans unrolled) and morph
//! targets. `KHR_mesh_quantization`'s integer attributes are read like any other (the
//! accessor's `normalized` flag decides).

use std::collections::BTreeMap;

use glam::Vec2;

use super::json;
use super::{ImportError, Importer};
use crate::scene::{Material, Mesh, MorphTarget, Primitive};

/// Per-vertex skin influences: joints and weights, `sets` entries per vertex.
type Influences = (Vec<[u16; 4]>, Vec<[f32; 4]>);

/// Primitive modes (spec 3.7.2.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Points,
    Lines,
    LineLoop,
    LineStrip,
    Triangles,
    TriangleStrip,
    TriangleFan,
}

impl Mode {
    fn from_code(code: u32) -> Option<Mode> {
        Some(match code {
            0 => Mode::Points,
            1 => Mode::Lines,
            2 => Mode::LineLoop,
            3 => Mode::LineStrip,
            4 => Mode::Triangles,
            5 => Mode::TriangleStrip,
            6 => Mode::TriangleFan,
            _ => return None,
        })
    }
}

impl Importer<'_> {
    /// `materials` are the imported ones (same indices as the file's): a primitive reads
    /// the texture-coordinate set its material's textures name.
    pub(super) fn meshes(&mut self, materials: &[Material]) -> Result<Vec<Mesh>, ImportError> {
        let mut skipped = Vec::new();
        let mut no_position = Vec::new();
        let mut meshes = Vec::new();
        let root = self.root;
        for (mi, mesh) in root.meshes.iter().enumerate() {
            let mut primitives = Vec::new();
            for (pi, prim) in mesh.primitives.iter().flatten().enumerate() {
                let mode = Mode::from_code(prim.mode.unwrap_or(4)).unwrap_or(Mode::Triangles);
                if matches!(
                    mode,
                    Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
                ) {
                    skipped.push(format!("meshes[{mi}].primitives[{pi}] ({mode:?})"));
                    continue;
                }
                // The specification allows a primitive without POSITION (an extension
                // or other attributes may stand for it): there is nothing to trace.
                let position = prim.attributes.as_ref().and_then(|a| a.get("POSITION"));
                let Some(&position) = position else {
                    let name = mesh
                        .name
                        .as_ref()
                        .map(|n| format!(" ({n:?})"))
                        .unwrap_or_default();
                    no_position.push(format!("meshes[{mi}]{name}.primitives[{pi}]"));
                    continue;
                };
                let material = prim.material.and_then(|m| materials.get(m));
                primitives.push(self.primitive(prim, position, (mi, pi), mode, material)?);
            }
            meshes.push(Mesh {
                name: mesh.name.clone(),
                primitives,
                weights: mesh.weights.clone().unwrap_or_default(),
            });
        }
        if !skipped.is_empty() {
            self.warn(format!(
                "skipped {} point/line primitive(s), only triangles are traced: {}",
                skipped.len(),
                skipped.join(", ")
            ));
        }
        if !no_position.is_empty() {
            // Said plainly when it leaves the file nothing at all: the frames are empty.
            let left = meshes.iter().any(|m: &Mesh| !m.primitives.is_empty());
            self.warn(format!(
                "skipped {} primitive(s) without POSITION, which have nothing to trace: {}{}",
                no_position.len(),
                no_position.join(", "),
                if left {
                    ""
                } else {
                    "; no mesh has a primitive left, so the frames show the background alone"
                }
            ));
        }
        Ok(meshes)
    }

    /// One triangle primitive, its POSITION accessor `pos_acc`; its other accessors
    /// must agree with the POSITION count.
    fn primitive(
        &mut self,
        prim: &json::Primitive,
        pos_acc: usize,
        (mi, pi): (usize, usize),
        mode: Mode,
        material: Option<&Material>,
    ) -> Result<Primitive, ImportError> {
        let at = format!("meshes[{mi}].primitives[{pi}]");
        let empty = BTreeMap::new();
        let attrs = prim.attributes.as_ref().unwrap_or(&empty);
        let get = |s: &str| attrs.get(s).copied();
        let positions = self.vec3s(pos_acc, &format!("{at}.POSITION"))?;
        let nv = positions.len();
        let normals = match get("NORMAL") {
            Some(acc) => {
                let usage = format!("{at}.NORMAL");
                self.same_count(acc, &usage, nv)?;
                Some(self.vec3s(acc, &usage)?)
            }
            None => None,
        };
        let set = self.uv_set(material, &at);
        let uvs = match get(&format!("TEXCOORD_{set}")) {
            Some(acc) => {
                let usage = format!("{at}.TEXCOORD_{set}");
                self.same_count(acc, &usage, nv)?;
                // The base specification allows only normalised integer texture
                // coordinates; KHR_mesh_quantization adds plain integers.
                let force = !self.uses("KHR_mesh_quantization");
                let f = self.floats(acc, &usage, 2, force)?;
                Some(f.chunks_exact(2).map(Vec2::from_slice).collect())
            }
            None => {
                if set != 0 {
                    self.warn(format!(
                        "{at}: its material's textures use TEXCOORD_{set}, which it lacks; \
                         textures sampled at (0, 0)"
                    ));
                }
                None
            }
        };
        let (joints, weights) = self.skin_influences(attrs, &at, nv)?;
        let triangles = self.triangles(prim, &at, nv, mode)?;
        let morph_targets = self.morph_targets(prim, &at, nv)?;
        Ok(Primitive {
            positions,
            normals,
            uvs,
            triangles,
            material: prim.material.map_or(u32::MAX, |m| m as u32),
            joints,
            weights,
            morph_targets,
        })
    }

    /// The texture-coordinate set a material's textures use: the base colour's, else the
    /// emissive's, else the metallic-roughness', else the normal map's. Textures naming different sets are
    /// drawn with the first one's (warned): a triangle carries one set.
    fn uv_set(&mut self, material: Option<&Material>, at: &str) -> u32 {
        let Some(m) = material else { return 0 };
        let refs: Vec<u32> = [
            m.base_color_texture,
            m.emissive_texture,
            m.metallic_roughness_texture,
            m.normal_texture,
        ]
        .into_iter()
        .flatten()
        .map(|r| r.tex_coord)
        .collect();
        let Some(&first) = refs.first() else { return 0 };
        if refs.iter().any(|&s| s != first) {
            self.warn(format!(
                "{at}: its material's textures use different TEXCOORD sets {refs:?}; all \
                 are sampled with TEXCOORD_{first}"
            ));
        }
        first
    }

    /// An attribute accessor must have one element per vertex.
    fn same_count(&self, acc: usize, usage: &str, nv: usize) -> Result<(), ImportError> {
        let count = self.count(acc);
        if count != nv {
            Err(self.acc_err(
                acc,
                usage,
                format!("count {count} differs from the POSITION count {nv}"),
            ))
        } else {
            Ok(())
        }
    }

    /// Skin influences, every JOINTS_n/WEIGHTS_n pair, interleaved per vertex.
    fn skin_influences(
        &self,
        attrs: &BTreeMap<String, usize>,
        at: &str,
        nv: usize,
    ) -> Result<Influences, ImportError> {
        let mut sets: Vec<(Vec<u32>, Vec<f32>)> = Vec::new();
        for s in 0u32.. {
            let (Some(&j), Some(&w)) = (
                attrs.get(&format!("JOINTS_{s}")),
                attrs.get(&format!("WEIGHTS_{s}")),
            ) else {
                break;
            };
            let (ju, wu) = (format!("{at}.JOINTS_{s}"), format!("{at}.WEIGHTS_{s}"));
            self.same_count(j, &ju, nv)?;
            self.same_count(w, &wu, nv)?;
            let joints = self.uints(j, &ju, 4)?;
            if let Some(big) = joints.iter().find(|&&x| x > u32::from(u16::MAX)) {
                return Err(self.acc_err(j, &ju, format!("joint {big} out of range")));
            }
            sets.push((joints, self.floats(w, &wu, 4, true)?));
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
        prim: &json::Primitive,
        at: &str,
        nv: usize,
        mode: Mode,
    ) -> Result<Vec<[u32; 3]>, ImportError> {
        let indices: Vec<u32> = match prim.indices {
            Some(acc) => {
                let usage = format!("{at}.indices");
                let idx = self.uints(acc, &usage, 1)?;
                if let Some((k, &i)) = idx.iter().enumerate().find(|(_, &i)| i as usize >= nv) {
                    return Err(self.acc_err(
                        acc,
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
                if !indices.len().is_multiple_of(3) {
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

    /// Morph targets: POSITION and NORMAL displacements (empty when absent). A cache of
    /// many targets is most of a file's bytes, so the targets are decoded side by side
    /// (their fresh memory's page faults were half of the decoding); an error is the
    /// first in the file's order, as one by one.
    fn morph_targets(
        &self,
        prim: &json::Primitive,
        at: &str,
        nv: usize,
    ) -> Result<Vec<MorphTarget>, ImportError> {
        use rayon::prelude::*;
        let read = |ti: usize, target: &BTreeMap<String, usize>, what: &str| match target.get(what)
        {
            Some(&acc) => {
                let usage = format!("{at}.targets[{ti}].{what}");
                self.same_count(acc, &usage, nv)?;
                self.vec3s(acc, &usage)
            }
            None => Ok(Vec::new()),
        };
        let decoded: Vec<Result<MorphTarget, ImportError>> = prim
            .targets
            .par_iter()
            .enumerate()
            .map(|(ti, target)| {
                Ok(MorphTarget {
                    positions: read(ti, target, "POSITION")?,
                    normals: read(ti, target, "NORMAL")?,
                })
            })
            .collect();
        decoded.into_iter().collect()
    }
}
