//! What the AOVs and the frame header need besides the tracer: the camera's matrices and
//! projection (`worldToCamera`, `worldToNDC`, the motion AOV), Cryptomatte ids
//! (MurmurHash3_x86_32 with the spec's float fix, the manifests, the ranking of a
//! pixel's samples) and the per-frame header values.
//!
//! Conventions (docs/COMPOSITING.md says them to compositor users):
//! * camera space is the glTF camera's: it looks down `-Z`, `+Y` up, `+X` right;
//! * NDC: after the divide by `w`, `x` and `y` run from −1 to 1 across the image (`+x`
//!   right, `+y` up); `z` is `1 / depth` for a perspective camera, the depth for an
//!   orthographic one (the OpenEXR spec lets readers ignore it);
//! * both matrices are stored as OpenEXR stores an `M44f`: a point is a row vector
//!   multiplied on the left, `p' = [x y z 1] · M`, so the translation is the last row.

use std::collections::BTreeMap;

use glam::{Mat4, Vec2, Vec3, Vec4};

use super::camera::CameraModel;
use crate::scene::Scene;

/// MurmurHash3_x86_32 of `data` with `seed` (Austin Appleby's reference algorithm).
pub fn murmur3_32(data: &[u8], seed: u32) -> u32 {
    const C1: u32 = 0xcc9e_2d51;
    const C2: u32 = 0x1b87_3593;
    let mut h = seed;
    let mut chunks = data.chunks_exact(4);
    for c in &mut chunks {
        let mut k = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        k = k.wrapping_mul(C1).rotate_left(15).wrapping_mul(C2);
        h ^= k;
        h = h.rotate_left(13).wrapping_mul(5).wrapping_add(0xe654_6b64);
    }
    let tail = chunks.remainder();
    if !tail.is_empty() {
        let mut k = 0u32;
        for (i, &b) in tail.iter().enumerate() {
            k |= u32::from(b) << (8 * i);
        }
        k = k.wrapping_mul(C1).rotate_left(15).wrapping_mul(C2);
        h ^= k;
    }
    h ^= data.len() as u32;
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^= h >> 16;
    h
}

/// The Cryptomatte id of `name`: MurmurHash3_32 (seed 0) of its UTF-8 bytes with the
/// exponent fix of the spec (an exponent of all zeros or all ones would make a
/// denormal, an infinity or a NaN: bit 23 is flipped), as the bits of the id float.
pub fn crypto_hash(name: &str) -> u32 {
    let mut h = murmur3_32(name.as_bytes(), 0);
    let exp = (h >> 23) & 255;
    if exp == 0 || exp == 255 {
        h ^= 1 << 23;
    }
    h
}

/// The metadata key of a Cryptomatte layer: the first 7 hex digits of the
/// MurmurHash3_32 of its name (no float fix).
pub fn crypto_key(layer: &str) -> String {
    format!("{:08x}", murmur3_32(layer.as_bytes(), 0))[..7].to_string()
}

/// One kind of Cryptomatte (objects or materials): its layer name, each element's id
/// bits (by node or material index) and the manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct CryptoKind {
    /// `CryptoObject` or `CryptoMaterial`.
    pub layer: &'static str,
    /// Id bits by node index (objects) or material index (materials).
    pub ids: Vec<u32>,
    /// JSON object name → 8 lowercase hex digits, names sorted.
    pub manifest: String,
}

/// The Cryptomatte names of a scene, the same for every frame of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct CryptoNames {
    pub object: CryptoKind,
    pub material: CryptoKind,
}

/// The name Cryptomatte gives node `i`: its glTF name, else `node<i>`.
pub fn object_name(scene: &Scene, i: usize) -> String {
    scene.nodes[i]
        .name
        .clone()
        .unwrap_or_else(|| format!("node{i}"))
}

/// The name Cryptomatte gives material `i`: its glTF name, else `material<i>`.
pub fn material_name(scene: &Scene, i: usize) -> String {
    scene
        .materials
        .get(i)
        .and_then(|m| m.name.clone())
        .unwrap_or_else(|| format!("material{i}"))
}

fn kind(
    layer: &'static str,
    names: Vec<String>,
    listed: impl Iterator<Item = usize>,
) -> CryptoKind {
    let ids: Vec<u32> = names.iter().map(|n| crypto_hash(n)).collect();
    let manifest: BTreeMap<&str, String> = listed
        .map(|i| (names[i].as_str(), format!("{:08x}", ids[i])))
        .collect();
    CryptoKind {
        layer,
        ids,
        manifest: serde_json::to_string(&manifest).unwrap_or_else(|_| "{}".into()),
    }
}

impl CryptoNames {
    /// Ids of every node and material; the manifests list the nodes that place a mesh
    /// in the shown scene and every material.
    pub fn new(scene: &Scene) -> CryptoNames {
        let nodes: Vec<String> = (0..scene.nodes.len())
            .map(|i| object_name(scene, i))
            .collect();
        let materials: Vec<String> = (0..scene.materials.len())
            .map(|i| material_name(scene, i))
            .collect();
        let shown = scene
            .scene_nodes()
            .into_iter()
            .filter(|&n| scene.nodes[n].mesh.is_some());
        CryptoNames {
            object: kind("CryptoObject", nodes, shown),
            material: kind("CryptoMaterial", materials, 0..scene.materials.len()),
        }
    }
}

/// The ranks of one pixel: `(id bits, coverage)` of the ids of its samples (`None` for
/// a sample that hit nothing), most coverage first, ties by smaller id; `levels` kept,
/// the rest `(0, 0)`. Coverage is the share of the pixel's samples.
pub fn rank(samples: &[Option<u32>], levels: usize, out: &mut [(f32, f32)]) {
    let mut counts: Vec<(u32, u32)> = Vec::with_capacity(samples.len());
    for id in samples.iter().flatten() {
        match counts.iter_mut().find(|(i, _)| i == id) {
            Some(c) => c.1 += 1,
            None => counts.push((*id, 1)),
        }
    }
    counts.sort_unstable_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let inv = 1.0 / samples.len().max(1) as f32;
    for (k, slot) in out.iter_mut().enumerate().take(levels) {
        *slot = counts
            .get(k)
            .map_or((0.0, 0.0), |&(id, n)| (f32::from_bits(id), n as f32 * inv));
    }
}

/// World → camera (column-vector convention, glam's).
pub fn world_to_camera(cam: &CameraModel) -> Mat4 {
    let r = cam.rotation.transpose();
    let t = -(r * cam.origin);
    Mat4::from_cols(
        r.x_axis.extend(0.0),
        r.y_axis.extend(0.0),
        r.z_axis.extend(0.0),
        t.extend(1.0),
    )
}

/// Camera → NDC clip space (column-vector convention), as the module docs say.
pub fn camera_to_ndc(cam: &CameraModel) -> Mat4 {
    match cam.ortho {
        None => {
            let sx = 1.0 / (cam.aspect * cam.tan_half);
            let sy = 1.0 / cam.tan_half;
            // Rows: x·sx, y·sy, 1, −z  →  after the divide: x/(−z)·sx, y/(−z)·sy, 1/(−z).
            Mat4::from_cols(
                Vec4::new(sx, 0.0, 0.0, 0.0),
                Vec4::new(0.0, sy, 0.0, 0.0),
                Vec4::new(0.0, 0.0, 0.0, -1.0),
                Vec4::new(0.0, 0.0, 1.0, 0.0),
            )
        }
        Some((xmag, ymag)) => Mat4::from_cols(
            Vec4::new(1.0 / xmag, 0.0, 0.0, 0.0),
            Vec4::new(0.0, 1.0 / ymag, 0.0, 0.0),
            Vec4::new(0.0, 0.0, -1.0, 0.0),
            Vec4::new(0.0, 0.0, 0.0, 1.0),
        ),
    }
}

/// A matrix as OpenEXR stores it (row-vector convention, rows in order).
pub fn exr_matrix(m: Mat4) -> [f32; 16] {
    // The row-vector matrix is the transpose; its rows are the columns of `m`.
    m.to_cols_array()
}

/// Where `p` (world) is seen on the image of `cam`, in pixel units (`(x + 0.5, y + 0.5)`
/// is the centre of pixel `(x, y)`); `None` behind a perspective camera.
pub fn project(cam: &CameraModel, p: Vec3) -> Option<Vec2> {
    let c = cam.rotation.transpose() * (p - cam.origin);
    let (sx, sy) = match cam.ortho {
        None => {
            if c.z >= 0.0 || c.z.is_nan() {
                return None;
            }
            let d = -c.z;
            (
                c.x / d / (cam.aspect * cam.tan_half),
                c.y / d / cam.tan_half,
            )
        }
        Some((xmag, ymag)) => (c.x / xmag, c.y / ymag),
    };
    let px = Vec2::new(
        (sx + 1.0) * 0.5 * cam.width as f32,
        (1.0 - sy) * 0.5 * cam.height as f32,
    );
    px.is_finite().then_some(px)
}

/// `fps` as the rational OpenEXR's `framesPerSecond` holds: exact for whole rates and
/// the NTSC rates (`24000/1001`…), else to 1/100000.
pub fn fps_rational(fps: f32) -> (i32, u32) {
    for d in [1u32, 1001, 1000, 100, 100_000] {
        let n = (fps as f64 * d as f64).round();
        if n.abs() < i32::MAX as f64 && ((n / d as f64) as f32 == fps || d == 100_000) {
            let g = gcd(n.abs() as u64, d as u64).max(1);
            return ((n as i64 / g as i64) as i32, (d as u64 / g) as u32);
        }
    }
    (24, 1)
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// The per-frame header values of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameHeader {
    pub fps: f32,
    /// OpenEXR layout (see [`exr_matrix`]).
    pub world_to_camera: [f32; 16],
    pub world_to_ndc: [f32; 16],
    /// [`RenderOptions::options_string`](super::RenderOptions::options_string).
    pub options: String,
    /// The manifests and layer names when the frame has Cryptomatte layers.
    pub crypto: Option<std::sync::Arc<CryptoNames>>,
}

impl FrameHeader {
    pub fn new(
        cam: &CameraModel,
        fps: f32,
        options: String,
        crypto: Option<std::sync::Arc<CryptoNames>>,
    ) -> FrameHeader {
        let w2c = world_to_camera(cam);
        FrameHeader {
            fps,
            world_to_camera: exr_matrix(w2c),
            world_to_ndc: exr_matrix(camera_to_ndc(cam) * w2c),
            options,
            crypto,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::LookAt;

    #[test]
    fn murmur3_known_vectors() {
        assert_eq!(murmur3_32(b"", 0), 0);
        assert_eq!(murmur3_32(b"", 1), 0x514e_28b7);
        assert_eq!(murmur3_32(b"hello", 0), 0x248b_fa47);
        assert_eq!(
            murmur3_32(b"The quick brown fox jumps over the lazy dog", 0),
            0x2e4f_f723
        );
        assert_eq!(murmur3_32(b"test", 0), 0xba6b_d213);
        assert_eq!(murmur3_32(b"Hello, world!", 1234), 0xfaf6_cdb3);
    }

    #[test]
    fn crypto_ids_have_a_normal_exponent() {
        for name in ["", "hello", "floor", "mover", "CryptoObject", "a", "b", "ü"] {
            let h = crypto_hash(name);
            let e = (h >> 23) & 255;
            assert!(e != 0 && e != 255, "{name}");
            assert!(f32::from_bits(h).is_normal() || f32::from_bits(h) == 0.0);
            assert_eq!(
                (h ^ murmur3_32(name.as_bytes(), 0)) & !(1 << 23),
                0,
                "{name}"
            );
        }
        // "" hashes to 0: exponent 0, so bit 23 flips.
        assert_eq!(crypto_hash(""), 1 << 23);
        assert_eq!(crypto_key("CryptoObject").len(), 7);
    }

    #[test]
    fn ranks_by_coverage_then_id() {
        let mut out = [(9.0, 9.0); 3];
        rank(&[Some(5), None, Some(7), Some(7)], 3, &mut out);
        assert_eq!(out[0], (f32::from_bits(7), 0.5));
        assert_eq!(out[1], (f32::from_bits(5), 0.25));
        assert_eq!(out[2], (0.0, 0.0));
    }

    #[test]
    fn matrices_and_projection_agree_with_the_rays() {
        let l = LookAt {
            from: Vec3::new(1.0, 2.0, 3.0),
            at: Vec3::new(0.0, 0.5, -1.0),
            up: Vec3::Y,
            yfov_deg: 50.0,
        };
        let cam = CameraModel::look_at(&l, 64, 48).unwrap();
        let w2c = world_to_camera(&cam);
        assert!(w2c.transform_point3(l.from).length() < 1e-5);
        let ndc = camera_to_ndc(&cam) * w2c;
        for (x, y) in [(0.5f32, 0.5f32), (10.5, 30.5), (63.5, 47.5)] {
            let r = cam.ray(x, y);
            let p = r.at(2.5);
            let px = project(&cam, p).unwrap();
            assert!((px - Vec2::new(x, y)).length() < 1e-3, "{px}");
            let c = ndc * p.extend(1.0);
            let (nx, ny) = (c.x / c.w, c.y / c.w);
            let got = Vec2::new((nx + 1.0) * 32.0, (1.0 - ny) * 24.0);
            assert!((got - Vec2::new(x, y)).length() < 1e-3, "{got}");
        }
        // Row-vector layout: the translation is the last row.
        let m = exr_matrix(w2c);
        assert_eq!(&m[12..15], &w2c.w_axis.truncate().to_array()[..]);
    }

    #[test]
    fn fps_rationals() {
        assert_eq!(fps_rational(24.0), (24, 1));
        assert_eq!(fps_rational(24000.0 / 1001.0), (24000, 1001));
        assert_eq!(fps_rational(12.5), (25, 2));
    }
}
