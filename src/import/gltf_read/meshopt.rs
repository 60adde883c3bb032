//! Compressed buffer views: `EXT_meshopt_compression` and `KHR_meshopt_compression`.
//!
//! A view with the extension gets its bytes by decoding
//! `buffers[buffer][byteOffset..+byteLength]` with meshoptimizer's own decoders (the
//! `meshopt` crate): `ATTRIBUTES` (vertex codec, `byteStride` a multiple of 4 up to 256),
//! `TRIANGLES` (index codec, 2 or 4 byte indices, `count` a multiple of 3) or `INDICES`
//! (index sequence), then for attributes the `filter`: `OCTAHEDRAL` (stride 4 or 8),
//! `QUATERNION` (stride 8), `EXPONENTIAL` (stride a multiple of 4) and, in
//! `KHR_meshopt_compression` only, `COLOR` (stride 4 or 8). The decoded view is
//! `count * byteStride` bytes and must be the view's `byteLength`. Decoding runs once per
//! view, before anything reads the views; accessors and images then read the decoded
//! bytes. Buffers marked `fallback` are not loaded (see `uri`).

use super::json::{BufferView, Meshopt};
use super::{ImportError, Importer};

/// A decoded view larger than this is refused (a tiny file could otherwise ask for any
/// allocation): 1 GiB.
const MAX_DECODED: usize = 1 << 30;

/// One vertex of `N` bytes, for the vertex decoder (which takes the stride from the type).
#[derive(Clone, Copy)]
#[repr(transparent)]
struct Row<const N: usize>([u8; N]);

impl<const N: usize> Default for Row<N> {
    fn default() -> Self {
        Row([0; N])
    }
}

/// What a decoder's status says, in words (meshoptimizer returns -1 for a header it
/// does not know, -2 for data too short, -3 for data that does not end where it should).
fn why(e: &meshopt::Error) -> String {
    match e {
        meshopt::Error::Native(-1) => "unknown header or codec version (-1)".into(),
        meshopt::Error::Native(-2) => "compressed data too short (-2)".into(),
        meshopt::Error::Native(-3) => "malformed compressed data (-3)".into(),
        other => other.to_string(),
    }
}

fn vertices<const N: usize>(encoded: &[u8], count: usize) -> Result<Vec<u8>, meshopt::Error> {
    let rows = meshopt::decode_vertex_buffer::<Row<N>>(encoded, count)?;
    let mut out = Vec::with_capacity(count * N);
    for r in &rows {
        out.extend_from_slice(&r.0);
    }
    Ok(out)
}

/// The vertex codec for a stride known to be a multiple of 4 in 4..=256.
fn decode_attributes(encoded: &[u8], count: usize, stride: usize) -> Result<Vec<u8>, String> {
    macro_rules! by_stride {
        ($($n:literal)*) => {
            match stride {
                $($n => vertices::<$n>(encoded, count)
                    .map_err(|e| format!("ATTRIBUTES data does not decode: {}", why(&e))),)*
                _ => Err(format!("byteStride {stride} is not a multiple of 4 in 4..=256")),
            }
        };
    }
    by_stride!(
        4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64 68 72 76 80 84 88 92 96 100 104 108
        112 116 120 124 128 132 136 140 144 148 152 156 160 164 168 172 176 180 184 188 192
        196 200 204 208 212 216 220 224 228 232 236 240 244 248 252 256
    )
}

/// Applies a vertex filter in place, on little-endian bytes of whole vertices.
fn apply_filter(bytes: Vec<u8>, filter: Filter, stride: usize) -> Vec<u8> {
    use bytemuck::allocation::pod_collect_to_vec as collect;
    match (filter, stride) {
        (Filter::None, _) => bytes,
        (Filter::Octahedral, 4) => {
            let mut v: Vec<[i8; 4]> = collect(&bytes);
            meshopt::decode_filter_oct(&mut v);
            bytemuck::cast_slice(&v).to_vec()
        }
        (Filter::Octahedral, _) => {
            let mut v: Vec<[i16; 4]> = collect(&bytes);
            meshopt::decode_filter_oct(&mut v);
            bytemuck::cast_slice(&v).to_vec()
        }
        (Filter::Quaternion, _) => {
            let mut v: Vec<[i16; 4]> = collect(&bytes);
            meshopt::decode_filter_quat(&mut v);
            bytemuck::cast_slice(&v).to_vec()
        }
        (Filter::Exponential, _) => {
            // Each 32-bit component decodes on its own, whatever the stride.
            let mut v: Vec<[u32; 1]> = collect(&bytes);
            meshopt::decode_filter_exp(&mut v);
            bytemuck::cast_slice(&v).to_vec()
        }
        (Filter::Color, 4) => {
            let mut v: Vec<[u8; 4]> = collect(&bytes);
            meshopt::decode_filter_color(&mut v);
            bytemuck::cast_slice(&v).to_vec()
        }
        (Filter::Color, _) => {
            let mut v: Vec<[u16; 4]> = collect(&bytes);
            meshopt::decode_filter_color(&mut v);
            bytemuck::cast_slice(&v).to_vec()
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Attributes,
    Triangles,
    Indices,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Attributes => "ATTRIBUTES",
            Mode::Triangles => "TRIANGLES",
            Mode::Indices => "INDICES",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Filter {
    None,
    Octahedral,
    Quaternion,
    Exponential,
    Color,
}

/// Checks a view's extension against the specification: its mode, filter, stride and
/// count, and that the decoded size is the view's `byteLength`. meshoptimizer asserts
/// these (a count of triangles, a stride per mode and filter) rather than returning an
/// error, so nothing reaches a decoder before it passes here.
fn validate(
    ext_name: &str,
    m: &Meshopt,
    view: &BufferView,
) -> Result<(Mode, Filter, usize, usize), String> {
    let at = |what: &str| format!("extensions.{ext_name}.{what}");
    let mode = match m.mode.as_deref() {
        Some("ATTRIBUTES") => Mode::Attributes,
        Some("TRIANGLES") => Mode::Triangles,
        Some("INDICES") => Mode::Indices,
        Some(other) => {
            return Err(format!(
                "{}: {other:?} is not ATTRIBUTES, TRIANGLES or INDICES",
                at("mode")
            ))
        }
        None => return Err(format!("{}: required, missing", at("mode"))),
    };
    let filter = match m.filter.as_deref() {
        None | Some("NONE") => Filter::None,
        Some("OCTAHEDRAL") => Filter::Octahedral,
        Some("QUATERNION") => Filter::Quaternion,
        Some("EXPONENTIAL") => Filter::Exponential,
        Some("COLOR") if ext_name == "KHR_meshopt_compression" => Filter::Color,
        Some(other) => return Err(format!("{}: {other:?} is not a known filter", at("filter"))),
    };
    let stride = m
        .byte_stride
        .ok_or_else(|| format!("{}: required, missing", at("byteStride")))?;
    let count = m
        .count
        .ok_or_else(|| format!("{}: required, missing", at("count")))?;
    let stride_ok = match mode {
        Mode::Attributes => stride % 4 == 0 && (4..=256).contains(&stride),
        Mode::Triangles | Mode::Indices => stride == 2 || stride == 4,
    };
    if !stride_ok {
        let want = match mode {
            Mode::Attributes => "a multiple of 4 in 4..=256",
            _ => "2 or 4",
        };
        return Err(format!(
            "{}: {stride} for {} must be {want}",
            at("byteStride"),
            mode.name()
        ));
    }
    if mode == Mode::Triangles && count % 3 != 0 {
        return Err(format!(
            "{}: {count} for TRIANGLES is not a multiple of 3",
            at("count")
        ));
    }
    let filter_ok = match filter {
        Filter::None => true,
        _ if mode != Mode::Attributes => false,
        Filter::Octahedral | Filter::Color => stride == 4 || stride == 8,
        Filter::Quaternion => stride == 8,
        Filter::Exponential => true,
    };
    if !filter_ok {
        return Err(format!(
            "{}: {} does not apply to {} with byteStride {stride}",
            at("filter"),
            m.filter.as_deref().unwrap_or("NONE"),
            mode.name()
        ));
    }
    let size = count
        .checked_mul(stride)
        .filter(|&s| s <= MAX_DECODED)
        .ok_or_else(|| {
            format!("count {count} x byteStride {stride} exceeds the {MAX_DECODED}-byte limit")
        })?;
    let length = view.byte_length.unwrap_or(0);
    if size != length {
        return Err(format!(
            "count {count} x byteStride {stride} = {size} bytes, but the view's byteLength is {length}"
        ));
    }
    Ok((mode, filter, stride, count))
}

impl Importer<'_> {
    /// Decodes every compressed buffer view (`None` for the others).
    pub(super) fn decode_views(&self) -> Result<Vec<Option<Vec<u8>>>, ImportError> {
        let mut out = Vec::with_capacity(self.root.buffer_views.len());
        for (i, view) in self.root.buffer_views.iter().enumerate() {
            let ext = view.extensions.as_ref();
            let found = match (
                ext.and_then(|e| e.khr_meshopt.as_ref()),
                ext.and_then(|e| e.ext_meshopt.as_ref()),
            ) {
                (Some(m), _) => Some(("KHR_meshopt_compression", m)),
                (None, Some(m)) => Some(("EXT_meshopt_compression", m)),
                (None, None) => None,
            };
            let decoded = match found {
                Some((name, m)) => Some(self.decode_view(name, m, view).map_err(|reason| {
                    ImportError::BufferView {
                        path: self.path.to_path_buf(),
                        view: i,
                        reason,
                    }
                })?),
                None => None,
            };
            out.push(decoded);
        }
        Ok(out)
    }

    fn decode_view(&self, name: &str, m: &Meshopt, view: &BufferView) -> Result<Vec<u8>, String> {
        let (mode, filter, stride, count) = validate(name, m, view)?;
        let b = m
            .buffer
            .ok_or_else(|| format!("extensions.{name}.buffer: required, missing"))?;
        let buf = self
            .buffer_bytes(b)
            .map_err(|why| format!("extensions.{name}.buffer: {why}"))?;
        let length = m
            .byte_length
            .ok_or_else(|| format!("extensions.{name}.byteLength: required, missing"))?;
        let start = m.byte_offset;
        let encoded = start
            .checked_add(length)
            .and_then(|end| buf.get(start..end))
            .ok_or_else(|| {
                format!(
                    "compressed bytes {start}..+{length} lie outside buffers[{b}] ({} bytes)",
                    buf.len()
                )
            })?;
        let failed =
            |e: meshopt::Error| format!("{name} {} data does not decode: {}", mode.name(), why(&e));
        let bytes = match (mode, stride) {
            (Mode::Attributes, _) => {
                let raw =
                    decode_attributes(encoded, count, stride).map_err(|e| format!("{name} {e}"))?;
                apply_filter(raw, filter, stride)
            }
            (Mode::Triangles, 2) => {
                let v = meshopt::decode_index_buffer::<u16>(encoded, count).map_err(failed)?;
                bytemuck::cast_slice(&v).to_vec()
            }
            (Mode::Triangles, _) => {
                let v = meshopt::decode_index_buffer::<u32>(encoded, count).map_err(failed)?;
                bytemuck::cast_slice(&v).to_vec()
            }
            (Mode::Indices, 2) => {
                let v = meshopt::decode_index_sequence::<u16>(encoded, count).map_err(failed)?;
                bytemuck::cast_slice(&v).to_vec()
            }
            (Mode::Indices, _) => {
                let v = meshopt::decode_index_sequence::<u32>(encoded, count).map_err(failed)?;
                bytemuck::cast_slice(&v).to_vec()
            }
        };
        Ok(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ext(mode: &str, filter: &str, stride: usize, count: usize) -> Meshopt {
        Meshopt {
            buffer: Some(0),
            byte_offset: 0,
            byte_length: Some(0),
            byte_stride: Some(stride),
            count: Some(count),
            mode: Some(mode.into()),
            filter: Some(filter.into()),
        }
    }

    fn view(length: usize) -> BufferView {
        BufferView {
            byte_length: Some(length),
            ..BufferView::default()
        }
    }

    #[test]
    fn validation_follows_the_spec() {
        let e = "EXT_meshopt_compression";
        let k = "KHR_meshopt_compression";
        assert!(validate(e, &ext("ATTRIBUTES", "NONE", 12, 5), &view(60)).is_ok());
        assert!(validate(e, &ext("ATTRIBUTES", "NONE", 260, 1), &view(260)).is_err());
        assert!(validate(e, &ext("ATTRIBUTES", "NONE", 6, 2), &view(12)).is_err());
        assert!(validate(e, &ext("TRIANGLES", "NONE", 2, 4), &view(8)).is_err());
        assert!(validate(e, &ext("TRIANGLES", "NONE", 4, 3), &view(12)).is_ok());
        assert!(validate(e, &ext("TRIANGLES", "OCTAHEDRAL", 4, 3), &view(12)).is_err());
        assert!(validate(e, &ext("INDICES", "NONE", 8, 3), &view(24)).is_err());
        assert!(validate(e, &ext("ATTRIBUTES", "QUATERNION", 4, 3), &view(12)).is_err());
        assert!(validate(e, &ext("ATTRIBUTES", "QUATERNION", 8, 3), &view(24)).is_ok());
        assert!(validate(e, &ext("ATTRIBUTES", "COLOR", 4, 3), &view(12)).is_err());
        assert!(validate(k, &ext("ATTRIBUTES", "COLOR", 4, 3), &view(12)).is_ok());
        assert!(validate(e, &ext("ATTRIBUTES", "EXPONENTIAL", 12, 3), &view(36)).is_ok());
        let size = validate(e, &ext("ATTRIBUTES", "NONE", 12, 5), &view(64)).unwrap_err();
        assert!(size.contains("byteLength is 64"), "{size}");
        let huge = validate(e, &ext("ATTRIBUTES", "NONE", 256, usize::MAX / 2), &view(0));
        assert!(huge.unwrap_err().contains("limit"));
    }

    #[test]
    fn every_stride_round_trips_through_the_vertex_codec() {
        for stride in (4..=256).step_by(4) {
            let count = 37;
            let data: Vec<u8> = (0..count * stride).map(|i| (i * 7 % 251) as u8).collect();
            let rows: Vec<Vec<u8>> = data.chunks(stride).map(<[u8]>::to_vec).collect();
            let encoded = encode_rows(&rows, stride);
            let back = decode_attributes(&encoded, count, stride).unwrap();
            assert_eq!(back, data, "stride {stride}");
        }
    }

    fn encode_rows(rows: &[Vec<u8>], stride: usize) -> Vec<u8> {
        macro_rules! enc {
            ($($n:literal)*) => {
                match stride {
                    $($n => {
                        let typed: Vec<Row<$n>> = rows
                            .iter()
                            .map(|r| Row(<[u8; $n]>::try_from(r.as_slice()).unwrap()))
                            .collect();
                        meshopt::encode_vertex_buffer(&typed).unwrap()
                    })*
                    _ => unreachable!(),
                }
            };
        }
        enc!(
            4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64 68 72 76 80 84 88 92 96 100 104 108
            112 116 120 124 128 132 136 140 144 148 152 156 160 164 168 172 176 180 184 188
            192 196 200 204 208 212 216 220 224 228 232 236 240 244 248 252 256
        )
    }

    #[test]
    fn filters_match_the_library_encoders() {
        // Octahedral, 16-bit: unit normals survive to within the quantisation.
        let normals = [
            [0.0f32, 0.0, 1.0, 0.0],
            [0.6, 0.8, 0.0, 0.0],
            [0.0, -1.0, 0.0, 0.0],
        ];
        let enc: Vec<[i16; 4]> = meshopt::encode_filter_oct(&normals, 16);
        let bytes = apply_filter(bytemuck::cast_slice(&enc).to_vec(), Filter::Octahedral, 8);
        let dec: Vec<[i16; 4]> = bytemuck::allocation::pod_collect_to_vec(&bytes);
        for (n, d) in normals.iter().zip(&dec) {
            for c in 0..3 {
                assert!(
                    (n[c] - f32::from(d[c]) / 32767.0).abs() < 1e-3,
                    "{n:?} {d:?}"
                );
            }
        }
        // Quaternion: identity and a turn about z.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let quats = [[0.0f32, 0.0, 0.0, 1.0], [0.0, 0.0, h, h]];
        let enc = meshopt::encode_filter_quat(&quats, 16);
        let bytes = apply_filter(bytemuck::cast_slice(&enc).to_vec(), Filter::Quaternion, 8);
        let dec: Vec<[i16; 4]> = bytemuck::allocation::pod_collect_to_vec(&bytes);
        for (q, d) in quats.iter().zip(&dec) {
            for c in 0..4 {
                assert!(
                    (q[c] - f32::from(d[c]) / 32767.0).abs() < 1e-3,
                    "{q:?} {d:?}"
                );
            }
        }
        // Exponential: exact for values the 24-bit mantissa holds.
        let values = [[1.5f32, -2.25, 1024.0], [0.0, 3.0, -0.125]];
        let enc = meshopt::encode_filter_exp(&values, 24, meshopt::EncodeExpMode::Separate);
        let bytes = apply_filter(bytemuck::cast_slice(&enc).to_vec(), Filter::Exponential, 12);
        let dec: Vec<[f32; 3]> = bytemuck::allocation::pod_collect_to_vec(&bytes);
        assert_eq!(dec, values);
    }
}
