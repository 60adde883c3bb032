//! Files a render writes: EXR frames (one part, RGBA half or float plus float AOVs,
//! ZIP-compressed scan lines in increasing order, no time stamps: the same pixels give
//! the same bytes), the tone-mapped PNG preview, and the atomic write they share.

use std::path::Path;

use exr::meta::attribute::{AttributeValue, Text};
use exr::prelude::{
    f16, read, AnyChannel, AnyChannels, Blocks, Compression, Encoding, FlatSamples, Image, Layer,
    LayerAttributes, LineOrder, ReadChannels, ReadLayers, SmallVec, Vec2, WritableImage,
};

use super::aov::{crypto_key, fps_rational, FrameHeader};
use super::options::{Aovs, ExrCompression, PixelType};
use super::shade::{FrameBuffers, LightPath};

/// The header attribute holding [`RenderOptions::options_string`](super::RenderOptions).
pub const OPTIONS_ATTRIBUTE: &str = "subfield/options";

/// The `software` attribute of every frame.
pub fn software() -> String {
    format!("subfield {}", env!("CARGO_PKG_VERSION"))
}

/// Channel names a frame with these settings has, sorted as EXR stores them.
pub fn channel_names(aovs: Aovs) -> Vec<String> {
    let mut names: Vec<String> = ["A", "B", "G", "R"].map(String::from).to_vec();
    let mut add = |list: &[&str]| names.extend(list.iter().map(|s| s.to_string()));
    if aovs.depth {
        add(&["Z"]);
    }
    if aovs.normal {
        add(&["N.X", "N.Y", "N.Z"]);
    }
    if aovs.albedo {
        add(&["albedo.B", "albedo.G", "albedo.R"]);
    }
    if aovs.position {
        add(&["P.X", "P.Y", "P.Z"]);
    }
    if aovs.motion {
        add(&["motion.X", "motion.Y"]);
    }
    for (on, pass) in aovs.light_paths().into_iter().zip(LightPath::ALL) {
        if on {
            for c in ["R", "G", "B"] {
                names.push(format!("{}.{c}", pass.name()));
            }
        }
    }
    for layer in crypto_layer_names(aovs) {
        for c in ["R", "G", "B", "A"] {
            names.push(format!("{layer}.{c}"));
        }
    }
    names.sort_unstable();
    names
}

/// `CryptoObject00…` then `CryptoMaterial00…`, as many of each as the levels need.
fn crypto_layer_names(aovs: Aovs) -> Vec<String> {
    let n = aovs.crypto_layers();
    ["CryptoObject", "CryptoMaterial"]
        .iter()
        .flat_map(|kind| (0..n).map(move |k| format!("{kind}{k:02}")))
        .collect()
}

/// What the `exr` crate writes for `compression`: ZIP is written uncompressed, then
/// ZIP-compressed sixteen lines a block by
/// [`zip_scanlines`](super::exr_zip::zip_scanlines); PIZ by the crate itself.
fn encoding(compression: ExrCompression) -> Encoding {
    Encoding {
        compression: match compression {
            ExrCompression::Zip | ExrCompression::None => Compression::Uncompressed,
            ExrCompression::Piz => Compression::PIZ,
        },
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    }
}

/// A channel with its `pLinear` flag set on purpose: `true` for colour in linear light
/// (R, G, B, albedo.*), `false` for data (A, Z, N, P, motion, Cryptomatte ids and
/// coverages), which lossy codecs must not treat as perceptual colour. (The `exr`
/// crate's guess by name would flag A, N.* and albedo.* but not R, G, B or Z.)
fn channel(name: &str, samples: FlatSamples, linear: bool) -> AnyChannel<FlatSamples> {
    let mut c = AnyChannel::new(name, samples);
    c.quantize_linearly = linear;
    c
}

/// An attribute text from UTF-8 (OpenEXR strings are bytes; names may be any UTF-8).
fn text(s: &str) -> Text {
    Text::from_slice_unchecked(s.as_bytes())
}

/// The colour space of every frame's RGB: linear, Rec.709 (sRGB) primaries, D65 white
/// (the `chromaticities` attribute, DESIGN.md §4), which is what the renderer's linear
/// RGB and every glTF colour are.
pub const REC709_D65: exr::meta::attribute::Chromaticities = exr::meta::attribute::Chromaticities {
    red: exr::math::Vec2(0.64, 0.33),
    green: exr::math::Vec2(0.30, 0.60),
    blue: exr::math::Vec2(0.15, 0.06),
    white: exr::math::Vec2(0.3127, 0.3290),
};

/// The header attribute naming the colour space (OpenEXR 3.4's `colorInteropID`).
pub const COLOR_INTEROP_ATTRIBUTE: &str = "colorInteropID";
/// Its value for every frame: the Color Interop Forum's id of linear Rec.709
/// primaries, D65 white, scene-referred (what `chromaticities` says in numbers).
pub const COLOR_INTEROP_ID: &str = "lin_rec709_scene";

/// The header attributes of a frame (see DESIGN.md §4): `framesPerSecond`,
/// `worldToCamera`, `worldToNDC`, `software`, `subfield/options` and the Cryptomatte
/// metadata. No time stamps.
fn layer_attributes(header: &FrameHeader) -> LayerAttributes {
    let mut a = LayerAttributes {
        frames_per_second: Some(fps_rational(header.fps)),
        world_to_camera: Some(header.world_to_camera),
        world_to_normalized_device: Some(header.world_to_ndc),
        software_name: Some(text(&software())),
        ..Default::default()
    };
    a.other.insert(
        text(OPTIONS_ATTRIBUTE),
        AttributeValue::Text(text(&header.options)),
    );
    // The colour space by name as well, as the ASWF Color Interop Forum's recommendation
    // for OpenEXR (read by OpenEXR 3.4 and later) spells it: the same space as
    // `chromaticities`, scene-referred linear Rec.709.
    a.other.insert(
        text(COLOR_INTEROP_ATTRIBUTE),
        AttributeValue::Text(text(COLOR_INTEROP_ID)),
    );
    if let Some(c) = &header.crypto {
        for kind in [&c.object, &c.material] {
            let key = crypto_key(kind.layer);
            let mut put = |field: &str, value: &str| {
                a.other.insert(
                    text(&format!("cryptomatte/{key}/{field}")),
                    AttributeValue::Text(text(value)),
                );
            };
            put("name", kind.layer);
            put("hash", "MurmurHash3_32");
            put("conversion", "uint32_to_float32");
            put("manifest", &kind.manifest);
        }
    }
    a
}

/// Sorts the attributes of a single-part EXR's header by name, in place. The `exr`
/// crate writes custom attributes in a hash map's order, which changes from run to
/// run; sorted, the same frame gives the same bytes. The header keeps its length, so
/// the offset table after it stays valid.
fn sort_header_attributes(bytes: &mut [u8]) {
    let mut at = 8; // magic number and version
    let mut attrs: Vec<(usize, usize)> = Vec::new();
    let cstr = |b: &[u8], from: usize| b[from..].iter().position(|&c| c == 0).map(|n| from + n);
    loop {
        let Some(name_end) = cstr(bytes, at) else {
            return;
        };
        if name_end == at {
            break; // the empty name ends the header
        }
        let Some(type_end) = cstr(bytes, name_end + 1) else {
            return;
        };
        let Some(size) = bytes.get(type_end + 1..type_end + 5) else {
            return;
        };
        let size = i32::from_le_bytes([size[0], size[1], size[2], size[3]]);
        let end = type_end + 5 + size.max(0) as usize;
        if end > bytes.len() {
            return;
        }
        attrs.push((at, end));
        at = end;
    }
    let Some(&(first, _)) = attrs.first() else {
        return;
    };
    let name = |&(a, _): &(usize, usize)| {
        let e = cstr(bytes, a).unwrap_or(a);
        &bytes[a..e]
    };
    let mut sorted = attrs.clone();
    sorted.sort_by(|x, y| name(x).cmp(name(y)));
    let mut out = Vec::with_capacity(at - first);
    for &(a, e) in &sorted {
        out.extend_from_slice(&bytes[a..e]);
    }
    bytes[first..at].copy_from_slice(&out);
}

/// The EXR bytes of a frame: its data window is the buffers (the image and the
/// overscan border, from `−overscan`), its display window the image.
pub fn encode_exr(
    fb: &FrameBuffers,
    pixel: PixelType,
    compression: ExrCompression,
    header: &FrameHeader,
) -> Result<Vec<u8>, exr::error::Error> {
    let n = fb.rgba.len();
    let rgba = |c: usize| -> FlatSamples {
        match pixel {
            PixelType::Half => {
                FlatSamples::F16(fb.rgba.iter().map(|p| f16::from_f32(p[c])).collect())
            }
            PixelType::Float => FlatSamples::F32(fb.rgba.iter().map(|p| p[c]).collect()),
        }
    };
    type List = SmallVec<[AnyChannel<FlatSamples>; 4]>;
    let mut list: List = SmallVec::new();
    for (c, name) in ["R", "G", "B", "A"].into_iter().enumerate() {
        list.push(channel(name, rgba(c), name != "A"));
    }
    if let Some(z) = &fb.depth {
        list.push(channel("Z", FlatSamples::F32(z.clone()), false));
    }
    fn split<const K: usize>(list: &mut List, v: &[[f32; K]], names: [&str; K], linear: bool) {
        for (c, name) in names.into_iter().enumerate() {
            let s: Vec<f32> = v.iter().map(|p| p[c]).collect();
            list.push(channel(name, FlatSamples::F32(s), linear));
        }
    }
    if let Some(nrm) = &fb.normal {
        split(&mut list, nrm, ["N.X", "N.Y", "N.Z"], false);
    }
    if let Some(alb) = &fb.albedo {
        split(&mut list, alb, ["albedo.R", "albedo.G", "albedo.B"], true);
    }
    if let Some(p) = &fb.position {
        split(&mut list, p, ["P.X", "P.Y", "P.Z"], false);
    }
    if let Some(m) = &fb.motion {
        split(&mut list, m, ["motion.X", "motion.Y"], false);
    }
    if let Some(lp) = &fb.light_paths {
        for ((pass, data), on) in LightPath::ALL.iter().zip(&lp.passes).zip(lp.written) {
            if on {
                let names = ["R", "G", "B"].map(|c| format!("{}.{c}", pass.name()));
                split(&mut list, data, names.each_ref().map(String::as_str), true);
            }
        }
    }
    if let Some(c) = &fb.crypto {
        for (kind, ranks) in [("CryptoObject", &c.object), ("CryptoMaterial", &c.material)] {
            for layer in 0..c.levels.div_ceil(2) {
                let at = |pixel: usize, r: usize| {
                    let k = 2 * layer + r;
                    if k < c.levels {
                        ranks[pixel * c.levels + k]
                    } else {
                        (0.0, 0.0)
                    }
                };
                let chan = |f: &dyn Fn(usize) -> f32| -> FlatSamples {
                    FlatSamples::F32((0..n).map(f).collect())
                };
                let name = |ch: &str| format!("{kind}{layer:02}.{ch}");
                list.push(channel(&name("R"), chan(&|i| at(i, 0).0), false));
                list.push(channel(&name("G"), chan(&|i| at(i, 0).1), false));
                list.push(channel(&name("B"), chan(&|i| at(i, 1).0), false));
                list.push(channel(&name("A"), chan(&|i| at(i, 1).1), false));
            }
        }
    }
    debug_assert!(list.iter().all(|c| c.sample_data.len() == n));
    let (dw, dh) = fb.data_size();
    let mut attributes = layer_attributes(header);
    let o = i32::try_from(fb.overscan)
        .map_err(|_| exr::error::Error::Invalid("overscan too large".into()))?;
    attributes.layer_position = Vec2(-o, -o);
    let layer = Layer::new(
        (dw as usize, dh as usize),
        attributes,
        encoding(compression),
        AnyChannels::sort(list),
    );
    let mut image = Image::from_layer(layer);
    image.attributes.chromaticities = Some(REC709_D65);
    image.attributes.display_window = exr::meta::attribute::IntegerBounds::new(
        Vec2(0, 0),
        Vec2(fb.width as usize, fb.height as usize),
    );
    let mut bytes = std::io::Cursor::new(Vec::with_capacity(n * 8));
    // Not parallel: the writer thread must not queue work on the render's pool (see
    // `exr_zip`), and PIZ's blocks through the crate are the only ones it compresses.
    image.write().non_parallel().to_buffered(&mut bytes)?;
    let mut bytes = bytes.into_inner();
    sort_header_attributes(&mut bytes);
    match compression {
        ExrCompression::Zip => super::exr_zip::zip_scanlines(&bytes)
            .map_err(|e| exr::error::Error::Invalid(e.to_string().into())),
        ExrCompression::Piz | ExrCompression::None => Ok(bytes),
    }
}

/// What a resumed run finds where a frame goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FrameFile {
    /// No regular file there.
    Missing,
    /// Not a whole EXR: cut short, corrupt, or unreadable.
    Incomplete,
    /// A whole EXR made with other options: another options string (see
    /// [`RenderOptions::options_string`](super::RenderOptions::options_string)), size,
    /// channels or pixel type, or none of ours.
    OtherOptions,
    /// A whole EXR of this size, these channels and these options.
    Complete,
}

/// Whether `path` is a complete EXR with this size, these channels and this options
/// string (`subfield/options`, see
/// [`RenderOptions::options_string`](super::RenderOptions::options_string)): every
/// block is read and decompressed (a truncated or corrupt file is not complete), and a
/// frame made with other options is not this run's. `width` and `height` are the data
/// window's: the image's plus twice the `--overscan`.
pub fn is_complete(
    path: &Path,
    width: u32,
    height: u32,
    aovs: Aovs,
    pixel: PixelType,
    options: &str,
) -> bool {
    frame_file(path, width, height, aovs, pixel, options) == FrameFile::Complete
}

/// What is at `path` for a frame of this size (the data window's), these channels and
/// this options string:
/// [`is_complete`] that also tells a whole frame made with other options from a broken
/// or missing one.
pub fn frame_file(
    path: &Path,
    width: u32,
    height: u32,
    aovs: Aovs,
    pixel: PixelType,
    options: &str,
) -> FrameFile {
    if !path.is_file() {
        return FrameFile::Missing;
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
        return FrameFile::Incomplete;
    };
    let [layer] = img.layer_data.as_slice() else {
        return FrameFile::OtherOptions;
    };
    if layer.size != Vec2(width as usize, height as usize) {
        return FrameFile::OtherOptions;
    }
    let key = text(OPTIONS_ATTRIBUTE);
    let stored = layer
        .attributes
        .other
        .get(&key)
        .or_else(|| img.attributes.other.get(&key));
    match stored {
        Some(AttributeValue::Text(t)) if t.bytes() == options.as_bytes() => {}
        _ => return FrameFile::OtherOptions,
    }
    let want = channel_names(aovs);
    let got = &layer.channel_data.list;
    let same = got.len() == want.len()
        && got.iter().zip(&want).all(|(c, w)| {
            let ty = match (&c.sample_data, w.as_str()) {
                (FlatSamples::F16(_), "A" | "B" | "G" | "R") => pixel == PixelType::Half,
                (FlatSamples::F32(_), "A" | "B" | "G" | "R") => pixel == PixelType::Float,
                (FlatSamples::F32(_), _) => true,
                _ => false,
            };
            ty && c.name.bytes() == w.as_bytes()
        });
    if same {
        FrameFile::Complete
    } else {
        FrameFile::OtherOptions
    }
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

/// The PNG bytes of a frame: RGB clamped and sRGB-encoded, the image alone (the
/// display window: no overscan border).
pub fn encode_preview(fb: &FrameBuffers) -> Result<Vec<u8>, image::ImageError> {
    let mut rgb = Vec::with_capacity((fb.width * fb.height) as usize * 3);
    let (o, dw) = (fb.overscan as usize, fb.data_size().0 as usize);
    for row in fb.rgba.chunks(dw.max(1)).skip(o).take(fb.height as usize) {
        for p in &row[o..o + fb.width as usize] {
            rgb.extend(p[..3].iter().map(|&c| linear_to_srgb8(c)));
        }
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
    use super::super::shade::{CryptoBuffers, LightPathBuffers};
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
            position: aovs.position.then(|| vec![[1.0, 2.0, 3.0]; n]),
            motion: aovs.motion.then(|| vec![[0.5, -0.25]; n]),
            crypto: aovs.cryptomatte.then(|| {
                let levels = aovs.crypto_levels as usize;
                let r = |i: usize| (f32::from_bits(0x3f80_0000 + i as u32), 0.5);
                CryptoBuffers {
                    levels,
                    object: (0..n * levels).map(r).collect(),
                    material: (0..n * levels).map(r).collect(),
                }
            }),
            light_paths: aovs.any_light_path().then(|| LightPathBuffers {
                passes: std::array::from_fn(|k| {
                    (0..n).map(|i| [k as f32, i as f32 * 0.125, 1.0]).collect()
                }),
                written: aovs.light_paths(),
            }),
            overscan: 0,
        }
    }

    fn header(aovs: Aovs, options: &str) -> FrameHeader {
        let mut scene = crate::scene::Scene::default();
        scene.nodes.push(crate::scene::Node {
            name: Some("thing".into()),
            ..Default::default()
        });
        let crypto = aovs
            .cryptomatte
            .then(|| std::sync::Arc::new(super::super::aov::CryptoNames::new(&scene)));
        let cam = super::super::CameraModel::framing(glam::Vec3::ZERO, glam::Vec3::ONE, 5, 3);
        FrameHeader::new(&cam, 24.0, options.into(), crypto)
    }

    #[test]
    fn exr_round_trips_and_is_deterministic() {
        let aovs = Aovs {
            crypto_levels: 3,
            ..Aovs::all()
        };
        let fb = frame(aovs);
        let hd = header(aovs, "spp=1");
        let a = encode_exr(&fb, PixelType::Half, ExrCompression::Zip, &hd).unwrap();
        // Custom attributes come out of a hash map: the sorted header makes every
        // encoding (in any process) the same bytes.
        for _ in 0..8 {
            assert_eq!(
                a,
                encode_exr(
                    &fb,
                    PixelType::Half,
                    ExrCompression::Zip,
                    &header(aovs, "spp=1")
                )
                .unwrap()
            );
        }
        let dir = std::env::temp_dir().join(format!("subfield-exr-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("f.exr");
        crate::atomic::write_atomically(&p, &a).unwrap();
        let o = "spp=1";
        assert!(is_complete(&p, 5, 3, aovs, PixelType::Half, o));
        assert!(!is_complete(&p, 5, 3, aovs, PixelType::Half, "spp=2"));
        assert!(!is_complete(&p, 5, 3, aovs, PixelType::Float, o));
        assert!(!is_complete(&p, 5, 4, aovs, PixelType::Half, o));
        assert!(!is_complete(&p, 5, 3, Aovs::default(), PixelType::Half, o));
        let four = Aovs {
            crypto_levels: 4,
            ..aovs
        };
        assert_eq!(channel_names(four), channel_names(aovs));
        let five = Aovs {
            crypto_levels: 5,
            ..aovs
        };
        assert!(!is_complete(&p, 5, 3, five, PixelType::Half, o));
        let img = exr::prelude::read_all_data_from_file(&p).unwrap();
        let layer = &img.layer_data[0];
        for c in &layer.channel_data.list {
            let name = c.name.to_string();
            let linear = matches!(name.as_str(), "R" | "G" | "B")
                || [
                    "albedo.",
                    "diffuse.",
                    "specular.",
                    "transmission.",
                    "emission.",
                ]
                .iter()
                .any(|p| name.starts_with(p));
            assert_eq!(c.quantize_linearly, linear, "{name}");
        }
        assert_eq!(layer.attributes.frames_per_second, Some((24, 1)));
        crate::atomic::write_atomically(&p, &a[..a.len() - 7]).unwrap();
        assert!(!is_complete(&p, 5, 3, aovs, PixelType::Half, o));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Every codec `--compression` offers gives the same pixels back (all lossless),
    /// with the codec named in the header; the overscan border makes the data window
    /// larger than the display window, and the preview shows the display window only.
    #[test]
    fn codecs_are_lossless_and_overscan_sets_the_windows() {
        let aovs = Aovs {
            depth: true,
            specular: true,
            ..Default::default()
        };
        let mut fb = frame(aovs);
        // 5x3 buffers as a 1x1 image with an overscan of 1 is 3x3: take the first 9.
        fb.width = 1;
        fb.height = 1;
        fb.overscan = 1;
        fb.rgba.truncate(9);
        fb.depth.as_mut().unwrap().truncate(9);
        for p in &mut fb.light_paths.as_mut().unwrap().passes {
            p.truncate(9);
        }
        let hd = header(aovs, "o");
        let mut raw = None;
        for (c, want) in [
            (ExrCompression::None, Compression::Uncompressed),
            (ExrCompression::Zip, Compression::ZIP16),
            (ExrCompression::Piz, Compression::PIZ),
        ] {
            let bytes = encode_exr(&fb, PixelType::Half, c, &hd).unwrap();
            let img = exr::prelude::read()
                .no_deep_data()
                .largest_resolution_level()
                .all_channels()
                .first_valid_layer()
                .all_attributes()
                .pedantic()
                .from_buffered(std::io::Cursor::new(&bytes))
                .unwrap();
            let l = &img.layer_data;
            assert_eq!(l.encoding.compression, want);
            assert_eq!(l.size, Vec2(3, 3));
            assert_eq!(l.attributes.layer_position, Vec2(-1, -1));
            assert_eq!(img.attributes.display_window.position, Vec2(0, 0));
            assert_eq!(img.attributes.display_window.size, Vec2(1, 1));
            let chans: Vec<_> = l
                .channel_data
                .list
                .iter()
                .map(|c| (c.name.to_string(), c.sample_data.clone()))
                .collect();
            match &raw {
                None => raw = Some(chans),
                Some(r) => assert_eq!(r, &chans, "{c:?}"),
            }
        }
        // The preview is the one pixel of the image: the centre of the 3x3 buffers.
        let png = encode_preview(&fb).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (1, 1));
        let centre = fb.rgba[4];
        assert_eq!(img.get_pixel(0, 0).0[0], linear_to_srgb8(centre[0]));
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
