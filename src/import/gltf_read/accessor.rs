//! Accessors: bounds against their buffer views, types, sparse storage, normalisation and
//! finite floats. Every value is decoded exactly (`f64`) before conversion.

use glam::Vec3;
use gltf::accessor::{DataType, Dimensions};

use super::{ImportError, Importer};

/// Refuse accessors claiming more components than this.
const MAX_COMPONENTS: usize = 1 << 28;
/// An accessor without a buffer view is all zeros (plus sparse values): its count is not
/// bounded by any buffer, so it gets a tighter cap (16 Mi components, 128 MiB decoded).
const MAX_ZERO_COMPONENTS: usize = 1 << 24;

/// Decoded accessor contents, exact (f64 holds every u32 and f32 value).
struct Raw {
    values: Vec<f64>,
    comps: usize,
    data_type: DataType,
    normalized: bool,
}

impl Importer<'_> {
    /// The bytes of a buffer view, checked against its buffer.
    fn view_bytes(
        &self,
        view: &gltf::buffer::View,
        accessor: usize,
        usage: &str,
    ) -> Result<&[u8], ImportError> {
        let b = view.buffer().index();
        let buf = self.buffers.get(b).map(Vec::as_slice).unwrap_or(&[]);
        let start = view.offset();
        let end = start.checked_add(view.length());
        end.and_then(|end| buf.get(start..end)).ok_or_else(|| {
            self.acc_err(
                accessor,
                usage,
                format!(
                    "bufferViews[{}] (bytes {start}..+{}) lies outside buffers[{b}] ({} bytes)",
                    view.index(),
                    view.length(),
                    buf.len()
                ),
            )
        })
    }

    fn read_raw(&self, acc: &gltf::Accessor, usage: &str) -> Result<Raw, ImportError> {
        let ai = acc.index();
        let data_type = acc.data_type();
        let dims = acc.dimensions();
        let comps = dims.multiplicity();
        let csize = data_type.size();
        if matches!(dims, Dimensions::Mat2 | Dimensions::Mat3) && csize < 4 {
            return Err(self.acc_err(ai, usage, "padded matrix columns are not supported"));
        }
        let elem = csize * comps;
        let count = acc.count();
        let total = count
            .checked_mul(comps)
            .filter(|&n| n <= MAX_COMPONENTS)
            .ok_or_else(|| self.acc_err(ai, usage, format!("count {count} is too large")))?;
        let mut values = Vec::new();
        if let Some(view) = acc.view() {
            let bytes = self.view_bytes(&view, ai, usage)?;
            let stride = match view.stride() {
                Some(s) if s < elem => {
                    return Err(self.acc_err(
                        ai,
                        usage,
                        format!("byteStride {s} is smaller than the element size {elem}"),
                    ))
                }
                Some(s) => s,
                None => elem,
            };
            let start = acc.offset();
            if count > 0 {
                let need = (count - 1)
                    .checked_mul(stride)
                    .and_then(|x| x.checked_add(start))
                    .and_then(|x| x.checked_add(elem));
                match need {
                    Some(n) if n <= bytes.len() => {}
                    _ => {
                        return Err(self.acc_err(
                            ai,
                            usage,
                            format!(
                            "{count} elements of {elem} bytes (stride {stride}) from byte {start} \
                                 run past bufferViews[{}] ({} bytes)",
                            view.index(),
                            bytes.len()
                        ),
                        ))
                    }
                }
            }
            values.resize(total, 0.0);
            for e in 0..count {
                let base = start + e * stride;
                for c in 0..comps {
                    let at = base + c * csize;
                    values[e * comps + c] = component(&bytes[at..at + csize], data_type);
                }
            }
        } else if total <= MAX_ZERO_COMPONENTS {
            values.resize(total, 0.0); // no buffer view: zeros (then sparse values)
        } else {
            return Err(self.acc_err(
                ai,
                usage,
                format!("count {count} without a buffer view is too large"),
            ));
        }
        if let Some(sparse) = acc.sparse() {
            self.apply_sparse(acc, usage, &sparse, &mut values)?;
        }
        Ok(Raw {
            values,
            comps,
            data_type,
            normalized: acc.normalized(),
        })
    }

    /// Overwrites the elements that sparse storage names (after the dense or zero data).
    fn apply_sparse(
        &self,
        acc: &gltf::Accessor,
        usage: &str,
        sparse: &gltf::accessor::sparse::Sparse,
        values: &mut [f64],
    ) -> Result<(), ImportError> {
        let ai = acc.index();
        let data_type = acc.data_type();
        let comps = acc.dimensions().multiplicity();
        let csize = data_type.size();
        let elem = csize * comps;
        let count = acc.count();
        let n = sparse.count();
        let idx = sparse.indices();
        let vals = sparse.values();
        let isize = match idx.index_type() {
            gltf::accessor::sparse::IndexType::U8 => 1,
            gltf::accessor::sparse::IndexType::U16 => 2,
            gltf::accessor::sparse::IndexType::U32 => 4,
        };
        let ibytes = self.view_bytes(&idx.view(), ai, usage)?;
        let vbytes = self.view_bytes(&vals.view(), ai, usage)?;
        let ifits = n
            .checked_mul(isize)
            .and_then(|x| x.checked_add(idx.offset()))
            .is_some_and(|end| end <= ibytes.len());
        let vfits = n
            .checked_mul(elem)
            .and_then(|x| x.checked_add(vals.offset()))
            .is_some_and(|end| end <= vbytes.len());
        if !ifits || !vfits {
            return Err(self.acc_err(ai, usage, "sparse data runs past its buffer view"));
        }
        for k in 0..n {
            let at = idx.offset() + k * isize;
            let target = match isize {
                1 => usize::from(ibytes[at]),
                2 => usize::from(u16::from_le_bytes([ibytes[at], ibytes[at + 1]])),
                _ => {
                    u32::from_le_bytes([ibytes[at], ibytes[at + 1], ibytes[at + 2], ibytes[at + 3]])
                        as usize
                }
            };
            if target >= count {
                return Err(self.acc_err(
                    ai,
                    usage,
                    format!("sparse index {target} past the count {count}"),
                ));
            }
            for c in 0..comps {
                let at = vals.offset() + k * elem + c * csize;
                values[target * comps + c] = component(&vbytes[at..at + csize], data_type);
            }
        }
        Ok(())
    }

    /// Floats, with integer components normalised when the accessor says so or
    /// `normalize_ints` (weights, uvs, rotations: the spec only allows normalised ints).
    pub(super) fn floats(
        &self,
        acc: &gltf::Accessor,
        usage: &str,
        comps: usize,
        normalize_ints: bool,
    ) -> Result<Vec<f32>, ImportError> {
        let raw = self.read_raw(acc, usage)?;
        if raw.comps != comps {
            return Err(self.acc_err(
                acc.index(),
                usage,
                format!("has {} components per element, expected {comps}", raw.comps),
            ));
        }
        let normalize = raw.normalized || normalize_ints;
        let scale = match raw.data_type {
            DataType::F32 => None,
            DataType::I8 if normalize => Some(127.0),
            DataType::U8 if normalize => Some(255.0),
            DataType::I16 if normalize => Some(32767.0),
            DataType::U16 if normalize => Some(65535.0),
            DataType::U32 if normalize => {
                return Err(self.acc_err(acc.index(), usage, "normalised UNSIGNED_INT"))
            }
            _ => None,
        };
        let mut out = Vec::with_capacity(raw.values.len());
        for (i, v) in raw.values.iter().enumerate() {
            let f = match scale {
                Some(s) => (v / s).max(-1.0) as f32,
                None => *v as f32,
            };
            if !f.is_finite() {
                return Err(self.acc_err(
                    acc.index(),
                    usage,
                    format!(
                        "element {} component {} is {f} (not finite)",
                        i / comps,
                        i % comps
                    ),
                ));
            }
            out.push(f);
        }
        Ok(out)
    }

    pub(super) fn vec3s(
        &self,
        acc: &gltf::Accessor,
        usage: &str,
    ) -> Result<Vec<Vec3>, ImportError> {
        let f = self.floats(acc, usage, 3, false)?;
        Ok(f.chunks_exact(3).map(Vec3::from_slice).collect())
    }

    /// Unsigned integers (indices, joints): must be an unsigned, non-normalised type.
    pub(super) fn uints(
        &self,
        acc: &gltf::Accessor,
        usage: &str,
        comps: usize,
    ) -> Result<Vec<u32>, ImportError> {
        let raw = self.read_raw(acc, usage)?;
        if raw.comps != comps
            || !matches!(raw.data_type, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(self.acc_err(
                acc.index(),
                usage,
                format!(
                    "expected {comps} unsigned integer component(s), found {} of {:?}",
                    raw.comps, raw.data_type
                ),
            ));
        }
        Ok(raw.values.iter().map(|&v| v as u32).collect())
    }
}

/// One little-endian component as an exact number.
fn component(b: &[u8], t: DataType) -> f64 {
    match (t, b) {
        (DataType::I8, [x]) => f64::from(*x as i8),
        (DataType::U8, [x]) => f64::from(*x),
        (DataType::I16, [a, b]) => f64::from(i16::from_le_bytes([*a, *b])),
        (DataType::U16, [a, b]) => f64::from(u16::from_le_bytes([*a, *b])),
        (DataType::U32, [a, b, c, d]) => f64::from(u32::from_le_bytes([*a, *b, *c, *d])),
        (DataType::F32, [a, b, c, d]) => f64::from(f32::from_le_bytes([*a, *b, *c, *d])),
        _ => f64::NAN, // sizes come from the type itself: unreachable
    }
}
