//! Accessors: bounds against their buffer views, types, sparse storage, normalisation and
//! finite floats. Every value is decoded exactly (`f64`) before conversion, except dense
//! `FLOAT` vectors, read as they are stored (the same values).

use glam::Vec3;

use super::json::{self, type_components, ComponentType as DataType};
use super::{ImportError, Importer};

/// Refuse accessors claiming more components than this.
const MAX_COMPONENTS: usize = 1 << 28;
/// An accessor without a buffer view is all zeros (plus sparse values): its count is not
/// bounded by any buffer, so it gets a tighter cap (16 Mi components, 128 MiB decoded).
const MAX_ZERO_COMPONENTS: usize = 1 << 24;

/// Where an accessor's elements are: its bytes, the first's offset and the stride,
/// where it has a buffer view (`None`: zeros before any sparse values).
struct Layout<'i> {
    acc: &'i json::Accessor,
    data_type: DataType,
    comps: usize,
    count: usize,
    dense: Option<(&'i [u8], usize, usize)>,
}

/// Decoded accessor contents, exact (f64 holds every u32 and f32 value).
struct Raw {
    values: Vec<f64>,
    comps: usize,
    data_type: DataType,
    normalized: bool,
}

impl Importer<'_> {
    /// The bytes of a buffer view, checked against its buffer.
    fn view_bytes(&self, view: usize, accessor: usize, usage: &str) -> Result<&[u8], ImportError> {
        let v =
            self.root.buffer_views.get(view).ok_or_else(|| {
                self.acc_err(accessor, usage, format!("bufferViews[{view}] missing"))
            })?;
        if let Some(Some(decoded)) = self.decoded_views.get(view) {
            return Ok(decoded);
        }
        let b = v.buffer.unwrap_or(usize::MAX);
        let buf = self
            .buffer_bytes(b)
            .map_err(|why| self.acc_err(accessor, usage, format!("bufferViews[{view}]: {why}")))?;
        let start = v.byte_offset;
        let length = v.byte_length.unwrap_or(0);
        let end = start.checked_add(length);
        end.and_then(|end| buf.get(start..end)).ok_or_else(|| {
            self.acc_err(
                accessor,
                usage,
                format!(
                    "bufferViews[{view}] (bytes {start}..+{length}) lies outside buffers[{b}] ({} bytes)",
                    buf.len()
                ),
            )
        })
    }

    /// The accessor `ai` (validated to exist by `check`; an error otherwise).
    pub(super) fn accessor(&self, ai: usize, usage: &str) -> Result<&json::Accessor, ImportError> {
        self.root
            .accessors
            .get(ai)
            .ok_or_else(|| self.acc_err(ai, usage, "missing"))
    }

    /// Its element count.
    pub(super) fn count(&self, ai: usize) -> usize {
        self.root
            .accessors
            .get(ai)
            .and_then(|a| a.count)
            .unwrap_or(0)
    }

    /// Its components per element (0 for a missing accessor).
    pub(super) fn components(&self, ai: usize) -> usize {
        self.root
            .accessors
            .get(ai)
            .and_then(|a| a.type_.as_deref())
            .and_then(type_components)
            .unwrap_or(0)
    }

    /// Where an accessor's elements lie, checked against its buffer view (or zeros
    /// without one): every error an accessor's layout can have, before any is decoded.
    fn layout(&self, ai: usize, usage: &str) -> Result<Layout<'_>, ImportError> {
        let acc = self.accessor(ai, usage)?;
        let data_type = acc
            .component_type
            .and_then(DataType::from_code)
            .ok_or_else(|| self.acc_err(ai, usage, "no valid componentType"))?;
        let type_ = acc.type_.as_deref().unwrap_or("");
        // `check` lets any type string through: an accessor nothing reads may have a
        // type a later glTF defines. One that is read must be a type we know.
        let comps = type_components(type_).ok_or_else(|| {
            self.acc_err(
                ai,
                usage,
                format!(
                    "type {type_:?} is not one glTF 2.0 defines (SCALAR, VEC2, VEC3, VEC4, \
                     MAT2, MAT3, MAT4)"
                ),
            )
        })?;
        let csize = data_type.size();
        if matches!(type_, "MAT2" | "MAT3") && csize < 4 {
            return Err(self.acc_err(ai, usage, "padded matrix columns are not supported"));
        }
        let elem = csize * comps;
        let count = acc.count.unwrap_or(0);
        let total = count
            .checked_mul(comps)
            .filter(|&n| n <= MAX_COMPONENTS)
            .ok_or_else(|| self.acc_err(ai, usage, format!("count {count} is too large")))?;
        let dense = if let Some(view) = acc.buffer_view {
            let bytes = self.view_bytes(view, ai, usage)?;
            let stride = match self.root.buffer_views.get(view).and_then(|v| v.byte_stride) {
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
            let start = acc.byte_offset;
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
                                 run past bufferViews[{view}] ({} bytes)",
                            bytes.len()
                        ),
                        ))
                    }
                }
            }
            Some((bytes, start, stride))
        } else if total <= MAX_ZERO_COMPONENTS {
            None // no buffer view: zeros (then sparse values)
        } else {
            return Err(self.acc_err(
                ai,
                usage,
                format!("count {count} without a buffer view is too large"),
            ));
        };
        Ok(Layout {
            acc,
            data_type,
            comps,
            count,
            dense,
        })
    }

    /// Every value of the accessor laid out as `l`, exact.
    fn read_raw(&self, l: Layout<'_>, ai: usize, usage: &str) -> Result<Raw, ImportError> {
        let (comps, csize) = (l.comps, l.data_type.size());
        let mut values = vec![0.0; l.count * comps];
        if let Some((bytes, start, stride)) = l.dense {
            for e in 0..l.count {
                let base = start + e * stride;
                for c in 0..comps {
                    let at = base + c * csize;
                    values[e * comps + c] = component(&bytes[at..at + csize], l.data_type);
                }
            }
        }
        if let Some(sparse) = &l.acc.sparse {
            self.apply_sparse(
                ai,
                usage,
                sparse,
                (l.data_type, comps, l.count),
                &mut values,
            )?;
        }
        Ok(Raw {
            values,
            comps,
            data_type: l.data_type,
            normalized: l.acc.normalized,
        })
    }

    /// An accessor of `FLOAT`s stored densely (a buffer view, no sparse storage), its
    /// elements of `N` components read straight from the bytes, one component after the
    /// other; `None` for any other, which [`read_raw`](Self::read_raw) decodes. The same
    /// values and errors as that path (an `f32` goes through `f64` unchanged), without
    /// its three passes over fresh memory: a morph-target cache is mostly such
    /// accessors, and decoding them through `f64` was a third of the import's time
    /// (`benches/PERF.md`, issue 38, round 19).
    fn dense_f32<const N: usize>(
        &self,
        l: &Layout<'_>,
        ai: usize,
        usage: &str,
    ) -> Result<Option<Vec<f32>>, ImportError> {
        let (DataType::F32, Some((bytes, start, stride)), None) =
            (l.data_type, l.dense, &l.acc.sparse)
        else {
            return Ok(None);
        };
        if l.comps != N {
            return Err(self.acc_err(
                ai,
                usage,
                format!("has {} components per element, expected {N}", l.comps),
            ));
        }
        let mut out = Vec::with_capacity(l.count * N);
        for e in 0..l.count {
            let base = start + e * stride;
            // `layout` checked that every element lies inside `bytes`.
            let Some(b) = bytes.get(base..base + 4 * N) else {
                return Err(self.acc_err(ai, usage, "element past its buffer view"));
            };
            let mut v = [0.0f32; N];
            for (c, x) in v.iter_mut().enumerate() {
                let f = f32::from_le_bytes([b[4 * c], b[4 * c + 1], b[4 * c + 2], b[4 * c + 3]]);
                if !f.is_finite() {
                    return Err(self.acc_err(
                        ai,
                        usage,
                        format!("element {e} component {c} is {f} (not finite)"),
                    ));
                }
                *x = f;
            }
            out.extend(v);
        }
        Ok(Some(out))
    }

    /// Overwrites the elements that sparse storage names (after the dense or zero data).
    fn apply_sparse(
        &self,
        ai: usize,
        usage: &str,
        sparse: &json::Sparse,
        (data_type, comps, count): (DataType, usize, usize),
        values: &mut [f64],
    ) -> Result<(), ImportError> {
        let csize = data_type.size();
        let elem = csize * comps;
        let n = sparse.count.unwrap_or(0);
        let (Some(idx), Some(vals)) = (&sparse.indices, &sparse.values) else {
            return Err(self.acc_err(ai, usage, "sparse without indices or values"));
        };
        let isize = match idx.component_type {
            Some(5121) => 1,
            Some(5123) => 2,
            Some(5125) => 4,
            _ => return Err(self.acc_err(ai, usage, "sparse indices of no unsigned type")),
        };
        let ibytes = self.view_bytes(idx.buffer_view.unwrap_or(usize::MAX), ai, usage)?;
        let vbytes = self.view_bytes(vals.buffer_view.unwrap_or(usize::MAX), ai, usage)?;
        let (ioff, voff) = (idx.byte_offset, vals.byte_offset);
        let ifits = n
            .checked_mul(isize)
            .and_then(|x| x.checked_add(ioff))
            .is_some_and(|end| end <= ibytes.len());
        let vfits = n
            .checked_mul(elem)
            .and_then(|x| x.checked_add(voff))
            .is_some_and(|end| end <= vbytes.len());
        if !ifits || !vfits {
            return Err(self.acc_err(ai, usage, "sparse data runs past its buffer view"));
        }
        for k in 0..n {
            let at = ioff + k * isize;
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
                let at = voff + k * elem + c * csize;
                values[target * comps + c] = component(&vbytes[at..at + csize], data_type);
            }
        }
        Ok(())
    }

    /// Floats, with integer components normalised when the accessor says so or
    /// `normalize_ints` (weights, uvs, rotations: the spec only allows normalised ints).
    pub(super) fn floats(
        &self,
        ai: usize,
        usage: &str,
        comps: usize,
        normalize_ints: bool,
    ) -> Result<Vec<f32>, ImportError> {
        let l = self.layout(ai, usage)?;
        // Dense FLOATs as stored (no normalisation applies to them).
        let dense = match comps {
            1 => self.dense_f32::<1>(&l, ai, usage)?,
            2 => self.dense_f32::<2>(&l, ai, usage)?,
            3 => self.dense_f32::<3>(&l, ai, usage)?,
            4 => self.dense_f32::<4>(&l, ai, usage)?,
            _ => None,
        };
        if let Some(v) = dense {
            return Ok(v);
        }
        let raw = self.read_raw(l, ai, usage)?;
        if raw.comps != comps {
            return Err(self.acc_err(
                ai,
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
                return Err(self.acc_err(ai, usage, "normalised UNSIGNED_INT"))
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
                    ai,
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

    pub(super) fn vec3s(&self, ai: usize, usage: &str) -> Result<Vec<Vec3>, ImportError> {
        // `floats` reads dense FLOATs as stored too.
        let f = self.floats(ai, usage, 3, false)?;
        Ok(f.chunks_exact(3).map(Vec3::from_slice).collect())
    }

    /// Unsigned integers (indices, joints): must be an unsigned, non-normalised type.
    pub(super) fn uints(
        &self,
        ai: usize,
        usage: &str,
        comps: usize,
    ) -> Result<Vec<u32>, ImportError> {
        let raw = self.read_raw(self.layout(ai, usage)?, ai, usage)?;
        if raw.comps != comps
            || !matches!(raw.data_type, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(self.acc_err(
                ai,
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
