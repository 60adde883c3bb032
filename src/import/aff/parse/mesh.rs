//! Geometry blocks: `m` meshes (vertices, normals, texture coordinates, faces) and `tpa`
//! animated triangles (one position and normal per key).

use super::*;

impl Parser {
    pub(super) fn mesh(&mut self, src: &mut Src, line: u32) -> Result<(), ImportError> {
        src.expect("vertices", "m")?;
        let nv = src.count("number of vertices")?;
        let mut verts = Vec::new();
        for _ in 0..nv {
            verts.push(src.vec3("mesh vertex")?);
        }
        let mut normals: Option<Vec<Vec3>> = None;
        let mut uvs: Option<Vec<Vec2>> = None;
        let mut texture = None;
        loop {
            let (word, wline) = src.token("'normals', 'texturecoords' or 'triangles'")?;
            match word {
                "normals" if normals.is_none() && uvs.is_none() => {
                    let n = src.count("number of normals")?;
                    let mut v = Vec::new();
                    for _ in 0..n {
                        v.push(src.vec3("mesh normal")?);
                    }
                    normals = Some(v);
                }
                "texturecoords" if uvs.is_none() => {
                    let n = src.count("number of texture coordinates")?;
                    let (name, tline) = src.token("texture name")?;
                    let name = name.to_string();
                    let mut v = Vec::new();
                    for _ in 0..n {
                        v.push(Vec2::new(src.f("texture u")?, src.f("texture v")?));
                    }
                    texture = Some(self.texture(src, tline, &name)?);
                    uvs = Some(v);
                }
                "triangles" => break,
                other => {
                    return Err(src.err(
                        wline,
                        format!("unexpected {other:?} in mesh 'm' (sections: vertices, normals, texturecoords, triangles)"),
                    ))
                }
            }
        }
        let nt = src.count("number of triangles")?;
        // Normalised normals; `None` where a normal has no length (the face normal is used).
        let unit: Option<Vec<Option<Vec3>>> = normals.as_ref().map(|ns| {
            ns.iter()
                .map(|n| Some(n.normalize_or_zero()).filter(|u| *u != Vec3::ZERO))
                .collect()
        });
        let per = 3 + if unit.is_some() { 3 } else { 0 } + if uvs.is_some() { 3 } else { 0 };
        let mut rec = [0usize; 9];
        let mut remap: HashMap<(usize, usize, usize), u32> = HashMap::new();
        let mut positions = Vec::new();
        let mut out_normals = Vec::new();
        let mut out_uvs = Vec::new();
        let mut indices = Vec::new();
        for ti in 0..nt {
            for (k, slot) in rec.iter_mut().enumerate().take(per) {
                *slot = src.count(&format!("index {} of triangle {ti}", k + 1))?;
            }
            let check = |i: usize, len: usize, what: &str| {
                if i < len {
                    Ok(())
                } else {
                    Err(src.err(
                        src.line,
                        format!("mesh triangle {ti}: {what} index {i} out of range (mesh 'm' at line {line} has {len})"),
                    ))
                }
            };
            let mut cursor = 3;
            let vi = [rec[0], rec[1], rec[2]];
            for &i in &vi {
                check(i, verts.len(), "vertex")?;
            }
            let ni = if let Some(u) = &unit {
                let ni = [rec[cursor], rec[cursor + 1], rec[cursor + 2]];
                cursor += 3;
                for &i in &ni {
                    check(i, u.len(), "normal")?;
                }
                Some(ni)
            } else {
                None
            };
            let ui = if let Some(t) = &uvs {
                let ui = [rec[cursor], rec[cursor + 1], rec[cursor + 2]];
                for &i in &ui {
                    check(i, t.len(), "texture coordinate")?;
                }
                Some(ui)
            } else {
                None
            };
            let face = face_normal(verts[vi[0]], verts[vi[1]], verts[vi[2]]);
            for k in 0..3 {
                let n_idx = ni.map_or(usize::MAX, |n| n[k]);
                let u_idx = ui.map_or(usize::MAX, |u| u[k]);
                let normal = match (&unit, ni) {
                    (Some(u), Some(n)) => Some(u[n[k]]),
                    _ => None,
                };
                // A vertex whose normal has no length takes this face's normal: not shared.
                let shared = normal != Some(None);
                let key = (vi[k], n_idx, u_idx);
                if shared {
                    if let Some(&i) = remap.get(&key) {
                        indices.push(i);
                        continue;
                    }
                }
                let i = positions.len() as u32;
                positions.push(verts[vi[k]]);
                if let Some(n) = normal {
                    out_normals.push(n.unwrap_or(face));
                }
                if let (Some(t), Some(u)) = (&uvs, ui) {
                    out_uvs.push(t[u[k]]);
                }
                if shared {
                    remap.insert(key, i);
                }
                indices.push(i);
            }
        }
        if indices.is_empty() {
            return Ok(());
        }
        let has_normals = unit.is_some();
        let b = self.batch(texture, has_normals);
        let base = b.positions.len() as u32;
        b.positions.extend_from_slice(&positions);
        if let Some(n) = b.normals.as_mut() {
            n.extend_from_slice(&out_normals);
        }
        if let Some(u) = b.uvs.as_mut() {
            u.extend_from_slice(&out_uvs);
        }
        b.indices.extend(indices.iter().map(|i| base + i));
        Ok(())
    }

    pub(super) fn tpa(&mut self, src: &mut Src, line: u32) -> Result<(), ImportError> {
        let n = src.count("number of keys")?;
        if n == 0 {
            return Err(src.err(line, "tpa with no keys"));
        }
        let mut times = Vec::new();
        let mut pos: Vec<[Vec3; 3]> = Vec::new();
        let mut nor: Vec<[Vec3; 3]> = Vec::new();
        for k in 0..n {
            let t = src.num(&format!("time of tpa key {}", k + 1))?;
            if let Some(&prev) = times.last() {
                if t <= prev {
                    return Err(src.err(
                        src.line,
                        format!("tpa key times must increase ({t} after {prev})"),
                    ));
                }
            }
            times.push(t);
            let mut p = [Vec3::ZERO; 3];
            let mut q = [Vec3::ZERO; 3];
            for j in 0..3 {
                p[j] = src.vec3("tpa vertex")?;
                q[j] = src.vec3("tpa normal")?;
            }
            let face = face_normal(p[0], p[1], p[2]);
            for v in &mut q {
                let u = v.normalize_or_zero();
                *v = if u == Vec3::ZERO { face } else { u };
            }
            pos.push(p);
            nor.push(q);
        }
        if n == 1 {
            self.add_triangles(None, &pos[0], Some(&nor[0]), None);
            return Ok(());
        }
        let node = self.current();
        let material = self.material();
        let key = (node, material, times.iter().map(|t| t.to_bits()).collect());
        let nodes = &mut self.scene.nodes;
        let i = *self.morph_index.entry(key).or_insert_with(|| {
            nodes[node].morphs.push(MorphBatch {
                material,
                times: times.clone(),
                positions: vec![Vec::new(); n],
                normals: vec![Vec::new(); n],
            });
            nodes[node].morphs.len() - 1
        });
        let m = &mut nodes[node].morphs[i];
        for k in 0..n {
            m.positions[k].extend_from_slice(&pos[k]);
            m.normals[k].extend_from_slice(&nor[k]);
        }
        Ok(())
    }
}
