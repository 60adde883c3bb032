//! Files a render writes: EXR frames (one part, RGBA half or float plus float AOVs,
//! ZIP-compressed scan lines in increasing order, no time stamps: the same pixels give
//! the same bytes), the tone-mapped PNG preview, and the atomic write they share.

use std::path::Path;

use exr::prelude::{
    f16, read, AnyChannel, AnyChannels, Blocks, Compression, Encoding, FlatSamples, Image, Layer,
    LayerAttributes, LineOrder, ReadChannels, ReadLayers, SmallVec, Vec2, WritableImage,
};

use super::options::{Aovs, PixelType};
use super::shade::FrameBuffers;
use super::RenderError;

/// Channel names a frame with these settings has, sorted as EXR stores them.
pub fn channel_names(aovs: Aovs) -> Vec<&'static str> {
    let mut names = vec!["A", "B", "G", "R"];
    if aovs.depth {
        names.push("Z");
    }
    if aovs.normal {
        names.extend(["N.X", "N.Y", "N.Z"]);
    }
    if aovs.albedo {
        names.extend(["albedo.B", "albedo.G", "albedo.R"]);
    }
    names.sort_unstable();
    names
}

fn encoding() -> Encoding {
    Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    }
}

/// The EXR bytes of a frame.
pub fn encode_exr(fb: &FrameBuffers, pixel: PixelType) -> Result<Vec<u8>, exr::error::Error> {
    let n = fb.rgba.len();
    let rgba = |c: usize| -> FlatSamples {
        match pixel {
            PixelType::Half => {
                FlatSamples::F16(fb.rgba.iter().map(|p| f16::from_f32(p[c])).collect())
            }
            PixelType::Float => FlatSamples::F32(fb.rgba.iter().map(|p| p[c]).collect()),
        }
    };
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (c, name) in ["R", "G", "B", "A"].into_iter().enumerate() {
        list.push(AnyChannel::new(name, rgba(c)));
    }
    if let Some(z) = &fb.depth {
        list.push(AnyChannel::new("Z", FlatSamples::F32(z.clone())));
    }
    let vec3 =
        |list: &mut SmallVec<[AnyChannel<FlatSamples>; 4]>, v: &[[f32; 3]], names: [&str; 3]| {
            for (c, name) in names.into_iter().enumerate() {
                let s: Vec<f32> = v.iter().map(|p| p[c]).collect();
                list.push(AnyChannel::new(name, FlatSamples::F32(s)));
            }
        };
    if let Some(nrm) = &fb.normal {
        vec3(&mut list, nrm, ["N.X", "N.Y", "N.Z"]);
    }
    if let Some(alb) = &fb.albedo {
        vec3(&mut list, alb, ["albedo.R", "albedo.G", "albedo.B"]);
    }
    debug_assert!(list.iter().all(|c| c.sample_data.len() == n));
    let layer = Layer::new(
        (fb.width as usize, fb.height as usize),
        LayerAttributes::default(),
        encoding(),
        AnyChannels::sort(list),
    );
    let image = Image::from_layer(layer);
    let mut bytes = std::io::Cursor::new(Vec::with_capacity(n * 8));
    image.write().non_parallel().to_buffered(&mut bytes)?;
    Ok(bytes.into_inner())
}

/// Whether `path` is a complete EXR with this size and these channels: every block is
/// read and decompressed (a truncated or corrupt file is not complete).
pub fn is_complete(path: &Path, width: u32, height: u32, aovs: Aovs, pixel: PixelType) -> bool {
    if !path.is_file() {
        return false;
    }
    let Ok(img) = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .pedantic()
        .non_parallel()
        .from_file(path)
    else {
        return false;
    };
    let [layer] = img.layer_data.as_slice() else {
        return false;
    };
    if layer.size != Vec2(width as usize, height as usize) {
        return false;
    }
    let want = channel_names(aovs);
    let got = &layer.channel_data.list;
    got.len() == want.len()
        && got.iter().zip(&want).all(|(c, w)| {
            let ty = match (&c.sample_data, *w) {
                (FlatSamples::F16(_), "A" | "B" | "G" | "R") => pixel == PixelType::Half,
                (FlatSamples::F32(_), "A" | "B" | "G" | "R") => pixel == PixelType::Float,
                (FlatSamples::F32(_), _) => true,
                _ => false,
            };
            ty && c.name.to_string() == *w
        })
}

/// Writes `bytes` to `path` atomically (see [`crate::atomic::write_atomically`]).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), RenderError> {
    crate::atomic::write_atomically(path, bytes).map_err(|source| RenderError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Linear radiance → 8-bit sRGB, clamped (what an EXR viewer shows at exposure 0).
pub fn linear_to_srgb8(c: f32) -> u8 {
    let c = if c.is_finite() {
        c.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// The PNG bytes of a frame: RGB clamped and sRGB-encoded.
pub fn encode_preview(fb: &FrameBuffers) -> Result<Vec<u8>, image::ImageError> {
    let mut rgb = Vec::with_capacity(fb.rgba.len() * 3);
    for p in &fb.rgba {
        rgb.extend(p[..3].iter().map(|&c| linear_to_srgb8(c)));
    }
    let mut out = Vec::new();
    image::write_buffer_with_format(
        &mut std::io::Cursor::new(&mut out),
        &rgb,
        fb.width,
        fb.height,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(aovs: Aovs) -> FrameBuffers {
        let (w, h) = (5u32, 3u32);
        let n = (w * h) as usize;
        FrameBuffers {
            width: w,
            height: h,
            rgba: (0..n).map(|i| [i as f32 * 0.25, 0.5, 2.0, 1.0]).collect(),
            depth: aovs.depth.then(|| {
                (0..n)
                    .map(|i| if i == 3 { f32::INFINITY } else { i as f32 })
                    .collect()
            }),
            normal: aovs.normal.then(|| vec![[0.0, 1.0, 0.0]; n]),
            albedo: aovs.albedo.then(|| vec![[0.1, 0.2, 0.3]; n]),
        }
    }

    #[test]
    fn exr_round_trips_and_is_deterministic() {
        let aovs = Aovs {
            depth: true,
            normal: true,
            albedo: true,
        };
        let fb = frame(aovs);
        let a = encode_exr(&fb, PixelType::Half).unwrap();
        let b = encode_exr(&fb, PixelType::Half).unwrap();
        assert_eq!(a, b);
        let dir = std::env::temp_dir().join(format!("subfield-exr-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("f.exr");
        write_atomically(&p, &a).unwrap();
        assert!(is_complete(&p, 5, 3, aovs, PixelType::Half));
        assert!(!is_complete(&p, 5, 3, aovs, PixelType::Float));
        assert!(!is_complete(&p, 5, 4, aovs, PixelType::Half));
        assert!(!is_complete(&p, 5, 3, Aovs::default(), PixelType::Half));
        write_atomically(&p, &a[..a.len() - 7]).unwrap();
        assert!(!is_complete(&p, 5, 3, aovs, PixelType::Half));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn srgb_encoding() {
        assert_eq!(linear_to_srgb8(0.0), 0);
        assert_eq!(linear_to_srgb8(1.0), 255);
        assert_eq!(linear_to_srgb8(7.0), 255);
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        assert_eq!(linear_to_srgb8(0.215_86), 128);
    }
}
