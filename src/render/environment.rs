//! What rays see when they leave the scene: a constant background colour or an
//! equirectangular environment map (`--background`, `--environment`; DESIGN.md §4).
//!
//! The map's orientation is Blender's, so an HDRI lights and frames a glTF scene as it
//! does in Blender after the glTF importer's Y-up to Z-up turn: the image's centre column
//! looks along world +X, its quarter column (u = 0.25) along −Z, its top row straight up
//! (+Y), with u = 0.5 + atan2(d.z, d.x) / 2π and v (from the bottom) = 0.5 +
//! atan2(d.y, √(d.x² + d.z²)) / π. `--environment-rotation θ` turns the map by θ degrees
//! about +Y, counter-clockwise seen from above (a right-handed turn about +Y).
//! Lookups are bilinear, wrapping in u and clamping in v.

use std::path::{Path, PathBuf};

use glam::Vec3;

/// Why an environment map cannot be used; each names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EnvironmentError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: not an environment map subfield reads: {reason}", path.display())]
    Format { path: PathBuf, reason: String },
}

/// An equirectangular map of linear RGB radiance, turned and scaled as asked.
#[derive(Clone, Debug)]
pub struct EnvironmentMap {
    width: usize,
    height: usize,
    /// Row-major from the top row, linear RGB.
    texels: Vec<Vec3>,
    /// Turn about +Y in radians (cos, sin kept).
    rotation_deg: f32,
    cos: f32,
    sin: f32,
    intensity: f32,
    /// xxh3 of the file's bytes: names the map in the options string.
    hash: u64,
}

impl PartialEq for EnvironmentMap {
    fn eq(&self, other: &Self) -> bool {
        self.hash == other.hash
            && self.width == other.width
            && self.height == other.height
            && self.rotation_deg.to_bits() == other.rotation_deg.to_bits()
            && self.intensity.to_bits() == other.intensity.to_bits()
    }
}

impl EnvironmentMap {
    /// Reads an equirectangular `.hdr` (Radiance RGBE) or `.exr` (its first RGB(A) layer,
    /// linear) and keeps it turned by `rotation_deg` about +Y and scaled by `intensity`.
    pub fn load(
        path: &Path,
        rotation_deg: f32,
        intensity: f32,
    ) -> Result<EnvironmentMap, EnvironmentError> {
        let bytes = std::fs::read(path).map_err(|source| EnvironmentError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let format = |reason: String| EnvironmentError::Format {
            path: path.to_path_buf(),
            reason,
        };
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        let (width, height, texels) = match ext.as_str() {
            "hdr" => read_hdr(&bytes).map_err(format)?,
            "exr" => read_exr(&bytes).map_err(format)?,
            _ => {
                return Err(format(
                    "give an equirectangular .hdr (Radiance) or .exr file".into(),
                ))
            }
        };
        if width < 2 || height < 1 {
            return Err(format(format!(
                "{width}x{height} texels: an equirectangular map needs at least 2x1"
            )));
        }
        if let Some(bad) = texels
            .iter()
            .position(|t| !t.is_finite() || t.min_element() < 0.0)
        {
            return Err(format(format!(
                "texel ({}, {}) is {:?}: radiance must be finite and not negative",
                bad % width,
                bad / width,
                texels[bad].to_array()
            )));
        }
        Ok(EnvironmentMap::from_texels(
            width,
            height,
            texels,
            rotation_deg,
            intensity,
            xxhash_rust::xxh3::xxh3_64(&bytes),
        ))
    }

    /// A map from texels in memory (row-major from the top row, linear RGB); `hash`
    /// names it in the options string.
    pub fn from_texels(
        width: usize,
        height: usize,
        texels: Vec<Vec3>,
        rotation_deg: f32,
        intensity: f32,
        hash: u64,
    ) -> EnvironmentMap {
        assert_eq!(texels.len(), width * height, "one texel per pixel");
        let r = rotation_deg.to_radians();
        EnvironmentMap {
            width,
            height,
            texels,
            rotation_deg,
            cos: r.cos(),
            sin: r.sin(),
            intensity,
            hash,
        }
    }

    /// The radiance arriving from direction `dir` (need not be unit length).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        // Turning the map by θ about +Y is looking the direction up turned by −θ.
        let d = Vec3::new(
            self.cos * dir.x - self.sin * dir.z,
            dir.y,
            self.sin * dir.x + self.cos * dir.z,
        );
        let u = 0.5 + d.z.atan2(d.x) / std::f32::consts::TAU;
        let v = 0.5 + d.y.atan2(d.x.hypot(d.z)) / std::f32::consts::PI;
        if !(u.is_finite() && v.is_finite()) {
            return Vec3::ZERO;
        }
        // Texel centres at (i + 0.5) / W; rows from the top.
        let x = u * self.width as f32 - 0.5;
        let y = (1.0 - v) * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let w = self.width as i64;
        let h = self.height as i64;
        let col = |i: i64| i.rem_euclid(w) as usize;
        let row = |j: i64| j.clamp(0, h - 1) as usize;
        let (xa, xb) = (col(x0 as i64), col(x0 as i64 + 1));
        let (ya, yb) = (row(y0 as i64), row(y0 as i64 + 1));
        let t = |x: usize, y: usize| self.texels[y * self.width + x];
        let top = t(xa, ya) * (1.0 - fx) + t(xb, ya) * fx;
        let bottom = t(xa, yb) * (1.0 - fx) + t(xb, yb) * fx;
        (top * (1.0 - fy) + bottom * fy) * self.intensity
    }

    /// The map as the GPU frame path reads it (shade.wgsl's `env`): a header (width and
    /// height as u32 bits, the turn's cos and sin, the intensity, three zeros) and the
    /// texels' RGB, row-major from the top row.
    #[cfg(feature = "gpu")]
    pub(in crate::render) fn gpu_table(&self) -> Vec<f32> {
        let mut t = Vec::with_capacity(8 + 3 * self.texels.len());
        t.extend_from_slice(&[
            f32::from_bits(self.width as u32),
            f32::from_bits(self.height as u32),
            self.cos,
            self.sin,
            self.intensity,
            0.0,
            0.0,
            0.0,
        ]);
        t.extend(self.texels.iter().flat_map(|c| c.to_array()));
        t
    }

    /// Texels in all.
    #[cfg(feature = "gpu")]
    pub(in crate::render) fn texel_count(&self) -> usize {
        self.texels.len()
    }

    /// How the options string names the map: its bytes' hash, turn and scale.
    pub fn describe(&self) -> String {
        format!(
            "{:016x}/rotation:{}/intensity:{}",
            self.hash, self.rotation_deg, self.intensity
        )
    }
}

/// A Radiance `.hdr` file's pixels, through the `image` crate's reader.
fn read_hdr(bytes: &[u8]) -> Result<(usize, usize, Vec<Vec3>), String> {
    let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Hdr)
        .map_err(|e| e.to_string())?
        .into_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let texels = img.pixels().map(|p| Vec3::new(p[0], p[1], p[2])).collect();
    Ok((w, h, texels))
}

/// An OpenEXR file's first layer with R, G and B, through the `exr` crate.
fn read_exr(bytes: &[u8]) -> Result<(usize, usize, Vec<Vec3>), String> {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |resolution, _| {
                let (w, h) = (resolution.width(), resolution.height());
                (w, vec![Vec3::ZERO; w * h])
            },
            |(w, texels): &mut (usize, Vec<Vec3>), pos, (r, g, b): (f32, f32, f32)| {
                texels[pos.y() * *w + pos.x()] = Vec3::new(r, g, b);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| e.to_string())?;
    let (w, texels) = image.layer_data.channel_data.pixels;
    let h = texels.len().checked_div(w).unwrap_or(0);
    Ok((w, h, texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(rotation: f32) -> EnvironmentMap {
        // 8x4 texels, each its own colour: (column, row, 1).
        let texels = (0..32)
            .map(|i| Vec3::new((i % 8) as f32, (i / 8) as f32, 1.0))
            .collect();
        EnvironmentMap::from_texels(8, 4, texels, rotation, 1.0, 0)
    }

    /// The texel a direction looks up, by the convention in the module's comment: the
    /// centre of column c is u = (c + 0.5) / 8.
    fn at_texel_centre(u: f32, v: f32) -> Vec3 {
        let phi = (u - 0.5) * std::f32::consts::TAU;
        let theta = (v - 0.5) * std::f32::consts::PI;
        Vec3::new(
            theta.cos() * phi.cos(),
            theta.sin(),
            theta.cos() * phi.sin(),
        )
    }

    #[test]
    fn texel_centres_give_their_texel_and_the_axes_land_where_documented() {
        let m = map(0.0);
        for row in 0..4 {
            for col in 0..8 {
                let dir = at_texel_centre((col as f32 + 0.5) / 8.0, 1.0 - (row as f32 + 0.5) / 4.0);
                let got = m.radiance(dir);
                assert!(
                    (got - Vec3::new(col as f32, row as f32, 1.0))
                        .abs()
                        .max_element()
                        < 1e-3,
                    "texel ({col}, {row}): got {got}"
                );
            }
        }
        // +X looks at the centre column boundary u = 0.5 (between columns 3 and 4), −Z at
        // u = 0.25 (between 1 and 2), +Z at u = 0.75; straight up at the top row.
        assert!((m.radiance(Vec3::X).x - 3.5).abs() < 1e-4);
        assert!((m.radiance(Vec3::NEG_Z).x - 1.5).abs() < 1e-4);
        assert!((m.radiance(Vec3::Z).x - 5.5).abs() < 1e-4);
        assert_eq!(m.radiance(Vec3::Y).y, 0.0);
        assert_eq!(m.radiance(Vec3::NEG_Y).y, 3.0);
    }

    #[test]
    fn rotation_turns_the_map_about_y_counter_clockwise_from_above() {
        // Turned by 90°, what lay along +X now lies along −Z (counter-clockwise seen from
        // +Y turns +X towards −Z).
        let (plain, turned) = (map(0.0), map(90.0));
        for d in [
            Vec3::X,
            Vec3::new(1.0, 0.3, 0.2),
            Vec3::new(0.4, -0.2, -1.0),
        ] {
            let moved = Vec3::new(d.z, d.y, -d.x);
            let (a, b) = (plain.radiance(d), turned.radiance(moved));
            assert!((a - b).abs().max_element() < 1e-3, "{d}: {a} against {b}");
        }
    }

    #[test]
    fn intensity_scales_and_bad_directions_see_black() {
        let texels = vec![Vec3::new(1.0, 2.0, 3.0); 8];
        let m = EnvironmentMap::from_texels(4, 2, texels, 0.0, 2.5, 0);
        assert_eq!(
            m.radiance(Vec3::new(0.3, 0.1, 0.9)),
            Vec3::new(2.5, 5.0, 7.5)
        );
        assert_eq!(m.radiance(Vec3::splat(f32::NAN)), Vec3::ZERO);
    }

    #[test]
    fn files_round_trip_and_bad_files_name_themselves() {
        let dir = std::env::temp_dir().join(format!("subfield-env-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // A 4x2 HDR written with the image crate's encoder.
        let px: Vec<image::Rgb<f32>> = (0..8).map(|i| image::Rgb([i as f32, 0.5, 2.0])).collect();
        let hdr = dir.join("sky.hdr");
        let file = std::fs::File::create(&hdr).unwrap();
        image::codecs::hdr::HdrEncoder::new(file)
            .encode(&px, 4, 2)
            .unwrap();
        let m = EnvironmentMap::load(&hdr, 0.0, 1.0).unwrap();
        assert_eq!((m.width, m.height), (4, 2));
        assert_eq!(m.texels[5], Vec3::new(5.0, 0.5, 2.0));
        // The same texels as an EXR.
        let exr_path = dir.join("sky.exr");
        exr::prelude::write_rgb_file(&exr_path, 4, 2, |x, y| ((y * 4 + x) as f32, 0.5f32, 2.0f32))
            .unwrap();
        let e = EnvironmentMap::load(&exr_path, 0.0, 1.0).unwrap();
        assert_eq!(e.texels, m.texels);
        // Errors name the file.
        let bad = dir.join("sky.png");
        std::fs::write(&bad, b"x").unwrap();
        let msg = EnvironmentMap::load(&bad, 0.0, 1.0)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("sky.png") && msg.contains(".hdr"), "{msg}");
        let cut = dir.join("cut.hdr");
        std::fs::write(&cut, b"#?RADIANCE\n").unwrap();
        let msg = EnvironmentMap::load(&cut, 0.0, 1.0)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("cut.hdr"), "{msg}");
        let missing = EnvironmentMap::load(&dir.join("none.exr"), 0.0, 1.0).unwrap_err();
        assert!(missing.to_string().contains("none.exr"), "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
