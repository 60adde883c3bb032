//! glTF as the specification allows it and as real exporters write it (issue 25): one
//! test per case, each file written here as JSON (`serde_json::json!`) plus a binary
//! buffer (a base64 data URI, or a GLB), with helpers of its own.
//!
//! Valid cases: the import succeeds with the right triangles, uvs, weights...; the
//! Khronos validator (`.ci/node_modules/gltf-validator`, when installed) finds no error
//! in the file; `subfield render` of it exits 0. Invalid or unsupported cases: one
//! error line naming the file and the accessor, node or extension, a non-zero exit, and
//! nothing written.

mod common;

use common::base64;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::{Vec2, Vec3};
use serde_json::{json, Value};
use subfield::import::{self, ImportError};
use subfield::scene::{LightKind, Property, Scene, UvTransform};

// ---------------------------------------------------------------------------------------
// Helpers: a document under construction, files, the validator, the CLI.

/// A glTF document being written: its JSON and its binary buffer (buffer 0), then
/// `more_buffers` as they are.
struct Doc {
    json: Value,
    bin: Vec<u8>,
    more_buffers: Vec<Value>,
}

impl Doc {
    fn new() -> Doc {
        Doc {
            json: json!({"asset": {"version": "2.0", "generator": "subfield tests/gltf_spec.rs"}}),
            bin: Vec::new(),
            more_buffers: Vec::new(),
        }
    }

    /// Appends to a root array, returning the new element's index.
    fn push(&mut self, array: &str, value: Value) -> usize {
        let a = self.json[array].as_array_mut().map(std::mem::take);
        let mut a = a.unwrap_or_default();
        a.push(value);
        let i = a.len() - 1;
        self.json[array] = Value::Array(a);
        i
    }

    /// Appends bytes (4-aligned) as a buffer view of buffer 0.
    fn view(&mut self, bytes: &[u8], stride: Option<usize>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        let mut v = json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()});
        if let Some(s) = stride {
            v["byteStride"] = json!(s);
        }
        self.push("bufferViews", v)
    }

    /// A float accessor over a new buffer view (with min / max, which POSITION needs).
    fn floats(&mut self, values: &[f32], type_: &str) -> usize {
        let comps = match type_ {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => 16,
        };
        let bytes: Vec<u8> = values.iter().flat_map(|f| f.to_le_bytes()).collect();
        let view = self.view(&bytes, None);
        let (min, max) = min_max(values, comps);
        self.push(
            "accessors",
            json!({"bufferView": view, "componentType": 5126, "count": values.len() / comps,
                   "type": type_, "min": min, "max": max}),
        )
    }

    /// A u16 SCALAR index accessor.
    fn indices(&mut self, idx: &[u16]) -> usize {
        let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = self.view(&bytes, None);
        self.push(
            "accessors",
            json!({"bufferView": view, "componentType": 5123, "count": idx.len(), "type": "SCALAR"}),
        )
    }

    /// Sets a root property.
    fn set(&mut self, key: &str, value: Value) {
        self.json[key] = value;
    }

    /// Declares an extension used (and required when `required`).
    fn extension(&mut self, name: &str, required: bool) {
        self.push("extensionsUsed", json!(name));
        if required {
            self.push("extensionsRequired", json!(name));
        }
    }

    fn with_buffer(&self, uri: Option<String>) -> Value {
        let mut j = self.json.clone();
        let mut b = json!({"byteLength": self.bin.len()});
        if let Some(u) = uri {
            b["uri"] = json!(u);
        }
        let mut buffers = vec![b];
        buffers.extend(self.more_buffers.iter().cloned());
        j["buffers"] = Value::Array(buffers);
        j
    }

    /// `.gltf` bytes, the buffer as a base64 data URI.
    fn gltf(&self) -> Vec<u8> {
        let uri = format!("data:application/octet-stream;base64,{}", base64(&self.bin));
        serde_json::to_vec_pretty(&self.with_buffer(Some(uri))).unwrap()
    }

    /// `.glb` bytes, the buffer as the BIN chunk.
    fn glb(&self) -> Vec<u8> {
        let mut json = serde_json::to_vec(&self.with_buffer(None)).unwrap();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }
}

fn min_max(values: &[f32], comps: usize) -> (Vec<f32>, Vec<f32>) {
    let mut min = vec![f32::INFINITY; comps];
    let mut max = vec![f32::NEG_INFINITY; comps];
    for e in values.chunks_exact(comps) {
        for c in 0..comps {
            min[c] = min[c].min(e[c]);
            max[c] = max[c].max(e[c]);
        }
    }
    (min, max)
}

/// A square [-1, 1]² at z = 0 facing +z (two triangles), `uvs` per corner, a camera
/// at z = 3 looking at it, and a point light: the mesh is mesh 0, node 0; the camera
/// node is node 1.
fn quad(doc: &mut Doc, attrs: Value, material: Option<usize>) -> usize {
    let pos = doc.floats(
        &[-1., -1., 0., 1., -1., 0., 1., 1., 0., -1., 1., 0.],
        "VEC3",
    );
    let idx = doc.indices(&[0, 1, 2, 0, 2, 3]);
    let mut a = json!({"POSITION": pos});
    for (k, v) in attrs.as_object().into_iter().flatten() {
        a[k] = v.clone();
    }
    let mut prim = json!({"attributes": a, "indices": idx});
    if let Some(m) = material {
        prim["material"] = json!(m);
    }
    let mesh = doc.push("meshes", json!({"primitives": [prim]}));
    let node = doc.push("nodes", json!({"mesh": mesh}));
    let cam = doc.push(
        "cameras",
        json!({"type": "perspective", "perspective": {"yfov": 0.3, "znear": 0.1}}),
    );
    let cam_node = doc.push("nodes", json!({"camera": cam, "translation": [0, 0, 3]}));
    doc.set("scenes", json!([{"nodes": [node, cam_node]}]));
    doc.set("scene", json!(0));
    node
}

fn temp_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("gltf-spec-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes `bytes` as `dir/name` and imports it.
fn import_file(dir: &Path, name: &str, bytes: &[u8]) -> (PathBuf, Result<Scene, ImportError>) {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let r = import::load(&path);
    (path, r)
}

/// Validates `file` with the Khronos validator when it is installed: returns the
/// number of errors and the report, `None` (with `SKIPPED:`) when it is not.
fn validator_errors(file: &Path) -> Option<(u64, String)> {
    let ci = Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci");
    if !ci.join("node_modules/gltf-validator").is_dir() {
        eprintln!("SKIPPED: validator check of {}: the Khronos glTF validator is not installed (npm install --prefix .ci)", file.display());
        return None;
    }
    let out = Command::new("node")
        .arg(ci.join("gltf-validate.js"))
        .arg(file)
        .output()
        .ok()?;
    let line = String::from_utf8_lossy(&out.stdout).trim().to_string();
    let v: Value =
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("validator: {line:?}: {e}"));
    Some((v["errors"].as_u64().unwrap_or(u64::MAX), line))
}

/// A valid case: the validator (when installed) has no error to report.
fn assert_spec_valid(file: &Path) {
    if let Some((errors, report)) = validator_errors(file) {
        assert_eq!(
            errors,
            0,
            "the validator refuses {}: {report}",
            file.display()
        );
    }
}

fn subfield(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args(args)
        .output()
        .unwrap()
}

/// `subfield render FILE` of one small frame; returns the EXR written.
fn render_ok(file: &Path, extra: &[&str]) -> PathBuf {
    let out = file.with_extension("exr");
    let mut args = vec![
        "render",
        file.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--size",
        "16x16",
        "--spp",
        "1",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    let o = subfield(&args);
    assert!(
        o.status.success(),
        "render {} failed: {}",
        file.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.is_file());
    out
}

/// `subfield render FILE` must fail with one line naming the file and each of `parts`,
/// and write nothing.
fn render_refused(file: &Path, parts: &[&str]) {
    let dir = file.parent().unwrap().join("out");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("f.exr");
    let o = subfield(&[
        "render",
        file.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--size",
        "8x8",
        "--quiet",
    ]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        !o.status.success(),
        "render of {} succeeded",
        file.display()
    );
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "not one line: {err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(
        lines[0].contains(&file.display().to_string()),
        "no file in: {err}"
    );
    for p in parts {
        assert!(lines[0].contains(p), "{p:?} missing from: {err}");
    }
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        0,
        "something was written for {}",
        file.display()
    );
}

/// The centre pixel's RGB of an EXR.
fn centre_pixel(exr: &Path) -> Vec3 {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        exr,
        |res, _| (vec![Vec3::ZERO; res.width() * res.height()], res.width()),
        |(px, w), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = Vec3::new(r, g, b)
        },
    )
    .unwrap();
    let (px, w) = &image.layer_data.channel_data.pixels;
    let h = px.len() / w;
    px[(h / 2) * w + w / 2]
}

fn warned(scene: &Scene, parts: &[&str]) -> bool {
    scene
        .warnings
        .iter()
        .any(|w| parts.iter().all(|p| w.0.contains(p)))
}

/// A PNG of `w`×`h` RGBA pixels.
fn png(w: u32, h: u32, rgba: &[u8]) -> Vec<u8> {
    let img = image::RgbaImage::from_raw(w, h, rgba.to_vec()).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// A texture of two texels, red (left) and green (right), nearest-sampled and clamped.
fn red_green_texture(doc: &mut Doc) -> usize {
    let bytes = png(2, 1, &[255, 0, 0, 255, 0, 255, 0, 255]);
    let view = doc.view(&bytes, None);
    let img = doc.push(
        "images",
        json!({"bufferView": view, "mimeType": "image/png"}),
    );
    let s = doc.push(
        "samplers",
        json!({"magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071}),
    );
    doc.push("textures", json!({"source": img, "sampler": s}))
}

// ---------------------------------------------------------------------------------------
// Valid cases.

#[test]
fn accessor_without_buffer_view_is_zeros_plus_sparse() {
    let dir = temp_dir("sparse");
    let mut doc = Doc::new();
    // POSITION: no buffer view, its three vertices given by sparse storage; the morph
    // target: zeros but for vertex 2, moved by (0, 0, 1).
    let sparse_idx = doc.view(&[0, 1, 2, 0], None); // u8 indices 0, 1, 2 (padded)
    let tri = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.];
    let sparse_val = doc.view(
        &tri.iter()
            .flat_map(|f| f.to_le_bytes())
            .collect::<Vec<u8>>(),
        None,
    );
    let pos = doc.push(
        "accessors",
        json!({"componentType": 5126, "count": 3, "type": "VEC3",
               "min": [0, 0, 0], "max": [1, 1, 0],
               "sparse": {"count": 3,
                          "indices": {"bufferView": sparse_idx, "componentType": 5121},
                          "values": {"bufferView": sparse_val}}}),
    );
    let t_idx = doc.view(&[2, 0, 0, 0], None);
    let t_val = doc.view(
        &[0f32, 0., 1.]
            .iter()
            .flat_map(|f| f.to_le_bytes())
            .collect::<Vec<u8>>(),
        None,
    );
    let target = doc.push(
        "accessors",
        json!({"componentType": 5126, "count": 3, "type": "VEC3",
               "min": [0, 0, 0], "max": [0, 0, 1],
               "sparse": {"count": 1,
                          "indices": {"bufferView": t_idx, "componentType": 5121},
                          "values": {"bufferView": t_val}}}),
    );
    doc.set(
        "meshes",
        json!([{"primitives": [{"attributes": {"POSITION": pos},
                                "targets": [{"POSITION": target}]}],
                "weights": [0.5]}]),
    );
    doc.set("nodes", json!([{"mesh": 0}]));
    doc.set("scenes", json!([{"nodes": [0]}]));
    let (path, scene) = import_file(&dir, "sparse.gltf", &doc.gltf());
    let scene = scene.unwrap();
    let p = &scene.meshes[0].primitives[0];
    assert_eq!(
        p.positions,
        vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        "sparse POSITION"
    );
    assert_eq!(p.triangles, vec![[0, 1, 2]]);
    assert_eq!(
        p.morph_targets[0].positions,
        vec![Vec3::ZERO, Vec3::ZERO, Vec3::Z]
    );
    assert_eq!(scene.meshes[0].weights, vec![0.5]);
    assert_spec_valid(&path);
    render_ok(&path, &[]);
}

/// Float vectors stored interleaved (a byte stride, an accessor offset), as exporters
/// write vertex buffers, and many morph targets: each element read from its own place.
/// A non-finite value names the first bad target in the file's order, element and
/// component (the targets are decoded side by side).
#[test]
fn interleaved_floats_and_many_morph_targets() {
    let dir = temp_dir("interleaved");
    let pos = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let nrm = [Vec3::Z; 3];
    // One view, 24 bytes a vertex: position then normal.
    let mut bytes = Vec::new();
    for k in 0..3 {
        for f in pos[k].to_array().into_iter().chain(nrm[k].to_array()) {
            bytes.extend_from_slice(&f.to_le_bytes());
        }
    }
    let targets = 12;
    let make = |bad: Option<(usize, usize, usize)>| {
        let mut doc = Doc::new();
        let view = doc.view(&bytes, Some(24));
        let p = doc.push(
            "accessors",
            json!({"bufferView": view, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0]}),
        );
        let n = doc.push(
            "accessors",
            json!({"bufferView": view, "byteOffset": 12, "componentType": 5126, "count": 3,
                   "type": "VEC3"}),
        );
        // Target t moves vertex v by (t, v, t + v) / 16, 16 bytes a vertex (a pad).
        let mut list = Vec::new();
        for t in 0..targets {
            let mut tb = Vec::new();
            for v in 0..3 {
                let mut d = [t as f32 / 16.0, v as f32 / 16.0, (t + v) as f32 / 16.0];
                if let Some((bt, bv, bc)) = bad {
                    if (t, v) == (bt, bv) {
                        d[bc] = f32::NAN;
                    } else if t > bt {
                        d[0] = f32::INFINITY; // every later target bad too
                    }
                }
                for f in d.into_iter().chain([7.0]) {
                    tb.extend_from_slice(&f.to_le_bytes());
                }
            }
            let tv = doc.view(&tb, Some(16));
            let (t16, hi_z) = (t as f32 / 16.0, (t + 2) as f32 / 16.0);
            let (lo, hi) = ([t16, 0.0, t16], [t16, 2.0 / 16.0, hi_z]);
            let a = doc.push(
                "accessors",
                json!({"bufferView": tv, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": lo, "max": hi}),
            );
            list.push(json!({"POSITION": a}));
        }
        doc.set(
            "meshes",
            json!([{"primitives": [{"attributes": {"POSITION": p, "NORMAL": n},
                                    "targets": list}],
                    "weights": vec![0.0; targets]}]),
        );
        doc.set("nodes", json!([{"mesh": 0}]));
        doc.set("scenes", json!([{"nodes": [0]}]));
        doc
    };
    let (path, scene) = import_file(&dir, "interleaved.glb", &make(None).glb());
    let scene = scene.unwrap();
    let p = &scene.meshes[0].primitives[0];
    assert_eq!(p.positions, pos.to_vec());
    assert_eq!(p.normals.as_deref(), Some(&nrm[..]));
    assert_eq!(p.morph_targets.len(), targets);
    for (t, m) in p.morph_targets.iter().enumerate() {
        let want: Vec<Vec3> = (0..3)
            .map(|v| Vec3::new(t as f32, v as f32, (t + v) as f32) / 16.0)
            .collect();
        assert_eq!(m.positions, want, "target {t}");
    }
    assert_spec_valid(&path);
    render_ok(&path, &[]);

    let (_, bad) = import_file(&dir, "bad.glb", &make(Some((5, 2, 1))).glb());
    let e = bad.unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(e, ImportError::Accessor { accessor: 7, .. }),
        "{text}"
    );
    for part in ["targets[5].POSITION", "element 2 component 1", "not finite"] {
        assert!(text.contains(part), "{part:?} not in: {text}");
    }
}

#[test]
fn texture_without_source_takes_the_webp_image() {
    let dir = temp_dir("webp");
    let mut doc = Doc::new();
    doc.extension("EXT_texture_webp", true);
    // A lossless WebP of 2×1 pixels.
    let pixels = [10u8, 200, 30, 255, 250, 40, 5, 255];
    let img = image::RgbaImage::from_raw(2, 1, pixels.to_vec()).unwrap();
    let mut webp = std::io::Cursor::new(Vec::new());
    img.write_to(&mut webp, image::ImageFormat::WebP).unwrap();
    let view = doc.view(&webp.into_inner(), None);
    let image = doc.push(
        "images",
        json!({"bufferView": view, "mimeType": "image/webp", "name": "w"}),
    );
    let tex = doc.push(
        "textures",
        json!({"extensions": {"EXT_texture_webp": {"source": image}}}),
    );
    let mat = doc.push(
        "materials",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": tex}}}),
    );
    let uv = doc.floats(&[0., 1., 1., 1., 1., 0., 0., 0.], "VEC2");
    quad(&mut doc, json!({"TEXCOORD_0": uv}), Some(mat));
    let (path, scene) = import_file(&dir, "webp.glb", &doc.glb());
    let scene = scene.unwrap();
    assert_eq!(scene.images.len(), 1);
    assert_eq!((scene.images[0].width, scene.images[0].height), (2, 1));
    assert_eq!(
        scene.images[0].rgba8, pixels,
        "lossless WebP decoded exactly"
    );
    let r = scene.materials[0].base_color_texture.unwrap();
    assert_eq!(scene.textures[r.texture as usize].image, 0);
    assert_spec_valid(&path);
    render_ok(&path, &[]);
}

#[test]
fn texture_only_in_basisu_is_drawn_without_and_warned() {
    let dir = temp_dir("basisu");
    let mut doc = Doc::new();
    doc.extension("KHR_texture_basisu", false);
    let image = doc.push(
        "images",
        json!({"uri": "never-read.ktx2", "mimeType": "image/ktx2"}),
    );
    let tex = doc.push(
        "textures",
        json!({"extensions": {"KHR_texture_basisu": {"source": image}}}),
    );
    let mat = doc.push(
        "materials",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": tex},
                                        "baseColorFactor": [0.2, 0.4, 0.6, 1]}}),
    );
    quad(&mut doc, json!({}), Some(mat));
    let (path, scene) = import_file(&dir, "basisu.gltf", &doc.gltf());
    let scene = scene.unwrap();
    assert!(scene.materials[0].base_color_texture.is_none());
    assert_eq!(scene.materials[0].base_color.x, 0.2);
    assert!(scene.images.is_empty(), "the KTX2 image is never read");
    assert!(
        warned(&scene, &["textures[0]", "KHR_texture_basisu"]),
        "{:?}",
        scene.warnings
    );
    assert!(warned(&scene, &["KHR_texture_basisu", "not supported"]));
    // Not validated: the validator would read the (absent) KTX2 image.
    render_ok(&path, &[]);
}

#[test]
fn channels_without_a_node_through_animation_pointer() {
    let dir = temp_dir("pointer");
    let mut doc = Doc::new();
    doc.extension("KHR_animation_pointer", false);
    quad(&mut doc, json!({}), None);
    let times = doc.floats(&[0.0, 1.0], "SCALAR");
    let moves = doc.floats(&[0., 0., 0., 0., 2., 0.], "VEC3");
    let fovs = doc.floats(&[0.3, 0.6], "SCALAR");
    doc.set(
        "animations",
        json!([{"samplers": [{"input": times, "output": moves},
                             {"input": times, "output": fovs}],
                "channels": [
                    {"sampler": 0, "target": {"path": "pointer",
                        "extensions": {"KHR_animation_pointer": {"pointer": "/nodes/0/translation"}}}},
                    {"sampler": 1, "target": {"path": "pointer",
                        "extensions": {"KHR_animation_pointer": {"pointer": "/cameras/0/perspective/yfov"}}}},
                    {"sampler": 0, "target": {"path": "translation"}}
                ]}]),
    );
    let (path, scene) = import_file(&dir, "pointer.gltf", &doc.gltf());
    let scene = scene.unwrap();
    let a = &scene.animations[0];
    assert_eq!(a.channels.len(), 1, "only the node pointer is animated");
    let c = &a.channels[0];
    assert_eq!((c.node, c.property), (0, Property::Translation));
    assert_eq!(c.times, vec![0.0, 1.0]);
    assert_eq!(c.values, vec![0., 0., 0., 0., 2., 0.]);
    assert!(warned(
        &scene,
        &["channels[1]", "/cameras/0/perspective/yfov", "skipped"]
    ));
    assert!(warned(
        &scene,
        &["channels[2]", "without a node", "skipped"]
    ));
    assert_spec_valid(&path);
    render_ok(&path, &["--frames", "1"]);
}

#[test]
fn unknown_light_type_and_unknown_extensions_warn() {
    let dir = temp_dir("lights");
    let mut doc = Doc::new();
    doc.extension("KHR_lights_punctual", false);
    doc.extension("EXT_made_up_by_an_exporter", false);
    quad(&mut doc, json!({}), None);
    doc.set(
        "extensions",
        json!({"KHR_lights_punctual": {"lights": [
            {"type": "area", "name": "future"},
            {"type": "spot", "color": [1, 0.5, 0.25], "intensity": 30, "spot": {"outerConeAngle": 0.5}}
        ]}}),
    );
    doc.push(
        "nodes",
        json!({"extensions": {"KHR_lights_punctual": {"light": 0}}}),
    );
    doc.push(
        "nodes",
        json!({"translation": [0, 0, 2], "extensions": {"KHR_lights_punctual": {"light": 1}}}),
    );
    doc.json["scenes"][0]["nodes"] = json!([0, 1, 2, 3]);
    let (path, scene) = import_file(&dir, "lights.gltf", &doc.gltf());
    let scene = scene.unwrap();
    assert_eq!(scene.lights.len(), 1);
    assert!(matches!(
        scene.lights[0].kind,
        LightKind::Spot { outer_cone_angle, .. } if outer_cone_angle == 0.5
    ));
    // 30 candela: 30/683 W/sr in the model.
    assert_eq!(scene.lights[0].intensity, (30.0f64 / 683.0) as f32);
    assert_eq!(scene.nodes[2].light, None, "the area light is skipped");
    assert_eq!(scene.nodes[3].light, Some(0));
    assert!(warned(&scene, &["lights[0]", "\"area\"", "skipped"]));
    assert!(warned(&scene, &["EXT_made_up_by_an_exporter", "ignored"]));
    assert_spec_valid(&path);
    render_ok(&path, &[]);
}

#[test]
fn scene_without_nodes_unused_named_objects_and_extras() {
    let dir = temp_dir("extras");
    let mut doc = Doc::new();
    let node = quad(&mut doc, json!({}), None);
    let extras = json!({"author": "someone", "tags": [1, "two", {"three": null}]});
    doc.json["asset"]["extras"] = extras.clone();
    doc.json["nodes"][node]["extras"] = extras.clone();
    doc.json["meshes"][0]["extras"] = extras.clone();
    doc.json["meshes"][0]["primitives"][0]["extras"] = extras.clone();
    doc.json["accessors"][0]["extras"] = extras.clone();
    doc.json["bufferViews"][0]["extras"] = extras.clone();
    doc.json["cameras"][0]["extras"] = extras.clone();
    doc.json["extras"] = extras.clone();
    // Named, used by nothing.
    doc.push(
        "materials",
        json!({"name": "unused material", "extras": extras}),
    );
    doc.push("nodes", json!({"name": "unused node"}));
    let shown = doc.json["scenes"][0].clone();
    // The default scene is the second; the first has no nodes at all.
    doc.set(
        "scenes",
        json!([{"name": "empty", "extras": {"fps": 12}}, shown]),
    );
    doc.set("scene", json!(1));
    let (path, scene) = import_file(&dir, "extras.gltf", &doc.gltf());
    let scene = scene.unwrap();
    assert_eq!(scene.roots, vec![0, 1]);
    assert_eq!(scene.meshes[0].primitives[0].triangles.len(), 2);
    assert_eq!(scene.nodes[2].name.as_deref(), Some("unused node"));
    assert_eq!(scene.fps, Some(12.0), "fps from the first scene's extras");
    assert_spec_valid(&path);
    render_ok(&path, &[]);

    // And a file whose only scene is empty renders (nothing to see).
    doc.set("scenes", json!([{}]));
    doc.set("scene", json!(0));
    let (path, scene) = import_file(&dir, "empty.gltf", &doc.gltf());
    assert!(scene.unwrap().roots.is_empty());
    assert_spec_valid(&path);
}

#[test]
fn mesh_quantization_integer_attributes() {
    let dir = temp_dir("quant");
    let mut doc = Doc::new();
    doc.extension("KHR_mesh_quantization", true);
    // POSITION: u16, not normalised, stride 8 (the 4-byte alignment of vertex data).
    let pos: [[u16; 3]; 3] = [[0, 0, 0], [2, 0, 0], [0, 2, 0]];
    let mut bytes = Vec::new();
    for p in pos {
        for c in p {
            bytes.extend(c.to_le_bytes());
        }
        bytes.extend([0, 0]);
    }
    let v = doc.view(&bytes, Some(8));
    let a_pos = doc.push(
        "accessors",
        json!({"bufferView": v, "componentType": 5123, "count": 3, "type": "VEC3",
               "min": [0, 0, 0], "max": [2, 2, 0]}),
    );
    // NORMAL: i8 normalised, stride 4.
    let v = doc.view(&[0, 0, 127, 0, 0, 0, 127, 0, 0, 0, 127, 0], Some(4));
    let a_nrm = doc.push(
        "accessors",
        json!({"bufferView": v, "componentType": 5120, "normalized": true, "count": 3, "type": "VEC3"}),
    );
    // TEXCOORD_0: u16 normalised; TEXCOORD_1: u8 not normalised (stride 4).
    let uv0: [u16; 6] = [0, 0, 65535, 0, 0, 65535];
    let v = doc.view(
        &uv0.iter()
            .flat_map(|c| c.to_le_bytes())
            .collect::<Vec<u8>>(),
        Some(4),
    );
    let a_uv0 = doc.push(
        "accessors",
        json!({"bufferView": v, "componentType": 5123, "normalized": true, "count": 3, "type": "VEC2"}),
    );
    let v = doc.view(&[0, 0, 0, 0, 4, 0, 0, 0, 0, 2, 0, 0], Some(4));
    let a_uv1 = doc.push(
        "accessors",
        json!({"bufferView": v, "componentType": 5121, "count": 3, "type": "VEC2"}),
    );
    let tex = red_green_texture(&mut doc);
    let mat = doc.push(
        "materials",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": tex, "texCoord": 1,
            "extensions": {"KHR_texture_transform": {"scale": [0.25, 0.5]}}}}}),
    );
    doc.extension("KHR_texture_transform", false);
    doc.set(
        "meshes",
        json!([{"primitives": [{"attributes": {"POSITION": a_pos, "NORMAL": a_nrm,
            "TEXCOORD_0": a_uv0, "TEXCOORD_1": a_uv1}, "material": mat}]}]),
    );
    let cam = doc.push(
        "cameras",
        json!({"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}),
    );
    doc.set(
        "nodes",
        json!([{"mesh": 0, "scale": [0.5, 0.5, 0.5]},
               {"camera": cam, "translation": [0.3, 0.3, 2]}]),
    );
    doc.set("scenes", json!([{"nodes": [0, 1]}]));
    let (path, scene) = import_file(&dir, "quant.glb", &doc.glb());
    let scene = scene.unwrap();
    let p = &scene.meshes[0].primitives[0];
    assert_eq!(
        p.positions,
        vec![Vec3::ZERO, Vec3::new(2., 0., 0.), Vec3::new(0., 2., 0.)]
    );
    assert_eq!(p.normals.as_ref().unwrap(), &vec![Vec3::Z; 3]);
    // The material samples TEXCOORD_1 (plain integers under KHR_mesh_quantization).
    assert_eq!(
        p.uvs.as_ref().unwrap(),
        &vec![Vec2::ZERO, Vec2::new(4., 0.), Vec2::new(0., 2.)]
    );
    let r = scene.materials[0].base_color_texture.unwrap();
    assert_eq!(r.tex_coord, 1);
    let t = r.transform.unwrap();
    assert_eq!(t.apply(Vec2::new(4., 2.)), Vec2::new(1., 1.));
    assert_spec_valid(&path);
    render_ok(&path, &[]);
}

#[test]
fn texture_transform_follows_the_extension() {
    // The extension's worked example: offset [0, 1], rotation π/2, scale [0.5, 0.5] maps
    // the unit square onto the lower-left quadrant of the image.
    let t = UvTransform {
        offset: Vec2::new(0., 1.),
        rotation: std::f32::consts::FRAC_PI_2,
        scale: Vec2::splat(0.5),
    };
    for (uv, want) in [
        (Vec2::new(0., 0.), Vec2::new(0., 1.)),
        (Vec2::new(1., 0.), Vec2::new(0., 0.5)),
        (Vec2::new(0., 1.), Vec2::new(0.5, 1.)),
        (Vec2::new(1., 1.), Vec2::new(0.5, 0.5)),
    ] {
        assert!(
            (t.apply(uv) - want).length() < 1e-6,
            "{uv} → {}",
            t.apply(uv)
        );
    }

    // Rendered: a quad whose uvs all sit on the red texel (u = 0.25); the transform's
    // offset moves them onto the green one, its texCoord override picks TEXCOORD_1.
    // Emissive only (base colour black), strength 4: the pixel is the texel × 4.
    let dir = temp_dir("transform");
    let render = |offset: f32, strength: f32, name: &str| -> Vec3 {
        let mut doc = Doc::new();
        doc.extension("KHR_texture_transform", true);
        doc.extension("KHR_materials_emissive_strength", false);
        let tex = red_green_texture(&mut doc);
        let mat = doc.push(
            "materials",
            json!({"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
                   "emissiveFactor": [1, 1, 1],
                   "emissiveTexture": {"index": tex, "texCoord": 0, "extensions": {
                       "KHR_texture_transform": {"offset": [offset, 0], "texCoord": 1}}},
                   "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}}),
        );
        let uv0 = doc.floats(&[0.75; 8], "VEC2");
        let uv1 = doc.floats(&[0.25, 0.5, 0.25, 0.5, 0.25, 0.5, 0.25, 0.5], "VEC2");
        quad(
            &mut doc,
            json!({"TEXCOORD_0": uv0, "TEXCOORD_1": uv1}),
            Some(mat),
        );
        let (path, scene) = import_file(&dir, name, &doc.gltf());
        let scene = scene.unwrap();
        assert_eq!(scene.materials[0].emissive_strength, strength);
        let r = scene.materials[0].emissive_texture.unwrap();
        assert_eq!(r.tex_coord, 1, "KHR_texture_transform's texCoord override");
        assert_eq!(
            scene.meshes[0].primitives[0].uvs.as_ref().unwrap()[0],
            Vec2::new(0.25, 0.5)
        );
        assert_spec_valid(&path);
        centre_pixel(&render_ok(&path, &[]))
    };
    let plain = render(0.0, 1.0, "red.gltf");
    let moved = render(0.5, 1.0, "green.gltf");
    let strong = render(0.5, 4.0, "green4.gltf");
    assert!(
        plain.x > 0.5 && plain.y < 0.1,
        "untransformed: red, got {plain}"
    );
    assert!(
        moved.y > 0.5 && moved.x < 0.1,
        "offset 0.5: green, got {moved}"
    );
    assert!(
        (strong.y / moved.y - 4.0).abs() < 0.05,
        "emissive strength 4: {strong} vs {moved}"
    );
}

// ---------------------------------------------------------------------------------------
// Refused: one line naming the file and the extension, accessor or node; nothing written.

#[test]
fn required_extensions_we_do_not_decode_are_one_line() {
    let dir = temp_dir("required");
    for (ext, hint) in [
        ("KHR_draco_mesh_compression", "without Draco"),
        ("KHR_texture_basisu", "PNG"),
        ("EXT_lights_image_based", "not supported"),
    ] {
        let mut doc = Doc::new();
        quad(&mut doc, json!({}), None);
        doc.extension(ext, true);
        let (path, r) = import_file(&dir, &format!("{ext}.gltf"), &doc.gltf());
        let e = r.unwrap_err();
        assert!(matches!(e, ImportError::Unsupported { .. }), "{e}");
        let m = e.to_string();
        assert!(m.contains(ext) && m.contains(hint), "{m}");
        render_refused(&path, &[ext, hint]);
    }
}

#[test]
fn structural_errors_name_the_object() {
    let dir = temp_dir("invalid");
    type Breaker = fn(&mut Value);
    let cases: [(&str, Breaker, &[&str]); 7] = [
        (
            "version",
            |j| j["asset"]["version"] = json!("1.0"),
            &["asset.version", "only glTF 2.x"],
        ),
        (
            "source",
            |j| j["textures"] = json!([{"source": 5}]),
            &["textures[0].source", "index 5 out of range"],
        ),
        (
            "count",
            |j| {
                j["accessors"][0].as_object_mut().unwrap().remove("count");
            },
            &["accessors[0].count", "required"],
        ),
        (
            "component",
            |j| j["accessors"][1]["componentType"] = json!(5124),
            &["accessors[1].componentType", "5124"],
        ),
        (
            "child",
            |j| j["nodes"][0]["children"] = json!([7]),
            &["nodes[0].children[0]", "index 7"],
        ),
        (
            "light",
            |j| j["nodes"][0]["extensions"] = json!({"KHR_lights_punctual": {"light": 0}}),
            &[
                "nodes[0].extensions.KHR_lights_punctual.light",
                "out of range",
            ],
        ),
        (
            "sampler",
            |j| j["animations"] = json!([{"samplers": [], "channels": [{"sampler": 0, "target": {"node": 0, "path": "scale"}}]}]),
            &["animations[0].channels[0].sampler", "out of range"],
        ),
    ];
    for (name, breaker, parts) in cases {
        let mut doc = Doc::new();
        quad(&mut doc, json!({}), None);
        breaker(&mut doc.json);
        let (path, r) = import_file(&dir, &format!("{name}.gltf"), &doc.gltf());
        let e = r.unwrap_err();
        assert!(matches!(e, ImportError::Invalid { .. }), "{name}: {e}");
        let m = e.to_string();
        for p in parts {
            assert!(m.contains(p), "{name}: {p:?} missing from {m}");
        }
        if let Some((errors, report)) = validator_errors(&path) {
            assert!(errors > 0, "{name}: the validator accepts it: {report}");
        }
        render_refused(&path, parts);
    }
}

#[test]
fn bad_data_behind_valid_structure_names_the_accessor() {
    let dir = temp_dir("data");
    // A sparse index past the accessor's count.
    let mut doc = Doc::new();
    let idx = doc.view(&[0, 0, 9, 0], None);
    let val = doc.view(&[0u8; 12], None);
    let pos = doc.push(
        "accessors",
        json!({"componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [0,0,0],
               "sparse": {"count": 1, "indices": {"bufferView": idx, "byteOffset": 2, "componentType": 5121},
                          "values": {"bufferView": val}}}),
    );
    doc.set(
        "meshes",
        json!([{"primitives": [{"attributes": {"POSITION": pos}}]}]),
    );
    doc.set("nodes", json!([{"mesh": 0}]));
    let (path, r) = import_file(&dir, "sparse-index.gltf", &doc.gltf());
    let e = r.unwrap_err();
    assert!(
        matches!(e, ImportError::Accessor { accessor: 0, .. }),
        "{e}"
    );
    render_refused(&path, &["accessors[0]", "POSITION", "sparse index 9"]);

    // A pointer to a node that does not exist.
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    let t = doc.floats(&[0., 1.], "SCALAR");
    let v = doc.floats(&[0., 0., 0., 1., 1., 1.], "VEC3");
    doc.set(
        "animations",
        json!([{"samplers": [{"input": t, "output": v}], "channels": [{"sampler": 0,
            "target": {"path": "pointer", "extensions": {"KHR_animation_pointer": {"pointer": "/nodes/9/scale"}}}}]}]),
    );
    let (path, r) = import_file(&dir, "pointer.gltf", &doc.gltf());
    let e = r.unwrap_err();
    assert!(
        matches!(e, ImportError::Animation { channel: 0, .. }),
        "{e}"
    );
    render_refused(&path, &["animations[0].channels[0]", "node 9"]);

    // A remote buffer stays refused.
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    let j = doc.with_buffer(Some("https://example.com/scene.bin".into()));
    let (path, r) = import_file(&dir, "remote.gltf", &serde_json::to_vec(&j).unwrap());
    let e = r.unwrap_err();
    assert!(matches!(e, ImportError::UriOutsideFolder { .. }), "{e}");
    render_refused(&path, &["buffers[0]", "https://example.com/scene.bin"]);
}

// ---------------------------------------------------------------------------------------
// Issue 41: the last kinds of file the specification (and the validator) allows that we
// refused. Each valid file is checked with the validator and rendered; what the scene
// does read must still be right, and what is really wrong is still one error line.

/// `subfield render FILE` (not quiet) succeeds and prints exactly one warning line
/// holding every one of `parts`.
fn render_warned(file: &Path, parts: &[&str]) {
    let out = file.with_extension("exr");
    let o = subfield(&[
        "render",
        file.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--size",
        "16x16",
        "--spp",
        "1",
    ]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "render {}: {err}", file.display());
    assert!(out.is_file());
    let hits = err
        .lines()
        .filter(|l| l.starts_with("warning: ") && parts.iter().all(|p| l.contains(p)))
        .count();
    assert_eq!(hits, 1, "one warning with {parts:?} expected in: {err}");
}

#[test]
fn issue41_buffer_without_data_that_nothing_reads() {
    let dir = temp_dir("issue41-buffer");
    for (name, glb) in [("unused.gltf", false), ("unused.glb", true)] {
        let mut doc = Doc::new();
        // Buffer 1: no URI, not the GLB's chunk; a view on it that nothing reads.
        doc.more_buffers.push(json!({"byteLength": 48}));
        doc.push("bufferViews", json!({"buffer": 1, "byteLength": 48}));
        quad(&mut doc, json!({}), None);
        let bytes = if glb { doc.glb() } else { doc.gltf() };
        let (path, scene) = import_file(&dir, name, &bytes);
        let scene = scene.unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(scene.meshes[0].primitives[0].triangles.len(), 2);
        assert_spec_valid(&path);
        render_ok(&path, &[]);
    }
    // Read, it is one error naming the accessor, the view and the buffer.
    for (name, glb) in [("read.gltf", false), ("read.glb", true)] {
        let mut doc = Doc::new();
        doc.more_buffers.push(json!({"byteLength": 48}));
        let view = doc.push("bufferViews", json!({"buffer": 1, "byteLength": 48}));
        let normals = doc.push(
            "accessors",
            json!({"bufferView": view, "componentType": 5126, "count": 4, "type": "VEC3"}),
        );
        quad(&mut doc, json!({"NORMAL": normals}), None);
        let bytes = if glb { doc.glb() } else { doc.gltf() };
        let (path, r) = import_file(&dir, name, &bytes);
        let e = r.unwrap_err();
        assert!(
            matches!(e, ImportError::Accessor { accessor, .. } if accessor == normals),
            "{name}: {e}"
        );
        render_refused(
            &path,
            &[
                &format!("accessors[{normals}]"),
                "NORMAL",
                &format!("bufferViews[{view}]"),
                "buffers[1] has no data",
            ],
        );
    }
    // A .gltf whose buffer 0 has no URI (there is no binary chunk to stand for it).
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    let j = doc.with_buffer(None);
    let (path, r) = import_file(&dir, "chunkless.gltf", &serde_json::to_vec(&j).unwrap());
    let e = r.unwrap_err();
    assert!(
        matches!(e, ImportError::Accessor { accessor: 0, .. }),
        "{e}"
    );
    render_refused(
        &path,
        &[
            "accessors[0]",
            "POSITION",
            "bufferViews[0]",
            "buffers[0] has no data",
            "no GLB binary chunk",
        ],
    );
}

/// Every integer in `v` written as a float of the same value (`3` → `3.0`).
fn integers_as_floats(v: &mut Value) {
    match v {
        Value::Number(n) if !n.is_f64() => *v = json!(n.as_f64().unwrap()),
        Value::Array(a) => a.iter_mut().for_each(integers_as_floats),
        Value::Object(o) => o.values_mut().for_each(integers_as_floats),
        _ => {}
    }
}

#[test]
fn issue41_integers_written_as_whole_floats() {
    let dir = temp_dir("issue41-floats");
    // Indices, counts, offsets, lengths, component types, a mode, a texCoord, sampler
    // enumerations, attribute and node indices, the default scene.
    let mut doc = Doc::new();
    let tex = red_green_texture(&mut doc);
    let mat = doc.push(
        "materials",
        json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": tex, "texCoord": 0}}}),
    );
    let uv = doc.floats(&[0.25, 0.5, 0.75, 0.5, 0.75, 0.5, 0.25, 0.5], "VEC2");
    quad(&mut doc, json!({"TEXCOORD_0": uv}), Some(mat));
    doc.json["meshes"][0]["primitives"][0]["mode"] = json!(4);
    let (_, ints) = import_file(&dir, "ints.gltf", &doc.gltf());
    let ints = ints.unwrap();

    let mut j: Value = serde_json::from_slice(&doc.gltf()).unwrap();
    integers_as_floats(&mut j);
    // `-0.0` and `4e0` are whole-valued floats too.
    j["scene"] = json!("SCENE");
    j["meshes"][0]["primitives"][0]["mode"] = json!("MODE");
    let text = serde_json::to_string_pretty(&j)
        .unwrap()
        .replace("\"SCENE\"", "-0.0")
        .replace("\"MODE\"", "4e0");
    assert!(text.contains("\"count\": 4.0") && text.contains("\"wrapS\": 33071.0"));
    let (path, floats) = import_file(&dir, "floats.gltf", text.as_bytes());
    let floats = floats.unwrap_or_else(|e| panic!("{e}"));
    let model = |s: &Scene| {
        format!(
            "{:?}",
            Scene {
                source: PathBuf::new(),
                ..s.clone()
            }
        )
    };
    assert_eq!(model(&floats), model(&ints), "the same scene read");
    assert_spec_valid(&path);
    render_ok(&path, &[]);

    // A fraction, a negative number or one past the type's range stays an error naming
    // the property (and the validator refuses them too).
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    for (name, at, bad, parts) in [
        (
            "fraction",
            "/accessors/0/count",
            json!(1.5),
            ["accessors[0].count", "1.5"],
        ),
        (
            "negative",
            "/bufferViews/1/byteOffset",
            json!(-4),
            ["bufferViews[1].byteOffset", "-4"],
        ),
        (
            "past-u32",
            "/accessors/1/componentType",
            json!(4294967296.0),
            ["accessors[1].componentType", "4294967296"],
        ),
        (
            "index",
            "/meshes/0/primitives/0/attributes/POSITION",
            json!(0.5),
            ["meshes[0].primitives[0].attributes.POSITION", "0.5"],
        ),
    ] {
        let mut j = doc.with_buffer(Some(format!(
            "data:application/octet-stream;base64,{}",
            base64(&doc.bin)
        )));
        *j.pointer_mut(at).unwrap() = bad;
        let (path, r) = import_file(
            &dir,
            &format!("{name}.gltf"),
            &serde_json::to_vec_pretty(&j).unwrap(),
        );
        let e = r.unwrap_err();
        assert!(matches!(e, ImportError::Json { .. }), "{name}: {e}");
        if let Some((errors, report)) = validator_errors(&path) {
            assert!(errors > 0, "{name}: the validator accepts it: {report}");
        }
        render_refused(&path, &parts);
    }
}

#[test]
fn issue41_primitive_without_position_is_skipped_warned() {
    let dir = temp_dir("issue41-position");
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    // A primitive with only normals in front of the quad's, in a named mesh, and a
    // second mesh (on a node of its own) with nothing else.
    let normals = doc.floats(&[0., 0., 1., 0., 0., 1., 0., 0., 1.], "VEC3");
    doc.json["meshes"][0]["name"] = json!("wing");
    let bare = json!({"attributes": {"NORMAL": normals}});
    doc.json["meshes"][0]["primitives"]
        .as_array_mut()
        .unwrap()
        .insert(0, bare.clone());
    let mesh = doc.push("meshes", json!({"primitives": [bare]}));
    let node = doc.push("nodes", json!({"mesh": mesh}));
    doc.json["scenes"][0]["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!(node));
    let (path, scene) = import_file(&dir, "some.gltf", &doc.gltf());
    let scene = scene.unwrap();
    assert_eq!(scene.meshes[0].primitives.len(), 1);
    assert_eq!(scene.meshes[0].primitives[0].triangles.len(), 2);
    assert!(scene.meshes[1].primitives.is_empty());
    let skipped = [
        "without POSITION",
        "meshes[0] (\"wing\").primitives[0]",
        "meshes[1].primitives[0]",
    ];
    assert!(warned(&scene, &skipped), "{:?}", scene.warnings);
    assert_eq!(
        scene
            .warnings
            .iter()
            .filter(|w| w.0.contains("POSITION"))
            .count(),
        1,
        "one warning: {:?}",
        scene.warnings
    );
    assert!(!warned(&scene, &["background alone"]));
    assert_spec_valid(&path);
    render_warned(&path, &skipped);

    // Every primitive without: nothing to trace, said in the same warning; the frames
    // show the background.
    doc.json["meshes"][0]["primitives"] = json!([bare]);
    let (path, scene) = import_file(&dir, "none.gltf", &doc.gltf());
    let scene = scene.unwrap();
    assert!(scene.meshes.iter().all(|m| m.primitives.is_empty()));
    let nothing = [
        "without POSITION",
        "meshes[1].primitives[0]",
        "background alone",
    ];
    assert!(warned(&scene, &nothing), "{:?}", scene.warnings);
    assert_spec_valid(&path);
    render_warned(&path, &nothing);
}

#[test]
fn issue41_unknown_accessor_type_nothing_reads() {
    let dir = temp_dir("issue41-type");
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    // A type a later glTF might define, on an accessor of zeros nothing reads.
    let odd = doc.push(
        "accessors",
        json!({"componentType": 5126, "count": 2, "type": "MAT5"}),
    );
    let (path, scene) = import_file(&dir, "unread.gltf", &doc.gltf());
    assert_eq!(scene.unwrap().meshes[0].primitives[0].triangles.len(), 2);
    assert_spec_valid(&path);
    render_ok(&path, &[]);

    // Read (as an animation's output), it is one error naming the accessor and the type.
    let times = doc.floats(&[0., 1.], "SCALAR");
    doc.set(
        "animations",
        json!([{"samplers": [{"input": times, "output": odd}],
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "scale"}}]}]),
    );
    let (path, r) = import_file(&dir, "read.gltf", &doc.gltf());
    let e = r.unwrap_err();
    assert!(
        matches!(e, ImportError::Accessor { accessor, .. } if accessor == odd),
        "{e}"
    );
    render_refused(
        &path,
        &[&format!("accessors[{odd}]"), "\"MAT5\"", "animations[0]"],
    );
}

#[test]
fn issue41_what_stays_refused_on_purpose() {
    let dir = temp_dir("issue41-refused");
    // A file that asks for a reader of glTF 2.1: the validator accepts it (a 2.x
    // document), but a 2.0 reader must not read it.
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    doc.json["asset"]["version"] = json!("2.1");
    doc.json["asset"]["minVersion"] = json!("2.1");
    let (path, r) = import_file(&dir, "min-version.gltf", &doc.gltf());
    let e = r.unwrap_err();
    assert!(matches!(e, ImportError::Invalid { .. }), "{e}");
    assert_spec_valid(&path);
    render_refused(&path, &["asset.minVersion", "\"2.1\"", "only glTF 2.0"]);

    // A buffer by http:// URI: never fetched.
    let mut doc = Doc::new();
    quad(&mut doc, json!({}), None);
    let j = doc.with_buffer(Some("http://example.com/scene.bin".into()));
    let (path, r) = import_file(&dir, "http.gltf", &serde_json::to_vec(&j).unwrap());
    let e = r.unwrap_err();
    assert!(matches!(e, ImportError::UriOutsideFolder { .. }), "{e}");
    render_refused(&path, &["buffers[0]", "http://example.com/scene.bin"]);
}
