//! A static [`Psf`] (an in-memory bake or an opened `.psf`, mapped or decompressed)
//! uploaded once as storage buffers: the triangles, each subfield's frame, the direction
//! table, and every subfield's tiles, slab starts, entries and blocks, each kind in one
//! buffer with the subfields one after another (a subfield's frame record says where
//! its part begins, so the baked arrays go up unchanged). An array larger than one
//! binding may hold is refused with the size needed and the size available.

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

/// A [`Psf`] on the GPU.
pub struct GpuStatic {
    pub(super) tris: wgpu::Buffer,
    pub(super) subs: wgpu::Buffer,
    pub(super) tiles: wgpu::Buffer,
    pub(super) starts: wgpu::Buffer,
    pub(super) entries: wgpu::Buffer,
    pub(super) blocks: wgpu::Buffer,
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

/// The size of `n` values of `T`, refused when one binding cannot hold it.
fn sized<T>(dev: &GpuDevice, what: &'static str, n: usize) -> Result<u64, GpuError> {
    let bytes = (n as u64).saturating_mul(std::mem::size_of::<T>() as u64);
    if bytes > dev.max_binding {
        return Err(dev.too_large(what, bytes));
    }
    Ok(bytes)
}

fn index(dev: &GpuDevice, what: &'static str, n: usize) -> Result<u32, GpuError> {
    u32::try_from(n).map_err(|_| dev.too_large(what, n as u64))
}

impl GpuStatic {
    /// Uploads `psf`. Every size is checked before the first byte is sent.
    pub fn upload(dev: &GpuDevice, psf: &Psf) -> Result<GpuStatic, GpuError> {
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
        let tri_bytes = sized::<[f32; 12]>(dev, "the static triangles", ntris)?;
        let tile_bytes = sized::<TileHeader>(dev, "the tile headers", nt)?;
        let start_bytes = sized::<u32>(dev, "the slab starts", ns)?;
        let entry_bytes = sized::<Entry>(dev, "the tile entries", ne)?;
        let block_bytes = sized::<Block>(dev, "the flat tiles' blocks", nb)?;
        let triangles = index(dev, "the static triangles", ntris)?;

        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let tris = dev.storage_with(
            "the static triangles",
            bytemuck::cast_slice(&pack_triangles(psf.triangles())),
        )?;
        let subs_buf = dev.storage_with("the subfields' frames", bytemuck::cast_slice(&meta))?;
        let table = psf.direction_table();
        let cells: Vec<u32> = table.cells().iter().map(|&c| u32::from(c)).collect();
        let table_buf = dev.storage_with("the direction table", bytemuck::cast_slice(&cells))?;
        // The subfields' arrays, one after another, written straight from the bake's
        // (or the mapping's) slices.
        let tiles = dev.buffer("the tile headers", tile_bytes, usage)?;
        let starts = dev.buffer("the slab starts", start_bytes, usage)?;
        let entries = dev.buffer("the tile entries", entry_bytes, usage)?;
        let blocks = dev.buffer("the flat tiles' blocks", block_bytes, usage)?;
        let (mut ot, mut os, mut oe, mut ob) = (0u64, 0u64, 0u64, 0u64);
        for s in subs {
            dev.write(&tiles, ot, bytemuck::cast_slice(&s.tiles));
            dev.write(&starts, os, bytemuck::cast_slice(&s.slab_starts));
            dev.write(&entries, oe, bytemuck::cast_slice(&s.entries));
            dev.write(&blocks, ob, bytemuck::cast_slice(&s.blocks));
            ot += std::mem::size_of_val::<[TileHeader]>(&s.tiles) as u64;
            os += std::mem::size_of_val::<[u32]>(&s.slab_starts) as u64;
            oe += std::mem::size_of_val::<[Entry]>(&s.entries) as u64;
            ob += std::mem::size_of_val::<[Block]>(&s.blocks) as u64;
        }
        dev.wait()?;
        Ok(GpuStatic {
            tris,
            subs: subs_buf,
            tiles,
            starts,
            entries,
            blocks,
            table: table_buf,
            subfields: subs.len() as u32,
            table_res: table.res(),
            triangles,
            clip: *psf.clip(),
            margin: psf.margin(),
            bytes: tri_bytes + tile_bytes + start_bytes + entry_bytes + block_bytes,
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
}
