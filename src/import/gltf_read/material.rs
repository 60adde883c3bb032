//! Materials (metallic-roughness and the extensions we render), the textures they use,
//! and the images behind those, decoded to RGBA8 in parallel.

use glam::{Vec3, Vec4};
use rayon::prelude::*;

use super::{ImportError, Importer};
use crate::scene::{AlphaMode, Image, Material, Texture, TextureRef, Wrap};

impl Importer<'_> {
    pub(super) fn texture_ref(
        &mut self,
        info: Option<gltf::texture::Info>,
        used: &mut Vec<usize>,
    ) -> Option<TextureRef> {
        let info = info?;
        let t = info.texture().index();
        if info.tex_coord() != 0 {
            self.warn(format!(
                "textures[{t}] uses TEXCOORD_{}; only TEXCOORD_0 is imported",
                info.tex_coord()
            ));
        }
        if info.texture_transform().is_some() {
            self.warn(format!("KHR_texture_transform on textures[{t}] is ignored"));
        }
        // Remapped later to the compact list of textures actually used.
        let slot = used.iter().position(|&u| u == t).unwrap_or_else(|| {
            used.push(t);
            used.len() - 1
        });
        Some(TextureRef {
            texture: slot as u32,
            tex_coord: info.tex_coord(),
        })
    }

    pub(super) fn materials(&mut self) -> (Vec<Material>, Vec<usize>) {
        let mut used = Vec::new();
        let mut out = Vec::new();
        let mut occluded = Vec::new();
        for m in self.doc.materials() {
            let pbr = m.pbr_metallic_roughness();
            let base_color_texture = self.texture_ref(pbr.base_color_texture(), &mut used);
            let metallic_roughness_texture =
                self.texture_ref(pbr.metallic_roughness_texture(), &mut used);
            let emissive_texture = self.texture_ref(m.emissive_texture(), &mut used);
            let normal = m.normal_texture();
            let normal_scale = normal.as_ref().map_or(1.0, |n| n.scale());
            let normal_texture = normal.and_then(|n| self.normal_ref(n, &mut used));
            if m.occlusion_texture().is_some() {
                occluded.push(m.index().unwrap_or(0).to_string());
            }
            if m.transmission()
                .and_then(|t| t.transmission_texture())
                .is_some()
            {
                self.warn(format!(
                    "materials[{}]: transmission texture ignored (factor used)",
                    m.index().unwrap_or(0)
                ));
            }
            out.push(Material {
                name: m.name().map(str::to_string),
                base_color: Vec4::from_array(pbr.base_color_factor()),
                base_color_texture,
                metallic: pbr.metallic_factor(),
                roughness: pbr.roughness_factor(),
                metallic_roughness_texture,
                emissive: Vec3::from_array(m.emissive_factor()),
                emissive_strength: m.emissive_strength().unwrap_or(1.0),
                emissive_texture,
                normal_texture,
                normal_scale,
                transmission: m.transmission().map_or(0.0, |t| t.transmission_factor()),
                ior: m.ior().unwrap_or(1.5),
                double_sided: m.double_sided(),
                alpha_mode: match m.alpha_mode() {
                    gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
                    gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                        cutoff: m.alpha_cutoff().unwrap_or(0.5),
                    },
                    gltf::material::AlphaMode::Blend => AlphaMode::Blend,
                },
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

    /// The slot of a material's `normalTexture` (as [`Self::texture_ref`] does for the
    /// other textures).
    fn normal_ref(
        &mut self,
        n: gltf::material::NormalTexture,
        used: &mut Vec<usize>,
    ) -> Option<TextureRef> {
        let t = n.texture().index();
        if n.tex_coord() != 0 {
            self.warn(format!(
                "textures[{t}] (a normal map) uses TEXCOORD_{}; only TEXCOORD_0 is imported",
                n.tex_coord()
            ));
        }
        let slot = used.iter().position(|&u| u == t).unwrap_or_else(|| {
            used.push(t);
            used.len() - 1
        });
        Some(TextureRef {
            texture: slot as u32,
            tex_coord: n.tex_coord(),
        })
    }

    /// Builds the textures that materials use and decodes only the images behind them.
    pub(super) fn textures_and_images(
        &self,
        used: &[usize],
    ) -> Result<(Vec<Texture>, Vec<Image>), ImportError> {
        let json = self.doc.as_json();
        let mut image_ids: Vec<usize> = Vec::new();
        let mut textures = Vec::new();
        for &t in used {
            let Some(tex) = self.doc.textures().nth(t) else {
                continue; // validated: cannot happen
            };
            let img = tex.source().index();
            let slot = image_ids.iter().position(|&i| i == img).unwrap_or_else(|| {
                image_ids.push(img);
                image_ids.len() - 1
            });
            let wrap = |w| match w {
                gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
                gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
                gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
            };
            let sampler = tex.sampler();
            textures.push(Texture {
                image: slot as u32,
                wrap_s: wrap(sampler.wrap_s()),
                wrap_t: wrap(sampler.wrap_t()),
                nearest: sampler.mag_filter() == Some(gltf::texture::MagFilter::Nearest),
            });
        }
        // Gather the encoded bytes (sequential: reads files), decode in parallel.
        let mut encoded = Vec::with_capacity(image_ids.len());
        for &i in &image_ids {
            let Some(img) = json.images.get(i) else {
                continue;
            };
            let what = format!("images[{i}]");
            let bytes = match (&img.buffer_view, &img.uri) {
                (Some(v), _) => {
                    let view =
                        self.doc
                            .views()
                            .nth(v.value())
                            .ok_or_else(|| ImportError::Image {
                                path: self.path.to_path_buf(),
                                image: i,
                                reason: "buffer view missing".into(),
                            })?;
                    let b = view.buffer().index();
                    let buf = self.buffers.get(b).map(Vec::as_slice).unwrap_or(&[]);
                    view.offset()
                        .checked_add(view.length())
                        .and_then(|end| buf.get(view.offset()..end))
                        .ok_or_else(|| ImportError::Image {
                            path: self.path.to_path_buf(),
                            image: i,
                            reason: format!("bufferViews[{}] lies outside buffers[{b}]", v.value()),
                        })?
                        .to_vec()
                }
                (None, Some(uri)) => self.load_uri(uri, &what)?,
                (None, None) => {
                    return Err(ImportError::Image {
                        path: self.path.to_path_buf(),
                        image: i,
                        reason: "neither uri nor bufferView".into(),
                    })
                }
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
