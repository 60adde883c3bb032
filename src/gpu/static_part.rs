//! A static [`Psf`] (an in-memory bake or an opened `.psf`, mapped or decompressed)
//! uploaded once as storage buffers: the triangles, each subfield's frame, the direction
//! table, and every subfield's tiles, slab starts, entries and blocks, each kind in one
//! buffer with the subfields one after another (a subfield's frame record says where
//! its part begins, so the baked arrays go up unchanged). An array larger than one
//! binding may hold (wgpu's `max_storage_buffer_binding_size`: 128 MiB on lavapipe,
//! under 4 GiB on NVIDIA) is split over up to [`CHUNKS`] bindings of a power of two
//! elements each, which the kernel tells apart by the index's high bits (trace.wgsl,
//! `stri` and its siblings); an array larger than that is refused with the size needed
//! and the size available.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use rayon::prelude::*;

use super::{GpuDevice, GpuError};
use crate::geometry::{is_degenerate, Aabb};
use crate::psf::{Block, Entry, Psf, TileHeader};

/// One subfield's frame and where its arrays begin (`SubMeta` in trace.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SubMeta {
    d: [f32; 4],
    u: [f32; 4],
    v: [f32; 4],
    n: [u32; 4],
    m: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<SubMeta>() == 80);

/// Triangles as the kernels read them: three `vec4`s, the vertices, with the first
/// vertex's `w` set to 1 for a triangle the CPU's test never hits ([`is_degenerate`],
/// which depends on the triangle alone, so it is decided here, on the CPU, once).
pub(super) fn pack_triangles(tris: &[[Vec3; 3]]) -> Vec<[f32; 12]> {
    tris.par_iter()
        .with_min_len(4096)
        .map(|t| {
            let flag = if is_degenerate(t) { 1.0 } else { 0.0 };
            [
                t[0].x, t[0].y, t[0].z, flag, t[1].x, t[1].y, t[1].z, 0.0, t[2].x, t[2].y, t[2].z,
                0.0,
            ]
        })
        .collect()
}

/// The most bindings one array of the static part is split over (trace.wgsl declares
/// this many of each; 26 storage bindings in all, lavapipe allows 32).
pub const CHUNKS: usize = 4;

/// One array of the static part in up to [`CHUNKS`] buffers of `1 << shift` elements
/// each (the last one shorter); unused bindings get a small dummy buffer.
pub(super) struct Chunked {
    pub(super) bufs: Vec<wgpu::Buffer>,
    pub(super) shift: u32,
}

impl Chunked {
    /// Binding `k` of this array (`k < CHUNKS`).
    pub(super) fn binding<'b>(&'b self, k: usize, dummy: &'b wgpu::Buffer) -> &'b wgpu::Buffer {
        self.bufs.get(k).unwrap_or(dummy)
    }
}

/// How an array of `n` elements of `size` bytes is split into bindings of at most `cap`
/// bytes: the shift (elements a chunk = `1 << shift`) and the chunks' lengths in bytes;
/// `Err(available)`, the most [`CHUNKS`] such bindings hold, when it needs more.
fn plan(n: usize, size: u64, cap: u64) -> Result<(u32, Vec<u64>), u64> {
    let per = (cap / size).max(1);
    // The largest power of two not above `per`, and below 2^31 (indices are u32).
    let shift = (63 - per.leading_zeros()).min(31);
    let chunk = 1u64 << shift;
    let count = (n as u64).div_ceil(chunk).max(1);
    if count > CHUNKS as u64 {
        return Err(CHUNKS as u64 * chunk * size);
    }
    Ok((
        shift,
        (0..count)
            .map(|k| chunk.min(n as u64 - k * chunk) * size)
            .collect(),
    ))
}

/// [`plan`] for an array of `n` values of `T` on `dev`: in bindings as large as the
/// adapter allows, or with `parts`, in bindings of about `1 / parts` of the array (2 to
/// 4 of them, for the tests).
fn plan_on<T>(
    dev: &GpuDevice,
    what: &'static str,
    n: usize,
    parts: Option<u64>,
) -> Result<(u32, Vec<u64>), GpuError> {
    let size = std::mem::size_of::<T>() as u64;
    let bytes = (n as u64).saturating_mul(size);
    let cap = match parts {
        Some(p) => bytes.div_ceil(p.max(1)).clamp(size, dev.max_binding),
        None => dev.max_binding,
    };
    plan(n, size, cap).map_err(|available| GpuError::TooLarge {
        what,
        needed: bytes,
        available,
        adapter: dev.describe(),
    })
}

/// A [`Psf`] on the GPU.
pub struct GpuStatic {
    pub(super) tris: Chunked,
    pub(super) subs: wgpu::Buffer,
    pub(super) tiles: Chunked,
    pub(super) starts: Chunked,
    pub(super) entries: Chunked,
    pub(super) blocks: Chunked,
    /// Bound where an array has fewer than [`CHUNKS`] buffers.
    pub(super) dummy: wgpu::Buffer,
    pub(super) table: wgpu::Buffer,
    pub(super) subfields: u32,
    pub(super) table_res: u32,
    pub(super) triangles: u32,
    pub(super) clip: Aabb,
    pub(super) margin: f32,
    bytes: u64,
}

impl std::fmt::Debug for GpuStatic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "GpuStatic({} triangles, {} subfields, {} bytes)",
            self.triangles, self.subfields, self.bytes
        )
    }
}

/// Makes the buffers of `lens` and writes `parts` (one slice after another) into them,
/// each element into the chunk its index falls in.
fn upload_chunked<'a, T: Pod>(
    dev: &GpuDevice,
    what: &'static str,
    (shift, lens): (u32, Vec<u64>),
    parts: impl Iterator<Item = &'a [T]>,
) -> Result<Chunked, GpuError> {
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
    let size = std::mem::size_of::<T>();
    let chunk = 1usize << shift;
    let bufs = lens
        .iter()
        // A binding must not be empty: an empty array gets one element's room.
        .map(|&len| dev.buffer(what, len.max(size as u64), usage))
        .collect::<Result<Vec<_>, _>>()?;
    let mut at = 0usize;
    for mut part in parts {
        while !part.is_empty() {
            let (k, within) = (at >> shift, at & (chunk - 1));
            let take = part.len().min(chunk - within);
            let Some(buf) = bufs.get(k) else {
                // `plan` sized the chunks for every element: more is a bug.
                return Err(dev.too_large(what, ((at + part.len()) * size) as u64));
            };
            dev.write(
                buf,
                (within * size) as u64,
                bytemuck::cast_slice(&part[..take]),
            );
            part = &part[take..];
            at += take;
        }
    }
    Ok(Chunked { bufs, shift })
}

fn index(dev: &GpuDevice, what: &'static str, n: usize) -> Result<u32, GpuError> {
    u32::try_from(n).map_err(|_| dev.too_large(what, n as u64))
}

impl GpuStatic {
    /// Uploads `psf`. Every size is checked before the first byte is sent.
    pub fn upload(dev: &GpuDevice, psf: &Psf) -> Result<GpuStatic, GpuError> {
        Self::upload_with(dev, psf, None)
    }

    /// Uploads `psf` with every array split over 2 to [`CHUNKS`] bindings (those with
    /// more than one element): how the tests run the split arrays, which real adapters
    /// need only for scenes larger than one binding, on small scenes.
    pub fn upload_split(dev: &GpuDevice, psf: &Psf) -> Result<GpuStatic, GpuError> {
        Self::upload_with(dev, psf, Some(2))
    }

    fn upload_with(dev: &GpuDevice, psf: &Psf, parts: Option<u64>) -> Result<GpuStatic, GpuError> {
        let subs = psf.subfields();
        let (mut nt, mut ns, mut ne, mut nb) = (0usize, 0usize, 0usize, 0usize);
        let mut meta = Vec::with_capacity(subs.len());
        for s in subs {
            let f = &s.frame;
            meta.push(SubMeta {
                d: [f.d.x, f.d.y, f.d.z, f.u0],
                u: [f.u.x, f.u.y, f.u.z, f.v0],
                v: [f.v.x, f.v.y, f.v.z, f.inv_tile],
                n: [
                    f.nu,
                    f.nv,
                    index(dev, "the tile headers", nt)?,
                    index(dev, "the slab starts", ns)?,
                ],
                m: [
                    index(dev, "the tile entries", ne)?,
                    index(dev, "the flat tiles' blocks", nb)?,
                    0,
                    0,
                ],
            });
            nt += s.tiles.len();
            ns += s.slab_starts.len();
            ne += s.entries.len();
            nb += s.blocks.len();
        }
        let ntris = psf.triangles().len();
        let p_tris = plan_on::<[f32; 4]>(dev, "the static triangles", 3 * ntris, parts)?;
        let p_tiles = plan_on::<TileHeader>(dev, "the tile headers", nt, parts)?;
        let p_starts = plan_on::<u32>(dev, "the slab starts", ns, parts)?;
        let p_entries = plan_on::<Entry>(dev, "the tile entries", ne, parts)?;
        let p_blocks = plan_on::<Block>(dev, "the flat tiles' blocks", nb, parts)?;
        let bytes = [&p_tris, &p_tiles, &p_starts, &p_entries, &p_blocks]
            .iter()
            .flat_map(|p| p.1.iter())
            .sum();
        let triangles = index(dev, "the static triangles", ntris)?;
        index(dev, "the static triangles", 3 * ntris)?;

        let packed = pack_triangles(psf.triangles());
        let tris = upload_chunked::<[f32; 4]>(
            dev,
            "the static triangles",
            p_tris,
            std::iter::once(bytemuck::cast_slice::<[f32; 12], [f32; 4]>(&packed)),
        )?;
        drop(packed);
        let subs_buf = dev.storage_with("the subfields' frames", bytemuck::cast_slice(&meta))?;
        let table = psf.direction_table();
        let cells: Vec<u32> = table.cells().iter().map(|&c| u32::from(c)).collect();
        let table_buf = dev.storage_with("the direction table", bytemuck::cast_slice(&cells))?;
        // The subfields' arrays, one after another, written straight from the bake's
        // (or the mapping's) slices.
        let tiles = upload_chunked(
            dev,
            "the tile headers",
            p_tiles,
            subs.iter().map(|s| &s.tiles[..]),
        )?;
        let starts = upload_chunked(
            dev,
            "the slab starts",
            p_starts,
            subs.iter().map(|s| &s.slab_starts[..]),
        )?;
        let entries = upload_chunked(
            dev,
            "the tile entries",
            p_entries,
            subs.iter().map(|s| &s.entries[..]),
        )?;
        let blocks = upload_chunked(
            dev,
            "the flat tiles' blocks",
            p_blocks,
            subs.iter().map(|s| &s.blocks[..]),
        )?;
        let dummy = dev.buffer(
            "an unused binding",
            std::mem::size_of::<Block>() as u64,
            wgpu::BufferUsages::STORAGE,
        )?;
        dev.wait()?;
        Ok(GpuStatic {
            tris,
            subs: subs_buf,
            tiles,
            starts,
            entries,
            blocks,
            dummy,
            table: table_buf,
            subfields: subs.len() as u32,
            table_res: table.res(),
            triangles,
            clip: *psf.clip(),
            margin: psf.margin(),
            bytes,
        })
    }

    /// The static triangles' count: moving triangle `i` is hit number `count + i`.
    pub fn triangle_count(&self) -> usize {
        self.triangles as usize
    }

    /// Bytes uploaded for the triangles and the subfields' arrays.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// How many bindings each array takes (1 unless it exceeds a binding): the
    /// triangles, tile headers, slab starts, entries and blocks.
    pub fn chunks(&self) -> [usize; 5] {
        [
            &self.tris,
            &self.tiles,
            &self.starts,
            &self.entries,
            &self.blocks,
        ]
        .map(|c| c.bufs.len())
    }
}

#[cfg(test)]
mod tests {
    use super::{plan, CHUNKS};

    #[test]
    fn plans_split_arrays_in_powers_of_two() {
        // Fits one binding: one chunk, the whole array.
        assert_eq!(plan(10, 12, 1 << 20), Ok((16, vec![120])));
        // 100 elements of 16 bytes in 512-byte bindings: 32 a chunk, 4 chunks.
        assert_eq!(plan(100, 16, 512), Ok((5, vec![512, 512, 512, 64])));
        // A cap that is not a power of two of elements rounds down: 96 / 12 = 8.
        assert_eq!(plan(20, 12, 100), Ok((3, vec![96, 96, 48])));
        // More than CHUNKS chunks: refused with what CHUNKS bindings hold.
        assert_eq!(plan(200, 16, 512), Err(CHUNKS as u64 * 512));
        // An empty array still takes one (empty) chunk.
        assert_eq!(plan(0, 48, 1 << 20), Ok((14, vec![0])));
        // Indices are u32: a chunk never exceeds 2^31 elements.
        assert_eq!(plan(1 << 33, 4, u64::MAX).map(|p| p.0), Ok(31));
    }
}
