//! `EXT_meshopt_compression` / `KHR_meshopt_compression` (issue 25): files written here
//! the way gltfpack writes them (compressed bytes in buffer 0, the views on a `fallback`
//! buffer that has no data at all), the data encoded with meshoptimizer's own encoders
//! (the `meshopt` crate), the extension required. The import must give back the
//! positions bit for bit and the triangles with their winding (the index codec may
//! rotate a triangle's corners, never reorder triangles or flip them); a corrupted or
//! malformed compressed view is one error line naming the file and `bufferViews[i]`.

mod common;

use common::base64;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{json, Value};
use subfield::import::{self, ImportError};

/// A 6 x 5 grid of vertices with irregular heights, and its triangles.
fn grid() -> (Vec<[f32; 3]>, Vec<u32>) {
    let (w, h) = (6u32, 5u32);
    let mut pos = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let z = ((x * 7 + y * 13) % 11) as f32 * 0.037 - 0.1;
            pos.push([x as f32 * 0.25 - 0.6, y as f32 * 0.3 - 0.55, z]);
        }
    }
    let mut idx = Vec::new();
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            let a = y * w + x;
            idx.extend_from_slice(&[a, a + 1, a + w + 1, a, a + w + 1, a + w]);
        }
    }
    (pos, idx)
}

/// A triangle with its smallest index first, winding kept.
fn canonical(t: [u32; 3]) -> [u32; 3] {
    let r = (0..3).min_by_key(|&i| t[i]).unwrap_or(0);
    [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
}

/// How the index data is compressed.
#[derive(Clone, Copy)]
enum Indices {
    /// `TRIANGLES`, 2-byte indices.
    Triangles16,
    /// `INDICES` (index sequence), 4-byte indices.
    Sequence32,
}

/// The compressed document: returns the JSON and the compressed buffer's bytes, and the
/// index of the index buffer view.
fn compressed_doc(ext: &str, pos: &[[f32; 3]], idx: &[u32], indices: Indices) -> (Value, Vec<u8>) {
    let vertex_data = meshopt::encode_vertex_buffer(pos).unwrap();
    let (index_data, mode, stride, component) = match indices {
        Indices::Triangles16 => (
            meshopt::encode_index_buffer(idx, pos.len()).unwrap(),
            "TRIANGLES",
            2,
            5123,
        ),
        Indices::Sequence32 => (
            meshopt::encode_index_sequence(idx, pos.len()).unwrap(),
            "INDICES",
            4,
            5125,
        ),
    };
    let mut bin = vertex_data.clone();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let index_offset = bin.len();
    bin.extend_from_slice(&index_data);
    let (mut min, mut max) = ([f32::MAX; 3], [f32::MIN; 3]);
    for p in pos {
        for c in 0..3 {
            min[c] = min[c].min(p[c]);
            max[c] = max[c].max(p[c]);
        }
    }
    let pos_len = pos.len() * 12;
    let idx_len = idx.len() * stride;
    let json = json!({
        "asset": {"version": "2.0", "generator": "subfield tests/gltf_meshopt.rs"},
        "extensionsUsed": [ext],
        "extensionsRequired": [ext],
        "buffers": [
            {"byteLength": bin.len(),
             "uri": format!("data:application/octet-stream;base64,{}", base64(&bin))},
            {"byteLength": pos_len + idx_len, "extensions": {ext: {"fallback": true}}},
        ],
        "bufferViews": [
            {"buffer": 1, "byteOffset": 0, "byteLength": pos_len, "byteStride": 12,
             "extensions": {ext: {"buffer": 0, "byteOffset": 0,
                 "byteLength": vertex_data.len(), "byteStride": 12, "count": pos.len(),
                 "mode": "ATTRIBUTES"}}},
            {"buffer": 1, "byteOffset": pos_len, "byteLength": idx_len,
             "extensions": {ext: {"buffer": 0, "byteOffset": index_offset,
                 "byteLength": index_data.len(), "byteStride": stride, "count": idx.len(),
                 "mode": mode, "filter": "NONE"}}},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": pos.len(), "type": "VEC3",
             "min": min, "max": max},
            {"bufferView": 1, "componentType": component, "count": idx.len(),
             "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0},
                  {"camera": 0, "translation": [0, 0, 3]}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.6, "znear": 0.1}}],
        "scenes": [{"nodes": [0, 1]}],
        "scene": 0,
    });
    (json, bin)
}

fn temp_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("gltf-meshopt-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(dir: &Path, name: &str, json: &Value) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec_pretty(json).unwrap()).unwrap();
    path
}

/// Replaces buffer 0 with `bin`.
fn set_bin(json: &mut Value, bin: &[u8]) {
    json["buffers"][0]["byteLength"] = json!(bin.len());
    json["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64(bin)
    ));
}

/// `subfield render FILE` must fail with one line naming the file and each of `parts`.
fn render_refused(file: &Path, parts: &[&str]) {
    let out = file.with_extension("exr");
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args([
            "render",
            file.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
        .args(["--size", "8x8", "--quiet"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        !o.status.success(),
        "render of {} succeeded",
        file.display()
    );
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "not one line: {err}");
    assert!(lines[0].contains(&file.display().to_string()), "{err}");
    for p in parts {
        assert!(lines[0].contains(p), "{p:?} missing from: {err}");
    }
    assert!(!out.exists(), "{} was written", out.display());
}

#[test]
fn compressed_positions_and_triangles_decode_exactly() {
    let dir = temp_dir("exact");
    let (pos, idx) = grid();
    let want: Vec<[u32; 3]> = idx
        .chunks(3)
        .map(|t| canonical([t[0], t[1], t[2]]))
        .collect();
    for ext in ["EXT_meshopt_compression", "KHR_meshopt_compression"] {
        for indices in [Indices::Triangles16, Indices::Sequence32] {
            let (json, _) = compressed_doc(ext, &pos, &idx, indices);
            let path = write(&dir, &format!("{ext}.gltf"), &json);
            let scene = import::load(&path).unwrap_or_else(|e| panic!("{ext}: {e}"));
            let prim = &scene.meshes[0].primitives[0];
            let got: Vec<[f32; 3]> = prim.positions.iter().map(|p| p.to_array()).collect();
            assert_eq!(
                got.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>(),
                pos.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>(),
                "{ext}: positions"
            );
            let tris: Vec<[u32; 3]> = prim.triangles.iter().map(|&t| canonical(t)).collect();
            assert_eq!(tris, want, "{ext}: triangles");
            if matches!(indices, Indices::Sequence32) {
                // The index sequence codec keeps every index where it was.
                let flat: Vec<u32> = prim.triangles.iter().flatten().copied().collect();
                assert_eq!(flat, idx, "{ext}: INDICES order");
            }
            assert!(
                !scene.warnings.iter().any(|w| w.0.contains("meshopt")),
                "{ext}: {:?}",
                scene.warnings
            );
        }
    }
}

#[test]
fn corrupted_compressed_data_is_one_line_naming_the_view() {
    let dir = temp_dir("corrupt");
    let (pos, idx) = grid();
    let (json, bin) = compressed_doc("EXT_meshopt_compression", &pos, &idx, Indices::Triangles16);
    // The vertex stream's header byte says which codec version wrote it: an unknown one
    // does not decode.
    let mut bad_header = bin.clone();
    bad_header[0] = 0x00;
    let mut j = json.clone();
    set_bin(&mut j, &bad_header);
    let path = write(&dir, "header.gltf", &j);
    let e = import::load(&path).unwrap_err();
    assert!(matches!(e, ImportError::BufferView { view: 0, .. }), "{e}");
    let m = e.to_string();
    assert!(!m.contains('\n'), "{m}");
    assert!(
        m.contains("bufferViews[0]") && m.contains("does not decode"),
        "{m}"
    );
    render_refused(
        &path,
        &["bufferViews[0]", "does not decode", "unknown header"],
    );

    // The index stream cut short: the decoder runs out of data.
    let mut j = json.clone();
    let cut = j["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["byteLength"]
        .as_u64()
        .unwrap()
        / 2;
    j["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["byteLength"] = json!(cut);
    let path = write(&dir, "short.gltf", &j);
    let e = import::load(&path).unwrap_err();
    assert!(matches!(e, ImportError::BufferView { view: 1, .. }), "{e}");
    render_refused(
        &path,
        &[
            "bufferViews[1]",
            "TRIANGLES",
            "does not decode",
            "too short",
        ],
    );
}

#[test]
fn malformed_extension_objects_name_the_property() {
    let dir = temp_dir("malformed");
    let (pos, idx) = grid();
    let (json, _) = compressed_doc("EXT_meshopt_compression", &pos, &idx, Indices::Triangles16);
    let ext = "EXT_meshopt_compression";
    type Breaker = fn(&mut Value);
    let cases: [(&str, Breaker, &[&str]); 5] = [
        (
            "stride",
            |j| {
                j["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["byteStride"] =
                    json!(6)
            },
            &["bufferViews[0]", "byteStride", "multiple of 4"],
        ),
        (
            "mode",
            |j| {
                j["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["mode"] =
                    json!("STRIPS")
            },
            &["bufferViews[1]", "mode", "STRIPS"],
        ),
        (
            "filter",
            |j| {
                j["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["filter"] =
                    json!("OCTAHEDRAL")
            },
            &[
                "bufferViews[1]",
                "filter",
                "OCTAHEDRAL does not apply to TRIANGLES",
            ],
        ),
        (
            "count",
            |j| j["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = json!(7),
            &["bufferViews[0]", "byteLength is 360"],
        ),
        (
            "outside",
            |j| {
                j["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["byteOffset"] =
                    json!(1 << 20)
            },
            &["bufferViews[0]", "outside buffers[0]"],
        ),
    ];
    for (name, breaker, parts) in cases {
        let mut j = json.clone();
        breaker(&mut j);
        let path = write(&dir, &format!("{name}.gltf"), &j);
        let e = import::load(&path).unwrap_err();
        let m = e.to_string();
        assert!(m.contains(&path.display().to_string()), "{name}: {m}");
        for p in parts {
            assert!(m.contains(p), "{name}: {p:?} missing from {m}");
        }
        assert!(
            m.contains(ext) || name == "count" || name == "outside",
            "{m}"
        );
    }
}

#[test]
fn compressed_scene_renders() {
    let dir = temp_dir("render");
    let (pos, idx) = grid();
    let (json, _) = compressed_doc("KHR_meshopt_compression", &pos, &idx, Indices::Triangles16);
    let path = write(&dir, "grid.gltf", &json);
    let out = dir.join("grid.exr");
    let o = Command::new(env!("CARGO_BIN_EXE_subfield"))
        .args([
            "render",
            path.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
        .args(["--size", "8x8", "--spp", "1", "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.is_file());
}
