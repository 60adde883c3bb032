//! The surface a ray meets: the hit's point, normals (normal maps), uvs, texture level of
//! detail, and the textured factors of its material read there.

use glam::{Vec2, Vec3, Vec3A, Vec3Swizzles, Vec4};

use super::ShadeContext;
use crate::geometry::{Hit, Ray};
use crate::psf::Prim;
use crate::scene::{AlphaMode, Material, TextureRef};

/// A hit made into a surface: where, which way it faces, and what its material reads.
///
/// Its vectors are `Vec3A`, as is shading's arithmetic: SSE lanes doing the operations
/// of `Vec3` in the same order (so the same bits), in fewer instructions (shading was
/// some 1,300 instructions a hit; benches/PERF.md, issue 38, round 9).
pub(super) struct Surface {
    pub(super) point: Vec3A,
    /// Geometric normal, facing the incoming ray.
    pub(super) ng: Vec3A,
    /// Shading normal, on the side of `ng`.
    pub(super) ns: Vec3A,
    /// Unit ray direction.
    pub(super) dir: Vec3A,
    pub(super) entering: bool,
    pub(super) uv: Vec2,
    /// Texture level of detail for a unit texture: a `w × h` texture adds
    /// `log2(√(w·h))`; `-∞` for the finest level.
    pub(super) lod: f32,
    pub(super) material: u32,
    /// Hit number of the triangle.
    pub(super) tri: u32,
}

/// `a × b` as `Vec3::cross` computes it (`Vec3A::cross` fuses its products where the
/// build has FMA, which would make an `x86-64-v3` build's frames differ).
#[inline(always)]
pub(super) fn cross(a: Vec3A, b: Vec3A) -> Vec3A {
    a.yzx() * b.zxy() - a.zxy() * b.yzx()
}

/// The texture level of detail at a hit (`Surface::lod`): log2 of the footprint's
/// width in uv units for a unit texture (Akenine-Möller et al. 2021, eq. 34), from the
/// ray cone's `width` there, the triangle's uvs `t` and unnormalised `face` normal, the
/// normal `ng` facing the ray and its unit direction `dir`; `-∞` (the finest level) for
/// a cone of no width or a triangle without uv or world area.
#[inline]
pub(super) fn level_of_detail(
    t: &[Vec2; 3],
    face: Vec3A,
    ng: Vec3A,
    dir: Vec3A,
    width: f32,
) -> f32 {
    if width > 0.0 {
        let uv_area = (t[1] - t[0]).perp_dot(t[2] - t[0]).abs();
        let world_area = face.length();
        let cos = ng.dot(dir).abs().max(1e-4);
        if uv_area > 0.0 && world_area > 0.0 {
            return (width / cos).log2() + 0.5 * (uv_area / world_area).log2();
        }
    }
    f32::NEG_INFINITY
}

/// The material's coverage at a point of base colour `base`.
pub(super) fn alpha_of(m: &Material, base: Vec4) -> f32 {
    match m.alpha_mode {
        AlphaMode::Opaque => 1.0,
        AlphaMode::Mask { cutoff } => {
            if base.w >= cutoff {
                1.0
            } else {
                0.0
            }
        }
        AlphaMode::Blend => base.w.clamp(0.0, 1.0),
    }
}

impl ShadeContext<'_> {
    /// Samples a texture (RGBA, linearised RGB when `srgb`) at `uv` (through the slot's
    /// `KHR_texture_transform`, if any), filtered for a footprint of level
    /// `lod + log2(√(width·height))` (see [`Surface::lod`]), or `None` without one.
    #[inline]
    pub(super) fn texture(
        &self,
        slot: Option<TextureRef>,
        uv: Vec2,
        lod: f32,
        srgb: bool,
    ) -> Option<Vec4> {
        let slot = slot?;
        let t = slot.texture as usize;
        let tex = self.scene.textures.get(t)?;
        let img = self.scene.images.get(tex.image as usize)?;
        let (w, h) = (img.width, img.height);
        if w == 0 || h == 0 || img.rgba8.len() as u64 != u64::from(w) * u64::from(h) * 4 {
            return None;
        }
        let uv = slot.transform.map_or(uv, |t| t.apply(uv));
        let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
        let lod = lod + 0.5 * ((w as f32) * (h as f32)).log2();
        Some(self.mips.lookup(t, tex, &img.rgba8, w, h, uv, lod, srgb))
    }

    /// Geometry at a hit, `None` for a triangle index out of range. `width`: the ray
    /// cone's width at the hit (0: the finest texture level).
    #[inline(always)]
    pub(super) fn surface(&self, ray: &Ray, hit: &Hit, width: f32) -> Option<Surface> {
        let (soup, i) = match Prim::from_index(hit.tri, self.static_soup.len()) {
            Prim::Static(i) => (self.static_soup, i as usize),
            Prim::Moving(i) => (self.dynamic_soup, i as usize),
        };
        let p = soup.positions.get(i)?;
        let nrm = soup.normals.get(i);
        let uvs = soup.uvs.get(i);
        let material = soup.material.get(i).copied().unwrap_or(u32::MAX);
        let (u, v) = (hit.u, hit.v);
        let w = 1.0 - u - v;
        let (p0, p1, p2) = (Vec3A::from(p[0]), Vec3A::from(p[1]), Vec3A::from(p[2]));
        let point = p0 * w + p1 * u + p2 * v;
        let face = cross(p1 - p0, p2 - p0);
        let mut ng = face.normalize_or_zero();
        let dir = Vec3A::from(ray.dir).normalize_or_zero();
        if ng == Vec3A::ZERO {
            ng = -dir;
        }
        let front = ng;
        // `entering`: the ray meets the side the winding makes the front.
        let entering = ng.dot(dir) < 0.0;
        if !entering {
            ng = -ng;
        }
        let mut ns = nrm
            .map(|n| {
                (Vec3A::from(n[0]) * w + Vec3A::from(n[1]) * u + Vec3A::from(n[2]) * v)
                    .normalize_or_zero()
            })
            .unwrap_or(Vec3A::ZERO);
        if ns == Vec3A::ZERO || !ns.is_finite() {
            ns = front;
        }
        let uv = uvs.map_or(Vec2::ZERO, |t| t[0] * w + t[1] * u + t[2] * v);
        // Level of detail without the texture's size: log2 of the footprint's width in
        // uv units (Akenine-Möller et al. 2021, eq. 34, for a unit texture).
        // Only a textured material reads it (two logarithms a hit saved elsewhere).
        let textured = self.material(material).is_some_and(|m| {
            m.base_color_texture.is_some()
                || m.metallic_roughness_texture.is_some()
                || m.emissive_texture.is_some()
                || m.normal_texture.is_some()
        });
        let lod = match uvs {
            Some(t) if textured => level_of_detail(t, face, ng, dir, width),
            _ => f32::NEG_INFINITY,
        };
        if let (Some(m), Some(t)) = (self.material(material), uvs) {
            if m.normal_texture.is_some() {
                ns = self
                    .normal_mapped(m, ns.into(), p, t, uv, lod)
                    .map_or(ns, Vec3A::from);
            }
        }
        if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        Some(Surface {
            point,
            ng,
            ns,
            dir,
            entering,
            uv,
            lod,
            material,
            tri: hit.tri,
        })
    }

    /// The front-side normal `n` bent by the material's normal map at `uv`. Tangent
    /// `T = ∂p/∂u` of the triangle (per triangle, from its uvs: the file's `TANGENT`
    /// attribute is not read), made orthogonal to `n`; bitangent `B = ±n × T`, the sign
    /// making it point along `−∂p/∂v` (glTF's normal maps have +Y towards decreasing `v`,
    /// and mirrored uvs flip it). `None` where the uvs are degenerate.
    pub(super) fn normal_mapped(
        &self,
        m: &Material,
        n: Vec3,
        p: &[Vec3; 3],
        t: &[Vec2; 3],
        uv: Vec2,
        lod: f32,
    ) -> Option<Vec3> {
        let c = self.texture(m.normal_texture, uv, lod, false)?;
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let (d1, d2) = (t[1] - t[0], t[2] - t[0]);
        let det = d1.perp_dot(d2);
        if det.abs() < 1e-12 {
            return None;
        }
        let dpdu = (e1 * d2.y - e2 * d1.y) / det;
        let dpdv = (e2 * d1.x - e1 * d2.x) / det;
        let tangent = (dpdu - n * n.dot(dpdu)).try_normalize()?;
        let mut bitangent = n.cross(tangent);
        if bitangent.dot(dpdv) > 0.0 {
            bitangent = -bitangent;
        }
        let s = if m.normal_scale.is_finite() {
            m.normal_scale
        } else {
            1.0
        };
        let local = Vec3::new(
            (2.0 * c.x - 1.0) * s,
            (2.0 * c.y - 1.0) * s,
            2.0 * c.z - 1.0,
        );
        let bent = (tangent * local.x + bitangent * local.y + n * local.z).try_normalize()?;
        // A map cannot turn the normal to the far side of the surface.
        (bent.dot(n) > 0.0).then_some(bent)
    }

    /// Base colour (factor × texture) at a surface.
    pub(super) fn base_color(&self, m: &Material, uv: Vec2, lod: f32) -> Vec4 {
        match self.texture(m.base_color_texture, uv, lod, true) {
            Some(t) => m.base_color * t,
            None => m.base_color,
        }
    }

    /// Emitted radiance of `m` at `uv`. Inlined, in lanes (it was an out-of-line call
    /// whose `Vec3` came back through memory); the texture's lookup stays out of line
    /// (benches/PERF.md, issue 38, round 12).
    #[inline(always)]
    pub(super) fn emission(&self, m: &Material, uv: Vec2, lod: f32) -> Vec3A {
        let e = Vec3A::from(m.emissive) * m.emissive_strength;
        if e != Vec3A::ZERO && m.emissive_texture.is_some() {
            self.textured_emission(m, e, uv, lod)
        } else {
            e
        }
    }

    #[inline(never)]
    fn textured_emission(&self, m: &Material, e: Vec3A, uv: Vec2, lod: f32) -> Vec3A {
        match self.texture(m.emissive_texture, uv, lod, true) {
            Some(t) => e * Vec3A::from(t.truncate()),
            None => e,
        }
    }

    /// Texture coordinates at barycentrics `b` of hit number `tri`.
    pub(super) fn uv_at(&self, tri: u32, b: Vec2) -> Vec2 {
        let uvs = match Prim::from_index(tri, self.static_soup.len()) {
            Prim::Static(i) => self.static_soup.uvs.get(i as usize),
            Prim::Moving(i) => self.dynamic_soup.uvs.get(i as usize),
        };
        uvs.map_or(Vec2::ZERO, |t| {
            t[0] * (1.0 - b.x - b.y) + t[1] * b.x + t[2] * b.y
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn bits(v: Vec3) -> [u32; 3] {
        v.to_array().map(f32::to_bits)
    }

    proptest! {
        /// Shading's arithmetic in `Vec3A` lanes gives `Vec3`'s bits: the frames do not
        /// change with it, nor with a build whose target has FMA (`cross`).
        #[test]
        fn lanes_give_vec3s_bits(
            a in prop::array::uniform3(-1e4f32..1e4),
            b in prop::array::uniform3(-1e4f32..1e4),
            s in 0f32..1.0,
        ) {
            let (a3, b3) = (Vec3::from(a), Vec3::from(b));
            let (aa, ba) = (Vec3A::from(a), Vec3A::from(b));
            prop_assert_eq!(bits(cross(aa, ba).into()), bits(a3.cross(b3)));
            prop_assert_eq!(aa.dot(ba).to_bits(), a3.dot(b3).to_bits());
            prop_assert_eq!(aa.length().to_bits(), a3.length().to_bits());
            prop_assert_eq!(bits(aa.normalize_or_zero().into()), bits(a3.normalize_or_zero()));
            prop_assert_eq!(bits(aa.lerp(ba, s).into()), bits(a3.lerp(b3, s)));
            prop_assert_eq!(aa.max_element().to_bits(), a3.max_element().to_bits());
            prop_assert_eq!(bits((aa * s + ba / 3.0 - aa * ba).into()), bits(a3 * s + b3 / 3.0 - a3 * b3));
        }
    }
}
