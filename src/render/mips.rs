//! Mip-maps and filtered texture lookups. A texture's chain is built once per render
//! (before the first frame), level by level with a 2×2 box filter; colour textures are
//! averaged in linear light and stored sRGB-encoded again, data textures (metallic-
//! roughness, normal maps) as they are. Lookups are trilinear: bilinear in the two levels
//! around the level of detail `λ`, which the shading finds from the ray cone's width
//! at the hit (Akenine-Möller et al. 2021, "Improved Shader and Texture Level of Detail
//! Using Ray Cones").

use glam::{Vec2, Vec4};
use rayon::prelude::*;

use crate::scene::{Scene, Texture, Wrap};

/// One level below the image: RGBA8, rows top to bottom.
#[derive(Clone, Debug)]
struct Level {
    width: u32,
    height: u32,
    rgba8: Vec<u8>,
}

/// The reduced levels of one image in one colour space (level 0 is the image).
#[derive(Clone, Debug, Default)]
struct Chain {
    levels: Vec<Level>,
}

/// The chains of every texture a material uses, in both colour spaces it is used in.
#[derive(Clone, Debug)]
pub struct TextureMips {
    /// Per texture: (sRGB chain, linear chain).
    chains: Vec<(Option<Chain>, Option<Chain>)>,
    /// An sRGB byte's linear value (a fixed-size table: a lookup needs no bounds check).
    lut: Box<[f32; 256]>,
}

impl Default for TextureMips {
    /// No chains (the chains of a scene without textures), the sRGB table filled.
    fn default() -> TextureMips {
        TextureMips::build(&Scene::default())
    }
}

pub(super) fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

fn quantise(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

fn wrap(i: i64, n: i64, mode: Wrap) -> i64 {
    match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m >= n {
                2 * n - 1 - m
            } else {
                m
            }
        }
    }
}

/// `(wrap(i, n, mode), wrap(i + 1, n, mode))`, the two texels a bilinear lookup reads
/// along an axis, with at most one division (none for an `i` inside the image, the
/// common case): a trilinear lookup had made sixteen `i64` remainders, most of a
/// textured hit's shading (`benches/PERF.md`, issue 38, round 22).
#[inline(always)]
fn wrap2(i: i64, n: i64, mode: Wrap) -> (i64, i64) {
    let next = |a: i64, m: i64| if a + 1 == m { 0 } else { a + 1 };
    match mode {
        Wrap::Repeat => {
            let a = if (0..n).contains(&i) {
                i
            } else {
                i.rem_euclid(n)
            };
            (a, next(a, n))
        }
        Wrap::ClampToEdge => (i.clamp(0, n - 1), (i + 1).clamp(0, n - 1)),
        Wrap::MirroredRepeat => {
            let m = if (0..2 * n).contains(&i) {
                i
            } else {
                i.rem_euclid(2 * n)
            };
            let fold = |m: i64| if m >= n { 2 * n - 1 - m } else { m };
            (fold(m), fold(next(m, 2 * n)))
        }
    }
}

/// Half of `src` (`w × h`) in each direction (at least 1): each texel the mean of the
/// 2×2 block above it (the last row or column of an odd side is folded into its
/// neighbour's block), averaged in linear light when `srgb`.
fn reduce(src: &[u8], w: u32, h: u32, srgb: bool, lut: &[f32]) -> Level {
    let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
    let decode = |b: u8| {
        if srgb {
            lut[b as usize]
        } else {
            b as f32 / 255.0
        }
    };
    let mut out = vec![0u8; (nw * nh * 4) as usize];
    out.par_chunks_mut((nw * 4) as usize)
        .enumerate()
        .for_each(|(y, row)| {
            let y = y as u32;
            let ys = 2 * y..if y + 1 == nh { h } else { 2 * y + 2 };
            for x in 0..nw {
                let xs = 2 * x..if x + 1 == nw { w } else { 2 * x + 2 };
                let mut acc = [0.0f32; 4];
                let mut n = 0.0f32;
                for sy in ys.clone() {
                    for sx in xs.clone() {
                        let at = ((sy * w + sx) * 4) as usize;
                        for c in 0..3 {
                            acc[c] += decode(src[at + c]);
                        }
                        acc[3] += src[at + 3] as f32 / 255.0;
                        n += 1.0;
                    }
                }
                let px = &mut row[(x * 4) as usize..(x * 4 + 4) as usize];
                for c in 0..3 {
                    let m = acc[c] / n;
                    px[c] = quantise(if srgb { linear_to_srgb(m) } else { m });
                }
                px[3] = quantise(acc[3] / n);
            }
        });
    Level {
        width: nw,
        height: nh,
        rgba8: out,
    }
}

impl TextureMips {
    /// For each texture of `scene`, whether a material reads it in sRGB (the colour
    /// slots) and whether linearly (the others).
    pub(super) fn wanted(scene: &Scene) -> Vec<(bool, bool)> {
        let mut want = vec![(false, false); scene.textures.len()];
        for m in &scene.materials {
            for (slot, srgb) in [
                (m.base_color_texture, true),
                (m.emissive_texture, true),
                (m.metallic_roughness_texture, false),
                (m.normal_texture, false),
            ] {
                if let Some(w) = slot.and_then(|t| want.get_mut(t.texture as usize)) {
                    if srgb {
                        w.0 = true;
                    } else {
                        w.1 = true;
                    }
                }
            }
        }
        want
    }

    /// Chains for every texture the scene's materials use (colour slots in sRGB, the
    /// others linear); images of the wrong size are left without one.
    pub fn build(scene: &Scene) -> TextureMips {
        let lut: Box<[f32; 256]> =
            Box::new(std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)));
        let want = Self::wanted(scene);
        let chains = scene
            .textures
            .iter()
            .zip(want)
            .map(|(t, (s, l))| {
                let img = scene.images.get(t.image as usize);
                let chain = |srgb: bool| {
                    let img = img?;
                    let (mut w, mut h) = (img.width, img.height);
                    if w == 0 || h == 0 || img.rgba8.len() as u64 != u64::from(w) * u64::from(h) * 4
                    {
                        return None;
                    }
                    let mut levels: Vec<Level> = Vec::new();
                    while w > 1 || h > 1 {
                        let src = levels.last().map_or(&img.rgba8[..], |l| &l.rgba8[..]);
                        let next = reduce(src, w, h, srgb, &lut[..]);
                        (w, h) = (next.width, next.height);
                        levels.push(next);
                    }
                    Some(Chain { levels })
                };
                (
                    if s { chain(true) } else { None },
                    if l { chain(false) } else { None },
                )
            })
            .collect();
        TextureMips { chains, lut }
    }

    /// Number of levels of texture `t`'s chain (the image included); 1 without a chain.
    pub fn levels(&self, t: usize, srgb: bool) -> usize {
        self.chain(t, srgb).map_or(1, |c| c.levels.len() + 1)
    }

    /// Level `i` (1 the first below the image) of texture `t`'s chain in the colour
    /// space `srgb` picks: its RGBA8 texels, width and height (for the GPU frame path,
    /// which uploads the chains).
    #[cfg(feature = "gpu")]
    pub(super) fn level(&self, t: usize, srgb: bool, i: usize) -> Option<(&[u8], u32, u32)> {
        let l = self.chain(t, srgb)?.levels.get(i.checked_sub(1)?)?;
        Some((&l.rgba8, l.width, l.height))
    }

    /// The sRGB decoding table lookups use (byte to linear value).
    #[cfg(feature = "gpu")]
    pub(super) fn srgb_table(&self) -> &[f32] {
        &self.lut[..]
    }

    fn chain(&self, t: usize, srgb: bool) -> Option<&Chain> {
        let c = self.chains.get(t)?;
        if srgb {
            c.0.as_ref()
        } else {
            c.1.as_ref()
        }
    }

    /// Texture `t` (as `tex`, image `base` of `width × height`) at `uv`, filtered at
    /// level of detail `lod` (0 the image; fractional levels blend the two around it;
    /// below 0 and without a chain, the image alone). RGB linearised when `srgb`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn lookup(
        &self,
        t: usize,
        tex: &Texture,
        base: &[u8],
        width: u32,
        height: u32,
        uv: Vec2,
        lod: f32,
        srgb: bool,
    ) -> Vec4 {
        let chain = self.chain(t, srgb);
        let top = chain.map_or(0, |c| c.levels.len());
        let level = |i: usize| -> (&[u8], u32, u32) {
            match i.checked_sub(1).and_then(|j| chain?.levels.get(j)) {
                Some(l) => (&l.rgba8, l.width, l.height),
                None => (base, width, height),
            }
        };
        let lod = if lod.is_finite() { lod } else { 0.0 };
        if lod <= 0.0 || top == 0 {
            let (d, w, h) = level(0);
            return self.bilinear(tex, d, w, h, uv, srgb, tex.nearest && lod <= 0.0);
        }
        let lod = lod.min(top as f32);
        let l0 = lod.floor() as usize;
        let f = lod - l0 as f32;
        let (d, w, h) = level(l0);
        let a = self.bilinear(tex, d, w, h, uv, srgb, false);
        if f <= 0.0 || l0 >= top {
            return a;
        }
        let (d, w, h) = level(l0 + 1);
        a.lerp(self.bilinear(tex, d, w, h, uv, srgb, false), f)
    }

    #[allow(clippy::too_many_arguments)]
    fn bilinear(
        &self,
        tex: &Texture,
        data: &[u8],
        w: u32,
        h: u32,
        uv: Vec2,
        srgb: bool,
        nearest: bool,
    ) -> Vec4 {
        let (w, h) = (i64::from(w), i64::from(h));
        let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
        // Texel `(x, y)`, both wrapped already.
        let fetch = |x: i64, y: i64| -> Vec4 {
            let at = ((y * w + x) * 4) as usize;
            match data.get(at..at + 4) {
                Some(p) => {
                    let c = |b: u8| {
                        if srgb {
                            self.lut[b as usize]
                        } else {
                            b as f32 / 255.0
                        }
                    };
                    Vec4::new(c(p[0]), c(p[1]), c(p[2]), p[3] as f32 / 255.0)
                }
                None => Vec4::ONE,
            }
        };
        let x = f64::from(uv.x) * w as f64;
        let y = f64::from(uv.y) * h as f64;
        if nearest {
            return fetch(
                wrap(x.floor() as i64, w, tex.wrap_s),
                wrap(y.floor() as i64, h, tex.wrap_t),
            );
        }
        let (x, y) = (x - 0.5, y - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, x1) = wrap2(x0 as i64, w, tex.wrap_s);
        let (y0, y1) = wrap2(y0 as i64, h, tex.wrap_t);
        let top = fetch(x0, y0).lerp(fetch(x1, y0), fx);
        let bottom = fetch(x0, y1).lerp(fetch(x1, y1), fx);
        top.lerp(bottom, fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Image, Material, TextureRef};

    #[test]
    fn chain_averages_in_linear_light_down_to_one_texel() {
        // A 4×2 checker of sRGB 255 / 0: its last level is the linear mean 0.5, which
        // sRGB-encodes to 188 (not 128, the mean of the encoded bytes).
        let mut rgba8 = Vec::new();
        for i in 0..8 {
            let v = if (i + i / 4) % 2 == 0 { 255 } else { 0 };
            rgba8.extend([v, v, v, 255]);
        }
        let scene = Scene {
            images: vec![Image {
                name: None,
                width: 4,
                height: 2,
                rgba8,
            }],
            textures: vec![Texture {
                image: 0,
                wrap_s: Wrap::Repeat,
                wrap_t: Wrap::Repeat,
                nearest: false,
            }],
            materials: vec![Material {
                base_color_texture: Some(TextureRef {
                    texture: 0,
                    tex_coord: 0,
                    transform: None,
                }),
                ..Material::default()
            }],
            ..Scene::default()
        };
        let mips = TextureMips::build(&scene);
        assert_eq!(mips.levels(0, true), 3, "4×2, 2×1, 1×1");
        assert_eq!(mips.levels(0, false), 1, "no linear use, no linear chain");
        let last = &mips.chains[0].0.as_ref().unwrap().levels[1];
        assert_eq!((last.width, last.height), (1, 1));
        assert_eq!(last.rgba8[0], 188);
        let img = &scene.images[0];
        let at = |lod: f32| {
            mips.lookup(
                0,
                &scene.textures[0],
                &img.rgba8,
                4,
                2,
                Vec2::new(0.125, 0.25),
                lod,
                true,
            )
        };
        assert!((at(0.0).x - 1.0).abs() < 1e-6, "level 0 is the texel");
        assert!((at(5.0).x - 0.5).abs() < 0.01, "the top level is the mean");
        let mid = at(1.5).x;
        assert!(mid > 0.4 && mid < 0.6, "trilinear blend {mid}");
    }

    #[test]
    fn wrap_pairs_are_two_wraps() {
        for mode in [Wrap::Repeat, Wrap::ClampToEdge, Wrap::MirroredRepeat] {
            for n in 1..7 {
                for i in -40..40 {
                    assert_eq!(
                        wrap2(i, n, mode),
                        (wrap(i, n, mode), wrap(i + 1, n, mode)),
                        "{mode:?} i={i} n={n}"
                    );
                }
                // Far from the image, as a coordinate of a huge uv is.
                for i in [i64::MIN / 4, -(1 << 40) - 3, 1 << 40, i64::MAX / 4] {
                    assert_eq!(
                        wrap2(i, n, mode),
                        (wrap(i, n, mode), wrap(i + 1, n, mode)),
                        "{mode:?} i={i} n={n}"
                    );
                }
            }
        }
    }

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        assert_eq!(wrap(5, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap(9, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap(8, 4, Wrap::MirroredRepeat), 0);
    }
}
