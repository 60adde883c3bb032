//! Test helpers shared by the integration tests: where the third-party scenes are (and
//! what a test does when they are not), and an independent reader of raw glTF
//! numbers (JSON + bytes, written separately from the library's importer) used to work
//! out expected values without calling the code under test.
#![allow(dead_code)]

pub mod build;
pub mod exr_read;
pub mod farm;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod motion;
pub mod render_scene;
pub mod reseal;

use std::path::{Path, PathBuf};

use glam::{Mat4, Quat, Vec3};
use serde_json::Value;

/// The root of the third-party files: `$SUBFIELD_SHARED` when set, else `../shared`
/// beside the crate (where `.ci/run` expects it). Setting `SUBFIELD_SHARED=/nonexistent`
/// shows what the tests do without it.
pub fn shared_root() -> PathBuf {
    match std::env::var_os("SUBFIELD_SHARED") {
        Some(root) => PathBuf::from(root),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared"),
    }
}

/// `scenes/REL` under [`shared_root`] (a file or a folder) when it is there.
///
/// When it is not, a test cannot check what it is for, so it must not pass quietly:
/// under CI (the variable `CI` set, as `.ci/run` and CI services do) this panics; on a
/// developer's machine it writes `SKIPPED: <test>: <reason>` to the real stderr (which
/// `cargo test` shows, unlike a test's own captured output) and returns `None`, and the
/// test returns early.
#[track_caller]
pub fn shared_scene(rel: impl AsRef<Path>) -> Option<PathBuf> {
    let rel = Path::new("scenes").join(rel);
    let path = shared_root().join(&rel);
    if path.exists() {
        return Some(path);
    }
    let shown = match std::env::var_os("SUBFIELD_SHARED") {
        Some(_) => path.display().to_string(),
        None => Path::new("../shared").join(&rel).display().to_string(),
    };
    if std::env::var_os("CI").is_some() {
        panic!(
            "{shown} missing: CI must have ../shared beside the clone \
             (the third-party scenes; or SUBFIELD_SHARED naming it)"
        );
    }
    let caller = std::panic::Location::caller();
    let thread = std::thread::current();
    let test = match thread.name() {
        Some(name) if name != "main" => name.to_string(),
        _ => format!("{}:{}", caller.file(), caller.line()),
    };
    // Straight to stderr: `eprintln!` inside a passing test is captured and dropped.
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "SKIPPED: {test}: {shown} missing (third-party scenes; see docs/TESTING.md)"
    );
    None
}

/// Validates `file` with the Khronos glTF validator (`.ci/node_modules/gltf-validator`,
/// installed by `.ci/run` or `npm install --prefix .ci`); returns (errors, warnings, the
/// report line). A missing validator fails the test, naming the install command: a file
/// that is never validated must not pass silently.
pub fn khronos_validate(file: &Path) -> (u64, u64, String) {
    let ci = Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci");
    assert!(
        ci.join("node_modules/gltf-validator").is_dir(),
        "the Khronos glTF validator is not installed: run `npm install --prefix .ci` \
         (or .ci/run, which does it)"
    );
    let out = std::process::Command::new("node")
        .arg(ci.join("gltf-validate.js"))
        .arg(file)
        .output()
        .expect("node must be installed to run the glTF validator");
    let line = String::from_utf8_lossy(&out.stdout).trim().to_string();
    let v: Value = serde_json::from_str(&line).unwrap_or_else(|e| {
        panic!(
            "validator output {line:?} ({e}); stderr {}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (
        v["errors"].as_u64().unwrap(),
        v["warnings"].as_u64().unwrap(),
        line,
    )
}

/// `../shared/scenes/gltf`, the Khronos sample models (see [`shared_scene`]).
#[track_caller]
pub fn shared_gltf() -> Option<PathBuf> {
    shared_scene("gltf")
}

/// Every `.gltf`/`.glb` under `dir`, sorted.
pub fn gltf_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if matches!(
                p.extension().and_then(|x| x.to_str()),
                Some("gltf") | Some("glb")
            ) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The raw file: its JSON and its buffers' bytes.
pub struct RawGltf {
    pub json: Value,
    pub buffers: Vec<Vec<u8>>,
}

fn b64(s: &str) -> Vec<u8> {
    let mut out = Vec::new();
    let (mut acc, mut bits) = (0u32, 0);
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => break,
        } as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

impl RawGltf {
    pub fn open(path: &Path) -> RawGltf {
        let bytes = std::fs::read(path).unwrap();
        let (json, bin) = if bytes.starts_with(b"glTF") {
            let jl = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
            let json: Value = serde_json::from_slice(&bytes[20..20 + jl]).unwrap();
            let at = 20 + jl;
            let bin = if at + 8 <= bytes.len() {
                let bl = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
                Some(bytes[at + 8..at + 8 + bl].to_vec())
            } else {
                None
            };
            (json, bin)
        } else {
            (serde_json::from_slice(&bytes).unwrap(), None)
        };
        let mut buffers = Vec::new();
        for b in json["buffers"].as_array().unwrap() {
            let data = match b["uri"].as_str() {
                None => bin.clone().unwrap(),
                Some(u) if u.starts_with("data:") => b64(u.split_once(',').unwrap().1),
                Some(u) => std::fs::read(path.parent().unwrap().join(u)).unwrap(),
            };
            buffers.push(data);
        }
        RawGltf { json, buffers }
    }

    /// Accessor contents as f64 per component (normalised ints divided out when the
    /// accessor says so), flattened; and the component count.
    pub fn accessor(&self, i: usize) -> (Vec<f64>, usize) {
        let a = &self.json["accessors"][i];
        let comps = match a["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            "MAT4" => 16,
            t => panic!("type {t}"),
        };
        let ct = a["componentType"].as_u64().unwrap();
        let size = match ct {
            5120 | 5121 => 1,
            5122 | 5123 => 2,
            _ => 4,
        };
        let count = a["count"].as_u64().unwrap() as usize;
        let v = &self.json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
        let buf = &self.buffers[v["buffer"].as_u64().unwrap() as usize];
        let base = v["byteOffset"].as_u64().unwrap_or(0) as usize
            + a["byteOffset"].as_u64().unwrap_or(0) as usize;
        let stride = v["byteStride"]
            .as_u64()
            .map_or(size * comps, |s| s as usize);
        let norm = a["normalized"].as_bool().unwrap_or(false);
        let mut out = Vec::new();
        for e in 0..count {
            for c in 0..comps {
                let at = base + e * stride + c * size;
                let b = &buf[at..at + size];
                let x = match ct {
                    5121 => b[0] as f64 / if norm { 255.0 } else { 1.0 },
                    5123 => {
                        u16::from_le_bytes([b[0], b[1]]) as f64 / if norm { 65535.0 } else { 1.0 }
                    }
                    5125 => u32::from_le_bytes(b.try_into().unwrap()) as f64,
                    5126 => f32::from_le_bytes(b.try_into().unwrap()) as f64,
                    t => panic!("component type {t}"),
                };
                out.push(x);
            }
        }
        (out, comps)
    }

    pub fn vec3s(&self, i: usize) -> Vec<Vec3> {
        let (v, c) = self.accessor(i);
        assert_eq!(c, 3);
        v.chunks(3)
            .map(|x| Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32))
            .collect()
    }

    pub fn node_count(&self) -> usize {
        self.json["nodes"].as_array().map_or(0, |n| n.len())
    }

    /// Rest local TRS of a node (decomposing a matrix when given).
    pub fn rest_trs(&self, n: usize) -> (Vec3, Quat, Vec3) {
        let node = &self.json["nodes"][n];
        let f = |k: &str, d: &[f32]| -> Vec<f32> {
            node[k]
                .as_array()
                .map(|a| a.iter().map(|x| x.as_f64().unwrap() as f32).collect())
                .unwrap_or_else(|| d.to_vec())
        };
        if node.get("matrix").is_some() {
            let m = Mat4::from_cols_slice(&f("matrix", &[]));
            let (s, r, t) = m.to_scale_rotation_translation();
            return (t, r, s);
        }
        let t = f("translation", &[0.0; 3]);
        let r = f("rotation", &[0.0, 0.0, 0.0, 1.0]);
        let s = f("scale", &[1.0; 3]);
        (
            Vec3::from_slice(&t),
            Quat::from_slice(&r),
            Vec3::from_slice(&s),
        )
    }

    /// World matrices of every node at time `t`, all clips applied in file order
    /// (LINEAR with slerp, STEP and CUBICSPLINE, clamped at both ends).
    pub fn world_at(&self, t: f64) -> Vec<Mat4> {
        let n = self.node_count();
        let mut trs: Vec<(Vec3, Quat, Vec3)> = (0..n).map(|i| self.rest_trs(i)).collect();
        let mut animated = vec![false; n];
        for anim in self.json["animations"].as_array().into_iter().flatten() {
            for ch in anim["channels"].as_array().unwrap() {
                let s = &anim["samplers"][ch["sampler"].as_u64().unwrap() as usize];
                let node = ch["target"]["node"].as_u64().unwrap() as usize;
                let path = ch["target"]["path"].as_str().unwrap();
                if path == "weights" {
                    continue;
                }
                let interp = s["interpolation"].as_str().unwrap_or("LINEAR");
                let (times, _) = self.accessor(s["input"].as_u64().unwrap() as usize);
                let (vals, w) = self.accessor(s["output"].as_u64().unwrap() as usize);
                let v = sample_raw(&times, &vals, w, interp, path == "rotation", t);
                match path {
                    "translation" => trs[node].0 = Vec3::new(v[0], v[1], v[2]),
                    "rotation" => trs[node].1 = Quat::from_xyzw(v[0], v[1], v[2], v[3]).normalize(),
                    "scale" => trs[node].2 = Vec3::new(v[0], v[1], v[2]),
                    _ => unreachable!(),
                }
                animated[node] = true;
            }
        }
        let local: Vec<Mat4> = (0..n)
            .map(|i| {
                let node = &self.json["nodes"][i];
                if !animated[i] && node.get("matrix").is_some() {
                    let m: Vec<f32> = node["matrix"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|x| x.as_f64().unwrap() as f32)
                        .collect();
                    Mat4::from_cols_slice(&m)
                } else {
                    let (t, r, s) = trs[i];
                    Mat4::from_translation(t) * Mat4::from_quat(r) * Mat4::from_scale(s)
                }
            })
            .collect();
        let mut parent = vec![None; n];
        for i in 0..n {
            for c in self.json["nodes"][i]["children"]
                .as_array()
                .into_iter()
                .flatten()
            {
                parent[c.as_u64().unwrap() as usize] = Some(i);
            }
        }
        (0..n)
            .map(|mut i| {
                let mut m = local[i];
                while let Some(p) = parent[i] {
                    m = local[p] * m;
                    i = p;
                }
                m
            })
            .collect()
    }
}

/// Independent keyframe sampling (glTF 2.0 Appendix C), in f64 where possible.
pub fn sample_raw(
    times: &[f64],
    vals: &[f64],
    w: usize,
    interp: &str,
    rotation: bool,
    t: f64,
) -> Vec<f32> {
    let cubic = interp == "CUBICSPLINE";
    let val = |k: usize| -> Vec<f64> {
        let o = if cubic { (3 * k + 1) * w } else { k * w };
        vals[o..o + w].to_vec()
    };
    let n = times.len();
    let out: Vec<f64> = if t <= times[0] {
        val(0)
    } else if t >= times[n - 1] {
        val(n - 1)
    } else {
        let mut k = 0;
        while times[k + 1] <= t {
            k += 1;
        }
        let td = times[k + 1] - times[k];
        let s = (t - times[k]) / td;
        match interp {
            "STEP" => val(k),
            "CUBICSPLINE" => {
                let p0 = val(k);
                let p1 = val(k + 1);
                let m0: Vec<f64> = vals[(3 * k + 2) * w..(3 * k + 3) * w]
                    .iter()
                    .map(|x| x * td)
                    .collect();
                let m1: Vec<f64> = vals[(3 * (k + 1)) * w..(3 * (k + 1) + 1) * w]
                    .iter()
                    .map(|x| x * td)
                    .collect();
                (0..w)
                    .map(|c| {
                        (2.0 * s.powi(3) - 3.0 * s * s + 1.0) * p0[c]
                            + (s.powi(3) - 2.0 * s * s + s) * m0[c]
                            + (-2.0 * s.powi(3) + 3.0 * s * s) * p1[c]
                            + (s.powi(3) - s * s) * m1[c]
                    })
                    .collect()
            }
            _ if rotation => {
                let a = val(k);
                let mut b = val(k + 1);
                let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
                let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
                let a: Vec<f64> = a.iter().map(|x| x / na).collect();
                b.iter_mut().for_each(|x| *x /= nb);
                let mut d: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
                if d < 0.0 {
                    b.iter_mut().for_each(|x| *x = -*x);
                    d = -d;
                }
                if d > 0.999999 {
                    (0..4).map(|c| a[c] + s * (b[c] - a[c])).collect()
                } else {
                    let th = d.min(1.0).acos();
                    let (wa, wb) = (((1.0 - s) * th).sin() / th.sin(), (s * th).sin() / th.sin());
                    (0..4).map(|c| wa * a[c] + wb * b[c]).collect()
                }
            }
            _ => {
                let (a, b) = (val(k), val(k + 1));
                (0..w).map(|c| a[c] + s * (b[c] - a[c])).collect()
            }
        }
    };
    out.iter().map(|&x| x as f32).collect()
}

/// Largest distance between two lists of points.
pub fn max_dist(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| x.distance(*y))
        .fold(0.0, f32::max)
}

/// Standard base64 with padding (a `data:` URI's payload), written here so tests that
/// build glTF JSON by hand need not call the library's encoder.
pub fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}
