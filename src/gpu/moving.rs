//! The moving triangles of a frame on the GPU: uploaded as posed on the CPU, then
//! gridded on the GPU by a count, a prefix scan and a scatter (moving.wgsl, scan.wgsl).
//!
//! One uniform 3D grid over the frame's moving triangles, rebuilt every frame, rather
//! than the CPU layer's per-direction 2D grids kept by generation stamps: a rebuild is
//! three passes over the triangles and one over the cells, all in parallel, with nothing
//! to invalidate; the stamps pay on the CPU because its insertion is serial per tile and
//! its lists are reused in place, which a GPU build does not need. One grid (not one a
//! direction) inserts each triangle once. The build reads one number back (the entry
//! count, to size the list) before the scatter: one round trip a frame.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use rayon::prelude::*;

use super::scan::exclusive_scan;
use super::static_part::pack_triangles;
use super::{GpuDevice, GpuError};
use crate::geometry::Aabb;
use crate::psf::margin_for;

/// Cells the grid aims at per triangle, and its bounds: 2 a triangle, at most 128 a side
/// and 2^21 in all.
const CELLS_PER_TRIANGLE: f64 = 2.0;
const MAX_SIDE: u32 = 128;
const MAX_CELLS: u64 = 1 << 21;

/// `GridParams` in moving.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct GridParams {
    g_lo: [f32; 4],
    dims: [u32; 4],
    m: [f32; 4],
}

/// The grid's shape for one frame: origin, cell side, cells a side, the margin each
/// triangle's box is grown by, and the box rays are clipped to.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Shape {
    pub lo: Vec3,
    pub cell: f32,
    pub dims: [u32; 3],
    pub margin: f32,
    pub clip: Aabb,
}

/// The moving triangles' grid on the GPU, remade by [`update`](Self::update).
pub struct GpuMoving {
    pub(super) tris: wgpu::Buffer,
    pub(super) cell_start: wgpu::Buffer,
    pub(super) cell_tris: wgpu::Buffer,
    pub(super) count: u32,
    pub(super) shape: Shape,
    /// Entries in the last grid (a triangle counts once per cell it is listed in).
    entries: u64,
    /// Whether updates are timed on the GPU, and the last update's GPU seconds.
    timing: bool,
    gpu_seconds: Option<f64>,
}

impl std::fmt::Debug for GpuMoving {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "GpuMoving({} triangles, {:?} cells, {} entries)",
            self.count, self.shape.dims, self.entries
        )
    }
}

/// The grid for triangles within `b`: cells about the size that gives
/// [`CELLS_PER_TRIANGLE`] a triangle, but no smaller than half the median triangle's
/// largest side (a frame whose triangles gather in a small ball does not list each in
/// hundreds of cells), within [`MAX_SIDE`] and [`MAX_CELLS`].
fn shape_for(tris: &[[Vec3; 3]], b: &Aabb) -> Shape {
    let margin = margin_for(b);
    let lo = b.min - Vec3::splat(2.0 * margin);
    let hi = b.max + Vec3::splat(2.0 * margin);
    let ext = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
    let volume = f64::from(ext.x) * f64::from(ext.y) * f64::from(ext.z);
    let want = (volume / (CELLS_PER_TRIANGLE * tris.len().max(1) as f64)).cbrt();
    let mut sides: Vec<f32> = tris
        .par_iter()
        .with_min_len(4096)
        .map(|t| {
            let e = t[0].max(t[1]).max(t[2]) - t[0].min(t[1]).min(t[2]);
            e.max_element()
        })
        .collect();
    let mid = sides.len() / 2;
    let median = if sides.is_empty() {
        0.0
    } else {
        *sides.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    let mut cell = (want as f32).max(0.5 * median);
    let dims_for = |cell: f32| {
        let n = |e: f32| ((e / cell).ceil() as u32).clamp(1, MAX_SIDE);
        [n(ext.x), n(ext.y), n(ext.z)]
    };
    let mut dims = dims_for(cell);
    while dims.iter().map(|&d| u64::from(d)).product::<u64>() > MAX_CELLS {
        cell *= 1.25;
        dims = dims_for(cell);
    }
    // The side that covers the box with these counts along its longest axis.
    let cell = (0..3)
        .map(|k| ext[k] / dims[k] as f32)
        .fold(f32::MIN_POSITIVE, f32::max)
        * (1.0 + 1e-6);
    Shape {
        lo,
        cell,
        dims,
        margin,
        clip: Aabb { min: lo, max: hi },
    }
}

impl GpuMoving {
    /// An empty moving part (no triangles).
    pub fn new(dev: &GpuDevice) -> Result<GpuMoving, GpuError> {
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        Ok(GpuMoving {
            tris: dev.buffer("the moving triangles", 16, usage)?,
            cell_start: dev.buffer("the moving grid's cells", 16, usage)?,
            cell_tris: dev.buffer("the moving grid's lists", 16, usage)?,
            count: 0,
            shape: Shape::default(),
            entries: 0,
            timing: false,
            gpu_seconds: None,
        })
    }

    /// This frame's moving triangles, gridded on the GPU. Triangle `i` is reported as
    /// hit number `static count + i`.
    pub fn update(&mut self, dev: &GpuDevice, tris: &[[Vec3; 3]]) -> Result<(), GpuError> {
        // Until this frame's grid is complete the part is empty: a failed update leaves
        // nothing half made for a tracer to read.
        self.count = 0;
        self.entries = 0;
        crate::psf::check_triangles(tris)?;
        let count = u32::try_from(tris.len())
            .map_err(|_| dev.too_large("the moving triangles", tris.len() as u64))?;
        if tris.is_empty() {
            return Ok(());
        }
        let bounds = Aabb::from_triangles(tris);
        let shape = shape_for(tris, &bounds);
        let cells = shape.dims.iter().map(|&d| u64::from(d)).product::<u64>();
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC;
        let packed = pack_triangles(tris);
        self.tris = dev.storage_with("the moving triangles", bytemuck::cast_slice(&packed))?;
        let counts = dev.buffer("the moving grid's counts", (cells + 1) * 4, usage)?;
        self.cell_start = dev.buffer("the moving grid's cells", (cells + 1) * 4, usage)?;
        let (gx, gy, stride) = GpuDevice::grid_of(u64::from(count), 64);
        let params = GridParams {
            g_lo: [shape.lo.x, shape.lo.y, shape.lo.z, shape.cell],
            dims: [shape.dims[0], shape.dims[1], shape.dims[2], count],
            m: [shape.margin, f32::from_bits(stride), 0.0, 0.0],
        };
        let uniform = dev.uniform(bytemuck::bytes_of(&params));

        // Count, then scan the counts (plus one zero: the total lands at the end).
        let stamps = if self.timing { dev.stamps(2) } else { None };
        let writes = |begin: Option<u32>, end: Option<u32>| {
            stamps.as_ref().map(|set| wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: begin,
                end_of_pass_write_index: end,
            })
        };
        let mut enc = dev.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&counts, 0, None);
        let bind = |cell_tris: &wgpu::Buffer| {
            dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("grid"),
                layout: &dev.grid_layout,
                entries: &[
                    entry(0, &uniform),
                    entry(1, &self.tris),
                    entry(2, &counts),
                    entry(3, &self.cell_start),
                    entry(4, cell_tris),
                ],
            })
        };
        {
            let placeholder = dev.buffer("the moving grid's lists", 16, usage)?;
            let group = bind(&placeholder);
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("count"),
                timestamp_writes: writes(Some(0), None),
            });
            pass.set_pipeline(&dev.count_pipe);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        exclusive_scan(dev, &mut enc, &counts, &self.cell_start, cells + 1)?;
        if stamps.is_some() {
            // An empty pass whose end closes the first span (count and scan).
            drop(enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("scanned"),
                timestamp_writes: writes(None, Some(1)),
            }));
        }
        // The total: the last exclusive sum.
        let mut total_enc = enc;
        let last = dev.buffer("the moving grid's total", 4, usage)?;
        total_enc.copy_buffer_to_buffer(&self.cell_start, cells * 4, &last, 0, 4);
        let bytes = dev.read_back(total_enc, &last, 4)?;
        let entries = u64::from(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]));
        // A count past u32 wraps on the GPU: refuse before it could.
        let listed = (cells + 1).max(entries);
        if listed.saturating_mul(4) > dev.max_binding || entries >= u64::from(u32::MAX) {
            return Err(dev.too_large("the moving grid's lists", entries.saturating_mul(4)));
        }
        self.cell_tris = dev.buffer("the moving grid's lists", entries * 4, usage)?;

        // Scatter, the counts cleared to serve as each cell's cursor.
        let mut enc = dev.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&counts, 0, None);
        {
            let group = bind(&self.cell_tris);
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("scatter"),
                timestamp_writes: writes(Some(2), Some(3)),
            });
            pass.set_pipeline(&dev.scatter_pipe);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        dev.queue.submit([enc.finish()]);
        dev.check()?;
        self.gpu_seconds = match &stamps {
            Some(set) => Some(dev.stamped_seconds(set, 2)?),
            None => None,
        };
        self.count = count;
        self.shape = shape;
        self.entries = entries;
        Ok(())
    }

    /// Times updates on the GPU (timestamp queries, where the adapter has them; an update
    /// then waits for its time): for benchmarks.
    pub fn set_timing(&mut self, on: bool) {
        self.timing = on;
    }

    /// The last update's GPU seconds (count and scan, then scatter; not the upload nor
    /// the entry count's read-back between them), when timed.
    pub fn gpu_seconds(&self) -> Option<f64> {
        self.gpu_seconds
    }

    /// The moving triangles of the last update.
    pub fn len(&self) -> usize {
        self.count as usize
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The last grid's cells along x, y, z and its entries.
    pub fn grid(&self) -> ([u32; 3], u64) {
        (self.shape.dims, self.entries)
    }
}

pub(super) fn entry(binding: u32, b: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: b.as_entire_binding(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gen::synth::{self, Rng};

    /// The grid covers the clip box (so every grown triangle box lands in cells), stays
    /// within its caps, and does not cut a tight cluster finer than its triangles.
    #[test]
    fn grid_shape_covers_the_bounds_within_the_caps() {
        let mut rng = Rng::new(3);
        let cases: Vec<Vec<[Vec3; 3]>> = vec![
            synth::soup(&mut rng, 1000, Vec3::ZERO, Vec3::splat(10.0), 0.3),
            synth::soup(
                &mut rng,
                200_000,
                Vec3::ZERO,
                Vec3::new(100.0, 1.0, 100.0),
                0.01,
            ),
            // a tight ball of large triangles: no finer than half the median size
            synth::soup(&mut rng, 5000, Vec3::ZERO, Vec3::splat(0.5), 2.0),
            vec![[Vec3::ONE; 3]],
        ];
        for tris in &cases {
            let b = Aabb::from_triangles(tris);
            let s = shape_for(tris, &b);
            let cells: u64 = s.dims.iter().map(|&d| u64::from(d)).product();
            assert!(cells <= MAX_CELLS, "{:?}", s.dims);
            assert!(s.dims.iter().all(|&d| (1..=MAX_SIDE).contains(&d)));
            for k in 0..3 {
                let end = s.lo[k] + s.cell * s.dims[k] as f32;
                assert!(end >= s.clip.max[k], "axis {k}: {end} < {}", s.clip.max[k]);
                assert!(s.lo[k] <= b.min[k] - s.margin);
                assert!(s.clip.max[k] >= b.max[k] + s.margin);
            }
        }
        let ball = &cases[2];
        let s = shape_for(ball, &Aabb::from_triangles(ball));
        assert!(s.dims.iter().all(|&d| d <= 8), "{:?}", s.dims);
    }
}
