//! Structural validation of the JSON, per the glTF 2.0 specification: the properties it
//! requires are there, every index is in range, every enumeration has a defined value.
//! Past this the readers index the root's arrays freely. Anything the specification
//! allows passes (an accessor without a buffer view, a texture whose image comes from an
//! extension, a channel target without a node, an unknown light type or accessor type, a
//! scene without nodes); what we cannot draw is the readers' business, as a warning or an
//! [`ImportError::Unsupported`](super::ImportError).
//!
//! Every problem found is listed with its JSON path (`skins[0].joints[1]: index 9 out of
//! range (3 nodes)`).

use super::json::{ComponentType, Root, TextureInfo};

/// Primitive modes 0 (points) to 6 (triangle fan).
const MAX_MODE: u32 = 6;

struct Problems(Vec<String>);

impl Problems {
    fn push(&mut self, at: impl std::fmt::Display, what: impl std::fmt::Display) {
        self.0.push(format!("{at}: {what}"));
    }

    /// An optional index: in range when present.
    fn index(&mut self, at: impl std::fmt::Display, i: Option<usize>, len: usize, of: &str) {
        if let Some(i) = i {
            if i >= len {
                self.push(at, format!("index {i} out of range ({len} {of})"));
            }
        }
    }

    /// A required index: present and in range.
    fn required(&mut self, at: impl std::fmt::Display, i: Option<usize>, len: usize, of: &str) {
        match i {
            None => self.push(at, "required, missing"),
            Some(_) => self.index(at, i, len, of),
        }
    }
}

/// Every structural problem of the document, empty when it is valid.
pub(super) fn check(root: &Root) -> Vec<String> {
    let mut p = Problems(Vec::new());
    let n = Counts::of(root);
    asset(root, &mut p);
    buffers(root, &n, &mut p);
    accessors(root, &n, &mut p);
    textures(root, &n, &mut p);
    materials(root, &n, &mut p);
    meshes(root, &n, &mut p);
    nodes(root, &n, &mut p);
    skins_and_scenes(root, &n, &mut p);
    cameras(root, &mut p);
    animations(root, &n, &mut p);
    p.0
}

struct Counts {
    accessors: usize,
    buffers: usize,
    views: usize,
    cameras: usize,
    images: usize,
    materials: usize,
    meshes: usize,
    nodes: usize,
    samplers: usize,
    skins: usize,
    textures: usize,
    lights: usize,
}

impl Counts {
    fn of(r: &Root) -> Counts {
        Counts {
            accessors: r.accessors.len(),
            buffers: r.buffers.len(),
            views: r.buffer_views.len(),
            cameras: r.cameras.len(),
            images: r.images.len(),
            materials: r.materials.len(),
            meshes: r.meshes.len(),
            nodes: r.nodes.len(),
            samplers: r.samplers.len(),
            skins: r.skins.len(),
            textures: r.textures.len(),
            lights: r
                .extensions
                .as_ref()
                .and_then(|e| e.lights_punctual.as_ref())
                .map_or(0, |l| l.lights.len()),
        }
    }
}

/// `asset.version` is required; a major version other than 2 (glTF 1.0, or a future
/// one) is not this format. `minVersion` above 2.0 asks for more than we know.
fn asset(r: &Root, p: &mut Problems) {
    let Some(a) = &r.asset else {
        p.push("asset", "required, missing");
        return;
    };
    match a.version.as_deref() {
        None => p.push("asset.version", "required, missing"),
        Some(v) if v.split('.').next() != Some("2") => {
            p.push("asset.version", format!("{v:?}: only glTF 2.x is read"))
        }
        Some(_) => {}
    }
    if let Some(m) = a.min_version.as_deref() {
        if m != "2.0" {
            p.push("asset.minVersion", format!("{m:?}: only glTF 2.0 is read"));
        }
    }
}

fn buffers(r: &Root, n: &Counts, p: &mut Problems) {
    for (i, b) in r.buffers.iter().enumerate() {
        if b.byte_length.is_none() {
            p.push(format!("buffers[{i}].byteLength"), "required, missing");
        }
    }
    for (i, v) in r.buffer_views.iter().enumerate() {
        p.required(
            format!("bufferViews[{i}].buffer"),
            v.buffer,
            n.buffers,
            "buffers",
        );
        if v.byte_length.is_none() {
            p.push(format!("bufferViews[{i}].byteLength"), "required, missing");
        }
        if let Some(s) = v.byte_stride {
            if !(4..=252).contains(&s) || s % 4 != 0 {
                p.push(
                    format!("bufferViews[{i}].byteStride"),
                    format!("{s} is not a multiple of 4 in 4..=252"),
                );
            }
        }
    }
    for (i, im) in r.images.iter().enumerate() {
        p.index(
            format!("images[{i}].bufferView"),
            im.buffer_view,
            n.views,
            "bufferViews",
        );
        match (&im.uri, im.buffer_view) {
            (Some(_), Some(_)) => p.push(format!("images[{i}]"), "has both uri and bufferView"),
            (None, None) => p.push(format!("images[{i}]"), "has neither uri nor bufferView"),
            // A missing mimeType is tolerated: the decoder recognises the format.
            _ => {}
        }
    }
}

fn accessors(r: &Root, n: &Counts, p: &mut Problems) {
    for (i, a) in r.accessors.iter().enumerate() {
        let at = format!("accessors[{i}]");
        p.index(
            format!("{at}.bufferView"),
            a.buffer_view,
            n.views,
            "bufferViews",
        );
        match a.component_type {
            None => p.push(format!("{at}.componentType"), "required, missing"),
            Some(c) if ComponentType::from_code(c).is_none() => {
                p.push(format!("{at}.componentType"), format!("{c} is not defined"))
            }
            Some(_) => {}
        }
        // The schema lets `type` be any string (a later glTF may add one, and the
        // validator only warns): an unknown one is refused when the accessor is read.
        if a.type_.is_none() {
            p.push(format!("{at}.type"), "required, missing");
        }
        if a.count.is_none() {
            p.push(format!("{at}.count"), "required, missing");
        }
        if let Some(s) = &a.sparse {
            if s.count.is_none() {
                p.push(format!("{at}.sparse.count"), "required, missing");
            }
            match &s.indices {
                None => p.push(format!("{at}.sparse.indices"), "required, missing"),
                Some(ix) => {
                    p.required(
                        format!("{at}.sparse.indices.bufferView"),
                        ix.buffer_view,
                        n.views,
                        "bufferViews",
                    );
                    match ix.component_type {
                        Some(5121 | 5123 | 5125) => {}
                        Some(c) => p.push(
                            format!("{at}.sparse.indices.componentType"),
                            format!("{c} is not an unsigned integer type"),
                        ),
                        None => p.push(
                            format!("{at}.sparse.indices.componentType"),
                            "required, missing",
                        ),
                    }
                }
            }
            match &s.values {
                None => p.push(format!("{at}.sparse.values"), "required, missing"),
                Some(v) => p.required(
                    format!("{at}.sparse.values.bufferView"),
                    v.buffer_view,
                    n.views,
                    "bufferViews",
                ),
            }
        }
    }
}

fn textures(r: &Root, n: &Counts, p: &mut Problems) {
    for (i, t) in r.textures.iter().enumerate() {
        let at = format!("textures[{i}]");
        p.index(format!("{at}.sampler"), t.sampler, n.samplers, "samplers");
        p.index(format!("{at}.source"), t.source, n.images, "images");
        if let Some(e) = &t.extensions {
            for (name, ext) in [
                ("EXT_texture_webp", &e.webp),
                ("KHR_texture_basisu", &e.basisu),
            ] {
                if let Some(ext) = ext {
                    p.index(
                        format!("{at}.extensions.{name}.source"),
                        ext.source,
                        n.images,
                        "images",
                    );
                }
            }
        }
    }
    for (i, s) in r.samplers.iter().enumerate() {
        for (name, v, ok) in [
            ("magFilter", s.mag_filter, &[9728, 9729][..]),
            (
                "minFilter",
                s.min_filter,
                &[9728, 9729, 9984, 9985, 9986, 9987][..],
            ),
            ("wrapS", s.wrap_s, &[33071, 33648, 10497][..]),
            ("wrapT", s.wrap_t, &[33071, 33648, 10497][..]),
        ] {
            if let Some(v) = v {
                if !ok.contains(&v) {
                    p.push(
                        format!("samplers[{i}].{name}"),
                        format!("{v} is not defined"),
                    );
                }
            }
        }
    }
}

fn texture_info(at: String, info: &Option<TextureInfo>, n: &Counts, p: &mut Problems) {
    if let Some(info) = info {
        p.required(format!("{at}.index"), info.index, n.textures, "textures");
    }
}

fn materials(r: &Root, n: &Counts, p: &mut Problems) {
    for (i, m) in r.materials.iter().enumerate() {
        let at = format!("materials[{i}]");
        if let Some(pbr) = &m.pbr_metallic_roughness {
            texture_info(
                format!("{at}.pbrMetallicRoughness.baseColorTexture"),
                &pbr.base_color_texture,
                n,
                p,
            );
            texture_info(
                format!("{at}.pbrMetallicRoughness.metallicRoughnessTexture"),
                &pbr.metallic_roughness_texture,
                n,
                p,
            );
        }
        texture_info(format!("{at}.emissiveTexture"), &m.emissive_texture, n, p);
        texture_info(format!("{at}.normalTexture"), &m.normal_texture, n, p);
        texture_info(format!("{at}.occlusionTexture"), &m.occlusion_texture, n, p);
        if let Some(t) = m.extensions.as_ref().and_then(|e| e.transmission.as_ref()) {
            texture_info(
                format!("{at}.extensions.KHR_materials_transmission.transmissionTexture"),
                &t.transmission_texture,
                n,
                p,
            );
        }
        if let Some(mode) = &m.alpha_mode {
            if !["OPAQUE", "MASK", "BLEND"].contains(&mode.as_str()) {
                p.push(
                    format!("{at}.alphaMode"),
                    format!("{mode:?} is not defined"),
                );
            }
        }
    }
}

fn meshes(r: &Root, n: &Counts, p: &mut Problems) {
    for (mi, m) in r.meshes.iter().enumerate() {
        let Some(prims) = &m.primitives else {
            p.push(format!("meshes[{mi}].primitives"), "required, missing");
            continue;
        };
        if prims.is_empty() {
            p.push(format!("meshes[{mi}].primitives"), "empty");
        }
        for (pi, prim) in prims.iter().enumerate() {
            let at = format!("meshes[{mi}].primitives[{pi}]");
            match &prim.attributes {
                None => p.push(format!("{at}.attributes"), "required, missing"),
                Some(attrs) => {
                    for (name, &a) in attrs {
                        p.index(
                            format!("{at}.attributes.{name}"),
                            Some(a),
                            n.accessors,
                            "accessors",
                        );
                    }
                }
            }
            p.index(
                format!("{at}.indices"),
                prim.indices,
                n.accessors,
                "accessors",
            );
            p.index(
                format!("{at}.material"),
                prim.material,
                n.materials,
                "materials",
            );
            if let Some(mode) = prim.mode.filter(|&m| m > MAX_MODE) {
                p.push(format!("{at}.mode"), format!("{mode} is not defined"));
            }
            for (ti, t) in prim.targets.iter().enumerate() {
                for (name, &a) in t {
                    p.index(
                        format!("{at}.targets[{ti}].{name}"),
                        Some(a),
                        n.accessors,
                        "accessors",
                    );
                }
            }
        }
    }
}

fn nodes(r: &Root, n: &Counts, p: &mut Problems) {
    for (ni, node) in r.nodes.iter().enumerate() {
        let at = format!("nodes[{ni}]");
        for (k, &c) in node.children.iter().enumerate() {
            p.index(format!("{at}.children[{k}]"), Some(c), n.nodes, "nodes");
        }
        p.index(format!("{at}.mesh"), node.mesh, n.meshes, "meshes");
        p.index(format!("{at}.skin"), node.skin, n.skins, "skins");
        p.index(format!("{at}.camera"), node.camera, n.cameras, "cameras");
        if node.skin.is_some() && node.mesh.is_none() {
            p.push(format!("{at}.skin"), "a skin without a mesh");
        }
        if let Some(l) = node.extensions.as_ref().and_then(|e| e.light.as_ref()) {
            p.required(
                format!("{at}.extensions.KHR_lights_punctual.light"),
                l.light,
                n.lights,
                "lights",
            );
        }
    }
}

fn skins_and_scenes(r: &Root, n: &Counts, p: &mut Problems) {
    for (si, s) in r.skins.iter().enumerate() {
        let at = format!("skins[{si}]");
        match &s.joints {
            None => p.push(format!("{at}.joints"), "required, missing"),
            Some(j) => {
                for (k, &j) in j.iter().enumerate() {
                    p.index(format!("{at}.joints[{k}]"), Some(j), n.nodes, "nodes");
                }
            }
        }
        p.index(
            format!("{at}.inverseBindMatrices"),
            s.inverse_bind_matrices,
            n.accessors,
            "accessors",
        );
        p.index(format!("{at}.skeleton"), s.skeleton, n.nodes, "nodes");
    }
    for (si, s) in r.scenes.iter().enumerate() {
        for (k, &node) in s.nodes.iter().enumerate() {
            p.index(
                format!("scenes[{si}].nodes[{k}]"),
                Some(node),
                n.nodes,
                "nodes",
            );
        }
    }
    p.index("scene", r.scene, r.scenes.len(), "scenes");
}

fn cameras(r: &Root, p: &mut Problems) {
    for (ci, c) in r.cameras.iter().enumerate() {
        let at = format!("cameras[{ci}]");
        match c.type_.as_deref() {
            None => p.push(format!("{at}.type"), "required, missing"),
            Some("perspective") => match &c.perspective {
                None => p.push(format!("{at}.perspective"), "required, missing"),
                Some(q) => {
                    if q.yfov.is_none() {
                        p.push(format!("{at}.perspective.yfov"), "required, missing");
                    }
                    if q.znear.is_none() {
                        p.push(format!("{at}.perspective.znear"), "required, missing");
                    }
                }
            },
            Some("orthographic") => match &c.orthographic {
                None => p.push(format!("{at}.orthographic"), "required, missing"),
                Some(o) => {
                    for (name, v) in [
                        ("xmag", o.xmag),
                        ("ymag", o.ymag),
                        ("znear", o.znear),
                        ("zfar", o.zfar),
                    ] {
                        if v.is_none() {
                            p.push(format!("{at}.orthographic.{name}"), "required, missing");
                        }
                    }
                }
            },
            Some(t) => p.push(format!("{at}.type"), format!("{t:?} is not defined")),
        }
    }
}

fn animations(r: &Root, n: &Counts, p: &mut Problems) {
    for (ai, a) in r.animations.iter().enumerate() {
        let at = format!("animations[{ai}]");
        let samplers = a.samplers.as_deref().unwrap_or(&[]);
        if a.samplers.is_none() {
            p.push(format!("{at}.samplers"), "required, missing");
        }
        if a.channels.is_none() {
            p.push(format!("{at}.channels"), "required, missing");
        }
        for (si, s) in samplers.iter().enumerate() {
            let sat = format!("{at}.samplers[{si}]");
            p.required(format!("{sat}.input"), s.input, n.accessors, "accessors");
            p.required(format!("{sat}.output"), s.output, n.accessors, "accessors");
            if let Some(i) = &s.interpolation {
                if !["LINEAR", "STEP", "CUBICSPLINE"].contains(&i.as_str()) {
                    p.push(
                        format!("{sat}.interpolation"),
                        format!("{i:?} is not defined"),
                    );
                }
            }
        }
        for (ci, c) in a.channels.iter().flatten().enumerate() {
            let cat = format!("{at}.channels[{ci}]");
            p.required(
                format!("{cat}.sampler"),
                c.sampler,
                samplers.len(),
                "samplers",
            );
            let Some(t) = &c.target else {
                p.push(format!("{cat}.target"), "required, missing");
                continue;
            };
            p.index(format!("{cat}.target.node"), t.node, n.nodes, "nodes");
            // Any other path string is allowed by the schema (extensions add them): the
            // reader skips such a channel with a warning.
            if t.path.is_none() {
                p.push(format!("{cat}.target.path"), "required, missing");
            }
        }
    }
}
