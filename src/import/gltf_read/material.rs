//! Materials (metallic-roughness and the extensions we render), the textures they use
//! (with `KHR_texture_transform` and their `texCoord`), and the images behind those,
//! decoded to RGBA8 in parallel (PNG, JPEG, and WebP for `EXT_texture_webp`).

use glam::{Vec2, Vec3, Vec4};
use rayon::prelude::*;

use super::json;
use super::{ImportError, Importer};
use crate::scene::{AlphaMode, Image, Material, Texture, TextureRef, UvTransform, Wrap};

impl Importer<'_> {
    /// For each texture of the file, the image we decode for it: `EXT_texture_webp`'s
    /// when given, else `source`. A texture with neither (its image only in
    /// `KHR_texture_basisu`, say) is drawn without, warned.
    pub(super) fn texture_images(&mut self) -> Vec<Option<usize>> {
        let root = self.root;
        let mut out = Vec::with_capacity(root.textures.len());
        for (ti, t) in root.textures.iter().enumerate() {
            let ext = t.extensions.as_ref();
            let webp = ext.and_then(|e| e.webp.as_ref()).and_then(|w| w.source);
            let image = webp.or(t.source);
            if image.is_none() {
                let only = if ext.and_then(|e| e.basisu.as_ref()).is_some() {
                    " (its image is KTX2 / Basis Universal, KHR_texture_basisu, not decoded)"
                } else {
                    ""
                };
                self.warn(format!(
                    "textures[{ti}] has no image we can decode{only}; materials are drawn without it"
                ));
            }
            out.push(image);
        }
        out
    }

    fn texture_ref(
        &mut self,
        info: Option<&json::TextureInfo>,
        texture_images: &[Option<usize>],
        used: &mut Vec<usize>,
    ) -> Option<TextureRef> {
        let info = info?;
        let t = info.index?;
        texture_images.get(t).copied().flatten()?;
        let transform = info.extensions.as_ref().and_then(|e| e.transform.as_ref());
        let tex_coord = transform
            .and_then(|x| x.tex_coord)
            .unwrap_or(info.tex_coord);
        let transform = transform.map(|x| UvTransform {
            offset: Vec2::from_array(x.offset),
            rotation: x.rotation,
            scale: Vec2::from_array(x.scale),
        });
        // Remapped later to the compact list of textures actually used.
        let slot = used.iter().position(|&u| u == t).unwrap_or_else(|| {
            used.push(t);
            used.len() - 1
        });
        Some(TextureRef {
            texture: slot as u32,
            tex_coord,
            transform,
        })
    }

    pub(super) fn materials(
        &mut self,
        texture_images: &[Option<usize>],
    ) -> (Vec<Material>, Vec<usize>) {
        let mut used = Vec::new();
        let mut out = Vec::new();
        let mut occluded = Vec::new();
        let root = self.root;
        let default_pbr = json::Pbr::default();
        for (mi, m) in root.materials.iter().enumerate() {
            let pbr = m.pbr_metallic_roughness.as_ref().unwrap_or(&default_pbr);
            let base_color_texture =
                self.texture_ref(pbr.base_color_texture.as_ref(), texture_images, &mut used);
            let metallic_roughness_texture = self.texture_ref(
                pbr.metallic_roughness_texture.as_ref(),
                texture_images,
                &mut used,
            );
            let emissive_texture =
                self.texture_ref(m.emissive_texture.as_ref(), texture_images, &mut used);
            let normal_scale = m
                .normal_texture
                .as_ref()
                .and_then(|n| n.scale)
                .unwrap_or(1.0);
            let normal_texture =
                self.texture_ref(m.normal_texture.as_ref(), texture_images, &mut used);
            if m.occlusion_texture.is_some() {
                occluded.push(mi.to_string());
            }
            let ext = m.extensions.as_ref();
            let transmission = ext.and_then(|e| e.transmission.as_ref());
            if transmission.is_some_and(|t| t.transmission_texture.is_some()) {
                self.warn(format!(
                    "materials[{mi}]: transmission texture ignored (factor used)"
                ));
            }
            // `extras.ambient`: the colour the ambient light is reflected with (AFF's, as
            // subfield's writer puts it).
            let ambient = match m.extras.as_ref().and_then(|e| e.get("ambient")) {
                None => None,
                Some(v) => {
                    let rgb = v.as_array().and_then(|a| {
                        a.iter()
                            .map(|x| x.as_f64().map(|x| x as f32))
                            .collect::<Option<Vec<f32>>>()
                    });
                    match rgb.as_deref() {
                        Some(&[r, g, b])
                            if [r, g, b].iter().all(|x| x.is_finite() && *x >= 0.0) =>
                        {
                            Some(Vec3::new(r, g, b))
                        }
                        _ => {
                            self.warn(format!(
                                "materials[{mi}]: extras.ambient {v} is not three numbers of \
                                 at least 0; ignored"
                            ));
                            None
                        }
                    }
                }
            };
            out.push(Material {
                name: m.name.clone(),
                base_color: Vec4::from_array(pbr.base_color_factor),
                base_color_texture,
                metallic: pbr.metallic_factor,
                roughness: pbr.roughness_factor,
                metallic_roughness_texture,
                emissive: Vec3::from_array(m.emissive_factor),
                emissive_strength: ext
                    .and_then(|e| e.emissive_strength.as_ref())
                    .map_or(1.0, |e| e.emissive_strength),
                emissive_texture,
                normal_texture,
                normal_scale,
                transmission: transmission.map_or(0.0, |t| t.transmission_factor),
                ior: ext.and_then(|e| e.ior.as_ref()).map_or(1.5, |i| i.ior),
                double_sided: m.double_sided,
                alpha_mode: match m.alpha_mode.as_deref() {
                    Some("MASK") => AlphaMode::Mask {
                        cutoff: m.alpha_cutoff.unwrap_or(0.5),
                    },
                    Some("BLEND") => AlphaMode::Blend,
                    _ => AlphaMode::Opaque,
                },
                ambient,
            });
        }
        if !occluded.is_empty() {
            // Once for the file, naming every material that has one.
            self.warn(format!(
                "occlusionTexture is not supported and is ignored (materials {})",
                occluded.join(", ")
            ));
        }
        (out, used)
    }

    /// Builds the textures that materials use and decodes only the images behind them.
    pub(super) fn textures_and_images(
        &self,
        used: &[usize],
        texture_images: &[Option<usize>],
    ) -> Result<(Vec<Texture>, Vec<Image>), ImportError> {
        let root = self.root;
        let mut image_ids: Vec<usize> = Vec::new();
        let mut textures = Vec::new();
        for &t in used {
            let (Some(tex), Some(&Some(img))) = (root.textures.get(t), texture_images.get(t))
            else {
                continue; // texture_ref only hands out textures with an image
            };
            let slot = image_ids.iter().position(|&i| i == img).unwrap_or_else(|| {
                image_ids.push(img);
                image_ids.len() - 1
            });
            let wrap = |w: Option<u32>| match w {
                Some(33071) => Wrap::ClampToEdge,
                Some(33648) => Wrap::MirroredRepeat,
                _ => Wrap::Repeat,
            };
            let sampler = tex.sampler.and_then(|s| root.samplers.get(s));
            textures.push(Texture {
                image: slot as u32,
                wrap_s: wrap(sampler.and_then(|s| s.wrap_s)),
                wrap_t: wrap(sampler.and_then(|s| s.wrap_t)),
                nearest: sampler.and_then(|s| s.mag_filter) == Some(9728),
            });
        }
        // Gather the encoded bytes (sequential: reads files), decode in parallel.
        let mut encoded = Vec::with_capacity(image_ids.len());
        for &i in &image_ids {
            let Some(img) = root.images.get(i) else {
                continue;
            };
            let what = format!("images[{i}]");
            let err = |reason: String| ImportError::Image {
                path: self.path.to_path_buf(),
                image: i,
                reason,
            };
            let bytes = match (img.buffer_view, &img.uri) {
                (Some(v), _) => {
                    let view = root
                        .buffer_views
                        .get(v)
                        .ok_or_else(|| err(format!("bufferViews[{v}] missing")))?;
                    if let Some(Some(decoded)) = self.decoded_views.get(v) {
                        encoded.push((i, img.name.clone(), decoded.clone()));
                        continue;
                    }
                    let b = view.buffer.unwrap_or(usize::MAX);
                    let buf = self
                        .buffer_bytes(b)
                        .map_err(|why| err(format!("bufferViews[{v}]: {why}")))?;
                    let start = view.byte_offset;
                    start
                        .checked_add(view.byte_length.unwrap_or(0))
                        .and_then(|end| buf.get(start..end))
                        .ok_or_else(|| err(format!("bufferViews[{v}] lies outside buffers[{b}]")))?
                        .to_vec()
                }
                (None, Some(uri)) => self.load_uri(uri, &what)?,
                (None, None) => return Err(err("neither uri nor bufferView".into())),
            };
            encoded.push((i, img.name.clone(), bytes));
        }
        let images = encoded
            .into_par_iter()
            .map(|(i, name, bytes)| {
                let decoded = image::load_from_memory(&bytes).map_err(|e| ImportError::Image {
                    path: self.path.to_path_buf(),
                    image: i,
                    reason: e.to_string(),
                })?;
                let rgba = decoded.to_rgba8();
                Ok(Image {
                    name,
                    width: rgba.width(),
                    height: rgba.height(),
                    rgba8: rgba.into_raw(),
                })
            })
            .collect::<Result<Vec<_>, ImportError>>()?;
        Ok((textures, images))
    }
}
