//! Four hits shaded at once, one in each SSE lane: [`ShadeContext::shade4`].
//!
//! [`ShadeContext::shade`] does a hit's vector arithmetic in `Vec3A`, three of four lanes
//! busy and a shuffle for every dot product, normalisation and broadcast scalar. Here
//! the same operations run on four hits side by side (`V3`: the x, y and z of four
//! vectors), for the common case of a frame without area lights, diffuse bounces or
//! light-path passes, lit by punctual lights (point, spot, directional; any number),
//! and hits on plain materials (no texture but the base colour's, opaque, not
//! transmissive, not emissive, no ambient colour of their own); a textured hit's base
//! colour is looked up lane by lane, as `shade` looks it up, and so is a glossy hit's
//! reflection, drawn from the GGX lobe with the ray's seed as `secondary` draws it (a
//! frame that draws random numbers derives its reflections' seeds as `secondary`
//! does). The museum class's dolly: 883 → 817 M instructions a frame, its shading
//! 67–70 → 52–56 ms a frame at 1 thread (benches/PERF.md, issue 38, round 13). The
//! demo (GGX floors and metals) had all its frames shaded one hit at a time; its
//! shading is now about a fifth faster (round 27).
//!
//! The answers are those of four calls of `shade`, bit for bit: each lane does the
//! scalar model's operations in the scalar model's order (glam's `Vec3A` dot product is
//! `(x·x' + y·y') + z·z'`, its normalisation a multiplication by `1 / sqrt` of that,
//! `max_element` `maxps` of (x, z) and of (y, z), then of the two), and what the hits
//! push goes to the block's lists hit by hit, as four calls would push it. A group with
//! a hit this path does not take (a miss, another material, a triangle out of range) or
//! with a value that is not finite where the scalar model takes a maximum or a clamp is
//! shaded by `shade` instead. A property test holds the two to the same lists, bit for
//! bit, over 400 random frames.

use glam::{BVec4A, Mat4, Vec2, Vec3, Vec3A, Vec4};

use super::block::{BlockOut, Item};
use super::bsdf::{glossy_alpha, glossy_reflection, powi, powi4, Factors};
use super::direct::{cone, PreLight};
use super::surface::level_of_detail;
use super::{LightPath, ShadeContext, GLOSSY_LIMIT, MIN_WEIGHT};
use crate::geometry::{Hit, Ray};
use crate::psf::Prim;
use crate::scene::{AlphaMode, Falloff, LightKind, Material};

/// What the four-lane path needs of a material, worked out once a frame with the
/// scalar model's own expressions (so the same bits); `None` for a material the path
/// does not take.
#[derive(Clone, Copy, Debug)]
pub(super) struct PlainMaterial {
    albedo: Vec3A,
    gloss: f32,
    /// `(1 − metallic)(1 − transmission)`, the first factor of the diffuse weight.
    diffuse: f32,
    /// `metallic (1 − gloss)`, a rough metal's lobe as diffuse.
    rough_metal: f32,
    f0: Vec3A,
    /// `f0 (1 − gloss / 2)`, the glint's colour.
    glint: Vec3A,
    reflects: bool,
    /// The GGX lobe's width where the reflection is drawn from it (`Lobes::glossy_alpha`):
    /// that lane's reflection is drawn as `secondary` draws it.
    glossy_alpha: Option<f32>,
    shininess: f32,
    /// The glint's normalisation, `(shininess + 8) / 8π`.
    norm: f32,
    /// The material's metallic, roughness and transmission factors, from which a
    /// textured hit's constants are worked out again with its own albedo.
    factors: (f32, f32, f32),
    /// Whether the base colour has a texture: `albedo`, `f0` and `glint` are then the
    /// factor's alone, and each hit gets its own ([`with_albedo`](Self::with_albedo)).
    textured: bool,
}

impl PlainMaterial {
    pub(super) fn of(m: &Material) -> Option<PlainMaterial> {
        let plain = m.metallic_roughness_texture.is_none()
            && m.emissive_texture.is_none()
            && m.normal_texture.is_none()
            && matches!(m.alpha_mode, AlphaMode::Opaque)
            && m.ambient.is_none()
            && m.transmission == 0.0
            && m.metallic.is_finite()
            && m.roughness.is_finite()
            && m.base_color.is_finite();
        if !plain {
            return None;
        }
        // An emitter is an area light, whose samples draw random numbers: a frame
        // with one is not the lanes' anyway. The emission must be +0 to the bit (the
        // scalar model adds it to the ambient term, and -0 + -0 is not +0 + -0).
        let emitted = Vec3A::from(m.emissive) * m.emissive_strength;
        if emitted.to_array().iter().any(|c| c.to_bits() != 0) {
            return None;
        }
        let factors = (m.metallic, m.roughness, m.transmission);
        let mut p = Self::with(factors, m.base_color.truncate().into())?;
        p.textured = m.base_color_texture.is_some();
        Some(p)
    }

    /// The material's constants for a hit whose base colour is `albedo` (a textured
    /// one's, factor times texture).
    #[inline]
    fn with_albedo(&self, albedo: Vec3A) -> Option<PlainMaterial> {
        Self::with(self.factors, albedo)
    }

    /// As `ShadeContext::lobes` computes them for `albedo` (no metallic-roughness
    /// texture); `None` where `f0` is not finite.
    fn with(factors: (f32, f32, f32), albedo: Vec3A) -> Option<PlainMaterial> {
        let Factors {
            metallic,
            roughness,
            transmission,
            gloss,
            f0,
        } = Factors::of(factors.0, factors.1, factors.2, albedo);
        let shininess = ShadeContext::shininess(roughness);
        if !f0.is_finite() {
            return None;
        }
        Some(PlainMaterial {
            albedo,
            gloss,
            diffuse: (1.0 - metallic) * (1.0 - transmission),
            rough_metal: metallic * (1.0 - gloss),
            f0,
            glint: f0 * (1.0 - gloss * 0.5),
            reflects: roughness < GLOSSY_LIMIT,
            glossy_alpha: glossy_alpha(roughness),
            shininess,
            norm: (shininess + 8.0) / (8.0 * std::f32::consts::PI),
            factors,
            textured: false,
        })
    }
}

/// Three coordinates of four vectors, one vector a lane.
#[derive(Clone, Copy)]
struct V3 {
    x: Vec4,
    y: Vec4,
    z: Vec4,
}

impl V3 {
    /// Four vectors across the lanes, each lane's coordinates read one by one. Read as
    /// four 16-byte rows and transposed in shuffles, as before round 17, the rows
    /// spanned the stores that had just written the 12-byte vectors, and the CPU could
    /// not forward them: 5 % of `shade4`'s time went to three such loads
    /// (`benches/PERF.md`, issue 38, round 17).
    #[inline(always)]
    fn of(v: [Vec3; 4]) -> V3 {
        V3::from_fn(|k| v[k])
    }

    /// `V3::of([f(0), f(1), f(2), f(3)])` without the array: `array::map` built one on
    /// the stack in 4- and 8-byte stores that a 16-byte load then read back, which the
    /// CPU cannot forward either.
    #[inline(always)]
    fn from_fn(f: impl Fn(usize) -> Vec3) -> V3 {
        let (a, b, c, d) = (f(0), f(1), f(2), f(3));
        V3 {
            x: Vec4::new(a.x, b.x, c.x, d.x),
            y: Vec4::new(a.y, b.y, c.y, d.y),
            z: Vec4::new(a.z, b.z, c.z, d.z),
        }
    }

    /// The four vectors, lane by lane (the transpose back).
    fn lanes(&self) -> [Vec3A; 4] {
        let m = Mat4::from_cols(self.x, self.y, self.z, Vec4::ZERO).transpose();
        [
            Vec3A::from_vec4(m.x_axis),
            Vec3A::from_vec4(m.y_axis),
            Vec3A::from_vec4(m.z_axis),
            Vec3A::from_vec4(m.w_axis),
        ]
    }

    fn splat(v: Vec3A) -> V3 {
        V3 {
            x: Vec4::splat(v.x),
            y: Vec4::splat(v.y),
            z: Vec4::splat(v.z),
        }
    }

    fn add(self, o: V3) -> V3 {
        V3 {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }

    fn sub(self, o: V3) -> V3 {
        V3 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }

    fn mul(self, o: V3) -> V3 {
        V3 {
            x: self.x * o.x,
            y: self.y * o.y,
            z: self.z * o.z,
        }
    }

    /// Each vector times its lane's scalar (`Vec3A * f32`).
    fn scale(self, s: Vec4) -> V3 {
        V3 {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }

    fn neg(self) -> V3 {
        V3 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }

    /// `Vec3A::dot`: `(x·x' + y·y') + z·z'`.
    fn dot(self, o: V3) -> Vec4 {
        (self.x * o.x + self.y * o.y) + self.z * o.z
    }

    /// `Vec3A::normalize_or_zero`: times `1 / sqrt(dot)` where that is finite and
    /// positive, else zero.
    fn normalize_or_zero(self) -> V3 {
        let rcp = Vec4::ONE / self.dot(self).sqrt();
        let ok = rcp.is_finite_mask() & rcp.cmpgt(Vec4::ZERO);
        V3::select(ok, self.scale(rcp), V3::splat(Vec3A::ZERO))
    }

    /// `Vec3A::max_element`: `maxps` of (x, z) and of (y, z), then `maxps` of the two,
    /// as its shuffles do (the same answer for NaN too).
    fn max_element(self) -> Vec4 {
        self.x.max(self.z).max(self.y.max(self.z))
    }

    /// `v == Vec3A::ZERO`.
    fn is_zero(self) -> BVec4A {
        self.x.cmpeq(Vec4::ZERO) & self.y.cmpeq(Vec4::ZERO) & self.z.cmpeq(Vec4::ZERO)
    }

    fn is_finite(self) -> BVec4A {
        self.x.is_finite_mask() & self.y.is_finite_mask() & self.z.is_finite_mask()
    }

    fn select(mask: BVec4A, a: V3, b: V3) -> V3 {
        V3 {
            x: Vec4::select(mask, a.x, b.x),
            y: Vec4::select(mask, a.y, b.y),
            z: Vec4::select(mask, a.z, b.z),
        }
    }
}

/// `Vec4::new(f(0), f(1), f(2), f(3))`: lanes filled from scalars, for values just
/// stored one by one (`Vec4::from_array` of such an array is a 16-byte load over four
/// 4-byte stores, which the CPU cannot forward; `benches/PERF.md`, issue 38, round 17).
#[inline(always)]
fn lanes4(f: impl Fn(usize) -> f32) -> Vec4 {
    Vec4::new(f(0), f(1), f(2), f(3))
}

/// `f32::clamp(x, lo, hi)` in lanes, for finite `x`.
fn clamp(x: Vec4, lo: f32, hi: f32) -> Vec4 {
    let x = Vec4::select(x.cmplt(Vec4::splat(lo)), Vec4::splat(lo), x);
    Vec4::select(x.cmpgt(Vec4::splat(hi)), Vec4::splat(hi), x)
}

/// The lanes' materials, gathered: scalars as lanes, colours as `V3`.
struct Mats {
    albedo: V3,
    f0: V3,
    diffuse: Vec4,
    rough_metal: Vec4,
    gloss: Vec4,
    reflects: BVec4A,
}

impl Mats {
    fn of(m: [&PlainMaterial; 4]) -> Mats {
        if m.iter().all(|x| std::ptr::eq(*x, m[0])) {
            // One material in all four lanes (most groups: a surface's neighbouring
            // pixels): splatted, not gathered.
            let m = m[0];
            return Mats {
                albedo: V3::splat(m.albedo),
                f0: V3::splat(m.f0),
                diffuse: Vec4::splat(m.diffuse),
                rough_metal: Vec4::splat(m.rough_metal),
                gloss: Vec4::splat(m.gloss),
                reflects: BVec4A::splat(m.reflects),
            };
        }
        let v = |f: fn(&PlainMaterial) -> Vec3A| V3::from_fn(|k| f(m[k]).into());
        let s = |f: fn(&PlainMaterial) -> f32| lanes4(|k| f(m[k]));
        Mats {
            albedo: v(|m| m.albedo),
            f0: v(|m| m.f0),
            diffuse: s(|m| m.diffuse),
            rough_metal: s(|m| m.rough_metal),
            gloss: s(|m| m.gloss),
            reflects: BVec4A::new(m[0].reflects, m[1].reflects, m[2].reflects, m[3].reflects),
        }
    }
}

impl ShadeContext<'_> {
    /// Whether [`shade4`](Self::shade4) may take this frame's hits into `out`.
    #[inline]
    pub(in crate::render) fn lanes(&self, out: &BlockOut) -> bool {
        self.lanes && !out.light_paths
    }

    /// Four rays' contributions, as four calls of [`shade`](Self::shade) in order would
    /// make them (see the module's notes); only where [`lanes`](Self::lanes) says so.
    #[allow(clippy::too_many_arguments)]
    pub(in crate::render) fn shade4(
        &self,
        rays: [&Ray; 4],
        items: [&Item; 4],
        hits: [Option<Hit>; 4],
        max_depth: u32,
        spp: u32,
        out: &mut BlockOut,
    ) {
        if !self.shade4_lanes(rays, items, hits, max_depth, out) {
            for k in 0..4 {
                self.shade(rays[k], items[k], hits[k], max_depth, spp, out);
            }
        }
    }

    /// The lanes' work; `false`, having pushed nothing, where a hit is not the path's.
    fn shade4_lanes(
        &self,
        rays: [&Ray; 4],
        items: [&Item; 4],
        hits: [Option<Hit>; 4],
        max_depth: u32,
        out: &mut BlockOut,
    ) -> bool {
        debug_assert!(self.lanes(out));
        // Each lane's triangle and material.
        let mut pos = [[Vec3::ZERO; 4]; 3];
        let mut nrm = [[Vec3::ZERO; 4]; 3];
        let mut has_normals = [false; 4];
        let mut mats: [Option<&PlainMaterial>; 4] = [None; 4];
        let mut uvw = [[0.0f32; 4]; 3];
        let mut t = [0.0f32; 4];
        // A textured lane's uvs and material (`surface` and `shade` read them so).
        let mut uvs: [Option<&[Vec2; 3]>; 4] = [None; 4];
        let mut textured: [Option<&Material>; 4] = [None; 4];
        for k in 0..4 {
            let Some(hit) = hits[k] else {
                return false;
            };
            let (soup, i) = match Prim::from_index(hit.tri, self.static_soup.len()) {
                Prim::Static(i) => (self.static_soup, i as usize),
                Prim::Moving(i) => (self.dynamic_soup, i as usize),
            };
            let Some(p) = soup.positions.get(i) else {
                return false;
            };
            let material = soup.material.get(i).copied().unwrap_or(u32::MAX);
            let plain = match self.plain.get(material as usize) {
                Some(m) => m.as_ref(),
                None => self.plain_default.as_ref(),
            };
            let Some(plain) = plain else {
                return false;
            };
            mats[k] = Some(plain);
            if plain.textured {
                uvs[k] = soup.uvs.get(i);
                textured[k] = Some(self.material(material).unwrap_or(&self.default_material));
            }
            for c in 0..3 {
                pos[c][k] = p[c];
            }
            if let Some(n) = soup.normals.get(i) {
                has_normals[k] = true;
                for c in 0..3 {
                    nrm[c][k] = n[c];
                }
            }
            let w = 1.0 - hit.u - hit.v;
            uvw[0][k] = w;
            uvw[1][k] = hit.u;
            uvw[2][k] = hit.v;
            t[k] = hit.t;
        }
        let [Some(m0), Some(m1), Some(m2), Some(m3)] = mats else {
            return false;
        };
        let mut mats = [m0, m1, m2, m3];
        let (w, u, v) = (
            lanes4(|k| uvw[0][k]),
            lanes4(|k| uvw[1][k]),
            lanes4(|k| uvw[2][k]),
        );

        // The surface (`ShadeContext::surface`).
        let (p0, p1, p2) = (V3::of(pos[0]), V3::of(pos[1]), V3::of(pos[2]));
        let point = p0.scale(w).add(p1.scale(u)).add(p2.scale(v));
        let (e1, e2) = (p1.sub(p0), p2.sub(p0));
        // `cross` as `Vec3::cross` computes it.
        let face = V3 {
            x: e1.y * e2.z - e1.z * e2.y,
            y: e1.z * e2.x - e1.x * e2.z,
            z: e1.x * e2.y - e1.y * e2.x,
        };
        let ray_dir = V3::from_fn(|k| rays[k].dir);
        let dir = ray_dir.normalize_or_zero();
        let mut ng = face.normalize_or_zero();
        ng = V3::select(ng.is_zero(), dir.neg(), ng);
        let front = ng;
        let entering = ng.dot(dir).cmplt(Vec4::ZERO);
        ng = V3::select(entering, ng, ng.neg());
        let smooth = V3::of(nrm[0])
            .scale(w)
            .add(V3::of(nrm[1]).scale(u))
            .add(V3::of(nrm[2]).scale(v))
            .normalize_or_zero();
        let normals = BVec4A::new(
            has_normals[0],
            has_normals[1],
            has_normals[2],
            has_normals[3],
        );
        let smooth = V3::select(normals, smooth, V3::splat(Vec3A::ZERO));
        let mut ns = V3::select(smooth.is_zero() | !smooth.is_finite(), front, smooth);
        ns = V3::select(ns.dot(ng).cmplt(Vec4::ZERO), ns.neg(), ns);

        // Where the scalar model takes a maximum or a clamp, the lanes agree with it
        // for finite values only: a group with any other is shaded one by one.
        let finite = point.is_finite() & ns.is_finite() & ng.is_finite() & dir.is_finite();
        if finite.bitmask() != 0b1111 {
            return false;
        }

        // `eps`, the origin off the surface, the cone.
        let extent = Vec4::splat(1e-3 * self.extent);
        let a = V3 {
            x: point.x.abs(),
            y: point.y.abs(),
            z: point.z.abs(),
        };
        let eps = Vec4::splat(1e-4) * a.max_element().max(extent);
        let origin = point.add(ng.scale(eps));
        let length = (ray_dir.x * ray_dir.x + ray_dir.y * ray_dir.y + ray_dir.z * ray_dir.z).sqrt();
        let distance = lanes4(|k| t[k]) * length;
        let cone_width = lanes4(|k| items[k].cone.width);
        let spread = lanes4(|k| items[k].cone.spread);
        let width = cone_width + spread * distance;
        // A textured lane's material with its own base colour.
        let mut own = [None; 4];
        if textured.iter().any(Option::is_some) {
            let (face, ng_l, dir_l) = (face.lanes(), ng.lanes(), dir.lanes());
            for k in 0..4 {
                let Some(m) = textured[k] else {
                    continue;
                };
                let b = (uvw[0][k], uvw[1][k], uvw[2][k]);
                let base = self.textured_base(m, uvs[k], b, face[k], ng_l[k], dir_l[k], width[k]);
                match mats[k].with_albedo(base.truncate().into()) {
                    Some(p) => own[k] = Some(p),
                    None => return false,
                }
            }
        }
        for k in 0..4 {
            if let Some(p) = &own[k] {
                mats[k] = p;
            }
        }
        let mat = Mats::of(mats);
        // Times the opaque surface's coverage, 1, as `shade` multiplies it.
        let weight = V3::from_fn(|k| items[k].weight).scale(Vec4::ONE);

        // The lobes (`ShadeContext::lobes`, without textures or transmission).
        let view = dir.neg();
        let cos_o = clamp(ns.dot(view), 0.0, 1.0);
        let x = Vec4::ONE - cos_o;
        let x2 = x * x;
        let x5 = x * (x2 * x2);
        let fresnel = mat.f0.add(V3::splat(Vec3A::ONE).sub(mat.f0).scale(x5));
        let fmax = fresnel.max_element();
        let kd_polished = mat.diffuse * (Vec4::ONE - fmax);
        let kd_rough = mat.diffuse * (Vec4::ONE - fmax * mat.gloss) + mat.rough_metal;
        let kd = mat
            .albedo
            .scale(Vec4::select(mat.reflects, kd_polished, kd_rough));
        let kr = V3::select(mat.reflects, fresnel, V3::splat(Vec3A::ZERO));

        // The ambient term; no emission (a plain material emits nothing).
        let ambient_light = V3::splat(Vec3A::from(self.options.ambient));
        let added = weight.mul(V3::splat(Vec3A::ZERO).add(kd.mul(ambient_light)));

        // The mirror ray (`secondary`, without refraction or a glossy lobe).
        let kr_w = weight.mul(kr);
        let krmax = kr_w.max_element();
        let two = Vec4::splat(2.0);
        let mut r = reflect4(dir, ns, two);
        let under = r.dot(ng).cmple(Vec4::ZERO);
        r = V3::select(under, reflect4(dir, ng, two), r);

        // What the four calls would push, list by list: each list gets the hits' entries
        // in their order, as the four calls push them (no list is read between them), and
        // a light's shadow rays are pushed as it is shaded, not held for all the lights.
        let added_lanes = added.lanes();
        for k in 0..4 {
            let item = items[k];
            out.cover(item.sample, item.coverage * 1.0);
            let c = added_lanes[k];
            if c.cmpne(Vec3A::ZERO).any() & c.is_finite() {
                out.add.push((item.sample, c.into()));
            }
        }
        // Direct light, a light at a time (`ShadeContext::direct_light`), each lane's
        // shadow ray pushed as it is made.
        let samples = items.map(|i| i.sample);
        for (li, l) in self.lights.iter().enumerate() {
            self.light4(l, &mats, origin, ns, ng, view, kd, weight, li, samples, out);
        }
        let (origin, r, kr_w) = (origin.lanes(), r.lanes(), kr_w.lanes());
        let glossy = mats.iter().any(|m| m.glossy_alpha.is_some());
        let (ns_l, ng_l, dir_l) = if glossy {
            (ns.lanes(), ng.lanes(), dir.lanes())
        } else {
            ([Vec3A::ZERO; 4], [Vec3A::ZERO; 4], [Vec3A::ZERO; 4])
        };
        for k in 0..4 {
            let item = items[k];
            if item.depth >= max_depth || krmax[k] <= MIN_WEIGHT {
                continue;
            }
            // A mirror's reflection, or one drawn from the GGX lobe as `secondary`
            // draws it (the lane's vectors are the scalar model's to the bit).
            let (dir_k, w, spread_k) = match mats[k].glossy_alpha {
                None => (r[k], kr_w[k], spread[k]),
                Some(alpha) => {
                    match glossy_reflection(dir_l[k], ns_l[k], ng_l[k], alpha, item.seed, kr_w[k]) {
                        Some((r, w)) => (r, w, spread[k] + alpha),
                        None => continue,
                    }
                }
            };
            out.next(
                Ray::new(origin[k].into(), dir_k.into()),
                Item {
                    sample: item.sample,
                    weight: w.into(),
                    coverage: 0.0,
                    depth: item.depth + 1,
                    passes: item.passes,
                    bounces: item.bounces,
                    diffuse: false,
                    // As `secondary` derives it (kind 0: the reflection).
                    seed: if self.random {
                        item.seed.child(0)
                    } else {
                        item.seed
                    },
                    cone: super::Cone {
                        width: width[k],
                        spread: spread_k,
                    },
                    path: item.path.or(Some(LightPath::Specular)),
                },
            );
        }
        true
    }

    /// A textured hit's base colour, as `surface` and `shade` find it: the uv at
    /// barycentrics `(w, u, v)`, the level of detail from the cone's `width`, the
    /// triangle's `face` (unnormalised) and uv area, the normal `ng` facing the ray and
    /// the ray's unit `dir`; then the factor times the texture.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn textured_base(
        &self,
        m: &Material,
        uvs: Option<&[Vec2; 3]>,
        (w, u, v): (f32, f32, f32),
        face: Vec3A,
        ng: Vec3A,
        dir: Vec3A,
        width: f32,
    ) -> Vec4 {
        let uv = uvs.map_or(Vec2::ZERO, |t| t[0] * w + t[1] * u + t[2] * v);
        let lod = uvs.map_or(f32::NEG_INFINITY, |t| {
            level_of_detail(t, face, ng, dir, width)
        });
        self.base_color(m, uv, lod)
    }

    /// One light's shadow ray and contribution in each lane (`light_at` and
    /// `direct_light`'s body), pushed to `out` as light `li`'s for the lanes' samples,
    /// lane by lane; nothing where the light adds nothing.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn light4(
        &self,
        l: &PreLight,
        mats: &[&PlainMaterial; 4],
        origin: V3,
        ns: V3,
        ng: V3,
        view: V3,
        kd: V3,
        weight: V3,
        li: usize,
        samples: [u32; 4],
        out: &mut BlockOut,
    ) {
        let (to, dist, irradiance, there) = match l.kind {
            LightKind::Directional => (
                V3::splat(-Vec3A::from(l.direction)),
                Vec4::INFINITY,
                V3::splat(l.power.into()),
                BVec4A::splat(true),
            ),
            _ => {
                let d = V3::splat(l.position.into()).sub(origin);
                let d2 = d.dot(d);
                let there = d2.cmpgt(Vec4::ZERO) & d2.is_finite_mask();
                let dist = d2.sqrt();
                let mut att = match l.falloff {
                    Falloff::None => Vec4::ONE,
                    Falloff::InverseSquare => Vec4::ONE / d2,
                };
                let to = V3 {
                    x: d.x / dist,
                    y: d.y / dist,
                    z: d.z / dist,
                };
                if l.range.is_some() || matches!(l.kind, LightKind::Spot { .. }) {
                    att = shaped(l, att, dist, to);
                }
                (to, dist, V3::splat(l.power.into()).scale(att), there)
            }
        };
        let cos_i = ns.dot(to);
        let facing = there & cos_i.cmpgt(Vec4::ZERO) & ng.dot(to).cmpgt(Vec4::ZERO);
        if facing.bitmask() == 0 {
            return;
        }
        // The glint (`ShadeContext::glint`): the half vector in lanes; the power in
        // lanes where the four share a whole exponent (one material, or one roughness),
        // else a lane at a time (each chain of squarings stops early, as the scalar one
        // does).
        let h = to.add(view).normalize_or_zero();
        let nh = ns.dot(h);
        let s = mats[0].shininess;
        let whole = s as u32;
        let (glint, g) = if s > 0.0
            && whole as f32 == s
            && mats[1..]
                .iter()
                .all(|m| m.shininess.to_bits() == s.to_bits())
        {
            // `f32::max` and `min` as `Vec4`'s in these lanes: `nh` is never NaN where
            // it counts (a lane that is not facing is dropped) and `norm × lobe` is
            // finite, so the two agree.
            let lobe = powi4(nh.max(Vec4::ZERO), whole);
            let norm = lanes4(|k| mats[k].norm);
            let glint = (norm * lobe).min(Vec4::splat(1e3));
            (Vec4::select(facing, glint, Vec4::ZERO), facing)
        } else {
            let mut glint = [0.0f32; 4];
            let mut has_glint = [false; 4];
            for k in 0..4 {
                let m = mats[k];
                if m.shininess <= 0.0 || facing.bitmask() & (1 << k) == 0 {
                    continue;
                }
                let nh = nh[k].max(0.0);
                let whole = m.shininess as u32;
                let lobe = if whole as f32 == m.shininess {
                    powi(nh, whole)
                } else {
                    nh.powf(m.shininess)
                };
                glint[k] = (m.norm * lobe).min(1e3);
                has_glint[k] = true;
            }
            let g = BVec4A::new(has_glint[0], has_glint[1], has_glint[2], has_glint[3]);
            (lanes4(|k| glint[k]), g)
        };
        let brdf = kd.scale(Vec4::splat(std::f32::consts::FRAC_1_PI));
        let glints = V3 {
            x: Vec4::new(
                mats[0].glint.x,
                mats[1].glint.x,
                mats[2].glint.x,
                mats[3].glint.x,
            ),
            y: Vec4::new(
                mats[0].glint.y,
                mats[1].glint.y,
                mats[2].glint.y,
                mats[3].glint.y,
            ),
            z: Vec4::new(
                mats[0].glint.z,
                mats[1].glint.z,
                mats[2].glint.z,
                mats[3].glint.z,
            ),
        }
        .scale(glint);
        let brdf = V3::select(g, brdf.add(glints), brdf);
        let c = weight.mul(brdf).mul(irradiance).scale(cos_i);
        let cmax = c.max_element();
        let keep = facing & cmax.cmpgt(Vec4::splat(MIN_WEIGHT * 1e-2)) & c.is_finite();
        let far = dist * Vec4::splat(1.0 - 1e-4);
        let (origin, to, c) = (origin.lanes(), to.lanes(), c.lanes());
        for k in 0..4 {
            if keep.bitmask() & (1 << k) == 0 {
                continue;
            }
            let ray = if dist[k].is_finite() {
                Ray::segment(origin[k].into(), to[k].into(), 0.0, far[k])
            } else {
                Ray::new(origin[k].into(), to[k].into())
            };
            out.push_shadow(ray, li, (samples[k], c[k].into()));
        }
    }
}

/// `att` times a light's range window and spot cone (`light_at`'s factors, in its
/// order), for lanes at `dist` in direction `to` from it. Out of line: inlined, the
/// point light's path compiled 0.75 % more instructions a frame and shaded 11 % slower.
#[inline(never)]
fn shaped(l: &PreLight, mut att: Vec4, dist: Vec4, to: V3) -> Vec4 {
    if let Some(r) = l.range {
        // `(1 − (dist / r)⁴)` clamped, squared: `powi(4)` is `(q²)²` and `powi(2)` a
        // square, as LLVM expands them and compiler-rt computes them.
        let q = dist / Vec4::splat(r);
        let q2 = q * q;
        let w = clamp(Vec4::ONE - q2 * q2, 0.0, 1.0);
        att *= w * w;
    }
    if let Some((co, scale)) = cone(l) {
        let cd = V3::splat(l.direction.into()).dot(to.neg());
        let w = clamp((cd - Vec4::splat(co)) * Vec4::splat(scale), 0.0, 1.0);
        att *= w * w;
    }
    att
}

/// `reflect(d, n)`: `d − (2 (d·n)) n`.
fn reflect4(d: V3, n: V3, two: Vec4) -> V3 {
    d.sub(n.scale(two * d.dot(n)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gen::synth::Rng;
    use crate::render::camera::CameraModel;
    use crate::render::mips::TextureMips;
    use crate::render::options::ShadingOptions;
    use crate::render::sampling::Seed;
    use crate::scene::{Image, Light, Scene, Texture, TextureRef, TriangleSoup, UvTransform, Wrap};

    /// The crate's deterministic generator, with what these tests draw from it.
    trait Draw {
        fn pick<T: Copy>(&mut self, xs: &[T]) -> T;
        fn vec(&mut self, s: f32) -> Vec3;
        fn next(&mut self) -> u64;
    }

    impl Draw for Rng {
        fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
            xs[self.below(xs.len())]
        }
        fn vec(&mut self, s: f32) -> Vec3 {
            self.in_box(Vec3::splat(-s), Vec3::splat(s))
        }
        fn next(&mut self) -> u64 {
            self.next_u64()
        }
    }

    /// Every list of `out`, as bits.
    fn lists(out: &BlockOut) -> Vec<u32> {
        let mut v = Vec::new();
        let v3 = |v: &mut Vec<u32>, c: Vec3| v.extend(c.to_array().map(f32::to_bits));
        v.push(out.add.len() as u32);
        for &(s, c) in &out.add {
            v.push(s);
            v3(&mut v, c);
        }
        v.push(out.cover.len() as u32);
        for &(s, c) in &out.cover {
            v.extend([s, c.to_bits()]);
        }
        v.push(out.shadow.len() as u32);
        for l in &out.shadow {
            v.push(l.rays.len() as u32);
            for (r, &(s, c)) in l.rays.iter().zip(&l.add) {
                v.extend(r.bits());
                v.push(s);
                v3(&mut v, c);
            }
        }
        v.push(out.next_rays.len() as u32);
        for (r, i) in out.next_rays.iter().zip(&out.next_items) {
            v.extend(r.bits());
            v.extend(i.bits());
        }
        v
    }

    fn material(rng: &mut Rng) -> Material {
        let mut m = Material {
            base_color: Vec4::new(rng.f32(), rng.range(0.0, 1.5), rng.f32(), 1.0),
            // Polished (a mirror ray), rough (none) or glossy (a direction drawn from
            // the GGX lobe with the ray's seed; the frame's reflections then get
            // seeds of their own).
            roughness: rng.pick(&[0.0, 0.01, 0.4, 0.5, 0.9, 1.0, 0.2, 0.3]),
            metallic: rng.pick(&[0.0, 0.3, 1.0]),
            double_sided: rng.next().is_multiple_of(2),
            ..Material::default()
        };
        if rng.next().is_multiple_of(6) {
            m.emissive = Vec3::new(rng.f32(), rng.f32(), 0.0);
            m.emissive_strength = rng.range(0.5, 4.0);
        }
        if rng.next().is_multiple_of(8) {
            // Not a plain material: its groups are shaded one hit at a time.
            m.transmission = 0.5;
        }
        if rng.next().is_multiple_of(3) {
            // A base colour texture (the scene's texture 0), now and then through a
            // uv transform: the lanes take it, each hit with its own albedo.
            m.base_color_texture = Some(TextureRef {
                texture: 0,
                tex_coord: 0,
                transform: rng.next().is_multiple_of(2).then(|| UvTransform {
                    offset: Vec2::new(rng.f32(), rng.f32()),
                    rotation: rng.range(0.0, 3.0),
                    scale: Vec2::new(rng.range(0.5, 3.0), rng.range(0.5, 3.0)),
                }),
            });
        }
        m
    }

    /// A small random RGBA image as the scene's texture 0.
    fn texture(rng: &mut Rng, scene: &mut Scene) {
        let (w, h) = (1 + (rng.next() % 8) as u32, 1 + (rng.next() % 8) as u32);
        scene.images.push(Image {
            name: None,
            width: w,
            height: h,
            rgba8: (0..w * h * 4).map(|_| (rng.next() % 256) as u8).collect(),
        });
        scene.textures.push(Texture {
            image: 0,
            wrap_s: rng.pick(&[Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge]),
            wrap_t: rng.pick(&[Wrap::Repeat, Wrap::ClampToEdge]),
            nearest: rng.next().is_multiple_of(2),
        });
    }

    fn light(rng: &mut Rng) -> Light {
        let spot = LightKind::Spot {
            inner_cone_angle: rng.range(0.0, 0.5),
            outer_cone_angle: rng.range(0.5, 1.4),
        };
        let range = Some(rng.range(1.0, 6.0));
        Light {
            name: None,
            node: 0,
            kind: rng.pick(&[LightKind::Point, LightKind::Directional, spot]),
            color: Vec3::new(1.0, rng.f32(), rng.f32()),
            intensity: rng.range(0.5, 50.0),
            range: rng.pick(&[None, None, range]),
            falloff: rng.pick(&[Falloff::InverseSquare, Falloff::None]),
            position: rng.vec(3.0),
            direction: rng.vec(1.0).normalize_or(Vec3::NEG_Y),
        }
    }

    fn soup(rng: &mut Rng, n: usize, materials: u32, normals: bool, uvs: bool) -> TriangleSoup {
        let mut s = TriangleSoup::default();
        for k in 0..n {
            let a = rng.vec(2.0);
            let mut p = [a, a + rng.vec(0.5), a + rng.vec(0.5)];
            if k % 11 == 0 {
                p[2] = p[1]; // degenerate: the shading normal stands in
            }
            s.positions.push(p);
            if normals {
                let mut n = [rng.vec(1.0), rng.vec(1.0), rng.vec(1.0)];
                if k % 13 == 0 {
                    n = [Vec3::ZERO; 3];
                }
                s.normals.push(n);
            }
            if uvs {
                let a = Vec2::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
                let mut t = [
                    a,
                    a + Vec2::new(rng.f32(), rng.f32()),
                    a + Vec2::new(rng.f32(), rng.f32()),
                ];
                if k % 7 == 0 {
                    t[2] = t[1]; // no uv area: the finest level
                }
                s.uvs.push(t);
            }
            // Now and then a material out of range: the default one.
            s.material
                .push((rng.next() % (u64::from(materials) + 1)) as u32);
        }
        s
    }

    #[test]
    fn four_hits_at_once_push_what_four_calls_push() {
        let (mut took, mut groups, mut frames, mut random) = (0, 0, 0, 0);
        for seed in 1..=400u64 {
            let mut rng = Rng::new(seed);
            let mut scene = Scene::default();
            for _ in 0..1 + rng.next() % 5 {
                scene.materials.push(material(&mut rng));
            }
            let nm = scene.materials.len() as u32;
            texture(&mut rng, &mut scene);
            let statics = soup(&mut rng, 24, nm, true, true);
            let moving = soup(&mut rng, 16, nm, false, false);
            // Up to eight lights: the lanes take any number (each light's shadow rays
            // are pushed as it is shaded).
            let lights: Vec<Light> = (0..1 + rng.next() % 8).map(|_| light(&mut rng)).collect();
            let camera = CameraModel::framing(Vec3::splat(-2.0), Vec3::splat(2.0), 8, 8);
            let options = ShadingOptions {
                ambient: Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 0.2,
                default_light: false,
                ..ShadingOptions::default()
            };
            let mips = TextureMips::build(&scene);
            let ctx = ShadeContext::new(
                &scene, &statics, &moving, &lights, &camera, options, 5.0, &mips,
            );
            if !ctx.lanes {
                // An emissive material makes its triangles area lights, whose samples
                // draw random numbers: the frame is the scalar path's.
                assert!(
                    scene.materials.iter().any(|m| m.emissive != Vec3::ZERO),
                    "seed {seed}: the frame should take the lanes"
                );
                continue;
            }
            frames += 1;
            random += usize::from(ctx.random);
            for _ in 0..16 {
                let max_depth = rng.pick(&[0, 1, 2]);
                let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); 4];
                let mut items = [Item::NONE; 4];
                let mut hits = [None; 4];
                for k in 0..4 {
                    let dir = rng.vec(1.0) * rng.pick(&[1.0, 0.001, 7.0]);
                    rays[k] = Ray::new(rng.vec(3.0), dir);
                    let u = rng.f32();
                    let v = rng.range(0.0, 1.0 - u);
                    let tri = match rng.next() % 20 {
                        0 => 1000, // out of range
                        _ => (rng.next() % 40) as u32,
                    };
                    hits[k] = (!rng.next().is_multiple_of(25)).then_some(Hit {
                        t: rng.range(0.01, 10.0),
                        tri,
                        u,
                        v,
                    });
                    items[k] = Item {
                        sample: (rng.next() % 64) as u32,
                        weight: Vec3::new(rng.f32(), rng.f32(), rng.f32())
                            * rng.pick(&[1.0, 0.0, 1e-5]),
                        coverage: rng.pick(&[1.0, 0.0, 0.5]),
                        depth: rng.pick(&[0, 1, 2]),
                        passes: 0,
                        bounces: 0,
                        diffuse: rng.next().is_multiple_of(6),
                        seed: Seed(rng.next()),
                        cone: super::super::Cone {
                            width: rng.f32(),
                            spread: rng.f32() * 0.01,
                        },
                        path: rng.pick(&[None, Some(LightPath::Specular)]),
                    };
                }
                let (r4, i4) = (
                    [&rays[0], &rays[1], &rays[2], &rays[3]],
                    [&items[0], &items[1], &items[2], &items[3]],
                );
                let (mut four, mut one) = (BlockOut::default(), BlockOut::default());
                ctx.shade4(r4, i4, hits, max_depth, 1, &mut four);
                for k in 0..4 {
                    ctx.shade(&rays[k], &items[k], hits[k], max_depth, 1, &mut one);
                }
                assert_eq!(lists(&four), lists(&one), "seed {seed}");
                let mut scratch = BlockOut::default();
                groups += 1;
                if ctx.shade4_lanes(r4, i4, hits, max_depth, &mut scratch) {
                    took += 1;
                }
            }
        }
        // Most groups take the lanes (the others: a miss, a triangle out of range, a
        // transmissive material), some of them in frames that draw random numbers (a
        // glossy material, whose reflections the lanes draw).
        println!(
            "{frames} frames ({random} with random numbers), {took} of {groups} groups in lanes"
        );
        assert!(
            frames > 100 && random > 20 && took * 4 > groups,
            "{frames} frames ({random} random), {took} of {groups}"
        );
    }

    #[test]
    fn a_glossy_frame_takes_the_lanes_area_lights_and_bounces_do_not() {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            roughness: 0.2, // glossy: a random direction
            ..Material::default()
        });
        let soup = TriangleSoup::default();
        let camera = CameraModel::framing(Vec3::splat(-1.0), Vec3::ONE, 4, 4);
        let mips = TextureMips::build(&scene);
        let point = Light {
            name: None,
            node: 0,
            kind: LightKind::Point,
            color: Vec3::ONE,
            intensity: 1.0,
            range: None,
            falloff: Falloff::InverseSquare,
            position: Vec3::Y,
            direction: Vec3::NEG_Y,
        };
        let ctx = |scene: &Scene, lights: &[Light]| {
            ShadeContext::new(
                scene,
                &soup,
                &soup,
                lights,
                &camera,
                ShadingOptions::default(),
                1.0,
                &mips,
            )
            .lanes
        };
        // A glossy material's hits take the lanes, their reflections drawn lane by lane.
        assert!(ctx(&scene, std::slice::from_ref(&point)));
        let glossy = PlainMaterial::of(&scene.materials[0]).map(|p| p.glossy_alpha);
        assert_eq!(glossy, Some(Some(0.2 * 0.2)));
        scene.materials[0].roughness = 1.0;
        assert!(ctx(&scene, std::slice::from_ref(&point)));
        let rough = PlainMaterial::of(&scene.materials[0]).map(|p| p.glossy_alpha);
        assert_eq!(rough, Some(None));
        let spot = Light {
            kind: LightKind::Spot {
                inner_cone_angle: 0.1,
                outer_cone_angle: 0.5,
            },
            range: Some(3.0),
            ..point.clone()
        };
        assert!(ctx(&scene, &[spot, point.clone()]));
        assert!(ctx(&scene, &vec![point.clone(); 9]));
        assert!(ctx(&scene, &[]));
        // Diffuse bounces and area lights draw random numbers at every hit.
        let bounces = ShadingOptions {
            diffuse_bounces: 1,
            ..ShadingOptions::default()
        };
        let lights = std::slice::from_ref(&point);
        let with = |scene: &Scene, soup: &TriangleSoup, options: ShadingOptions| {
            let none = TriangleSoup::default();
            ShadeContext::new(scene, soup, &none, lights, &camera, options, 1.0, &mips).lanes
        };
        assert!(!with(&scene, &soup, bounces));
        scene.materials[0].emissive = Vec3::ONE;
        let mut emitter = TriangleSoup::default();
        emitter.positions.push([Vec3::ZERO, Vec3::X, Vec3::Y]);
        emitter.material.push(0);
        assert!(!with(&scene, &emitter, ShadingOptions::default()));
        assert!(with(&scene, &soup, ShadingOptions::default()));
    }
}
