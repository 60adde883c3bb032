//! [`GpuTracer`]: closest hits and any hits of ray batches over a [`GpuStatic`] and a
//! [`GpuMoving`] together (trace.wgsl), numbered as [`Layered`](crate::psf::Layered)
//! numbers them (static triangles first) and equal to its answers.
//!
//! The seam's methods cannot fail, the GPU can: [`try_intersect_batch`] and
//! [`try_occluded_batch`] return a [`GpuError`]; the [`Intersector`] methods call them,
//! and on an error answer "no hit" for the batch and keep the first error, which
//! [`take_error`](GpuTracer::take_error) hands over. The frame loop asks after every
//! frame and fails the frame with it, so a frame traced through a failure is never
//! written.
//!
//! [`try_intersect_batch`]: GpuTracer::try_intersect_batch
//! [`try_occluded_batch`]: GpuTracer::try_occluded_batch

use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

use super::moving::entry;
use super::{GpuDevice, GpuError, GpuMoving, GpuStatic};
use crate::geometry::{Hit, Intersector, Ray, Shear};

/// `Params` in trace.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Params {
    a: [u32; 4],
    b: [u32; 4],
    clip_lo: [f32; 4],
    clip_hi: [f32; 4],
    g_lo: [f32; 4],
    g_dims: [u32; 4],
    m_lo: [f32; 4],
    m_hi: [f32; 4],
    k: [u32; 4],
    k2: [u32; 4],
}

/// `Ray` in trace.wgsl: origin and `t_min`, direction and `t_max`, and the shear the CPU
/// computed (`kx | ky << 2 | kz << 4`, bit 8 for a valid ray).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(super) struct GpuRay {
    o: [f32; 4],
    d: [f32; 4],
    s: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<GpuRay>() == 48);

pub(super) fn pack_ray(r: &Ray) -> GpuRay {
    let (o, d) = (r.origin, r.dir);
    let (s, bits) = if r.is_valid() {
        let s = Shear::new(d);
        let k = s.kx as u32 | (s.ky as u32) << 2 | (s.kz as u32) << 4 | 1 << 8;
        ([s.sx, s.sy, s.sz], k)
    } else {
        ([0.0; 3], 0)
    };
    GpuRay {
        o: [o.x, o.y, o.z, r.t_min],
        d: [d.x, d.y, d.z, r.t_max],
        s: [s[0], s[1], s[2], f32::from_bits(bits)],
    }
}

/// Rays a dispatch at most: 48 bytes in and 16 out each, far inside a 128 MiB binding.
const CHUNK: usize = 1 << 20;

/// Traces on the GPU: the static part and this frame's moving part.
pub struct GpuTracer<'a> {
    dev: &'a GpuDevice,
    stat: &'a GpuStatic,
    moving: &'a GpuMoving,
    error: Mutex<Option<GpuError>>,
    /// GPU seconds of the trace passes so far, when timed ([`timed`](Self::timed)).
    gpu_seconds: Option<Mutex<f64>>,
}

impl<'a> GpuTracer<'a> {
    pub fn new(dev: &'a GpuDevice, stat: &'a GpuStatic, moving: &'a GpuMoving) -> Self {
        GpuTracer {
            dev,
            stat,
            moving,
            error: Mutex::new(None),
            gpu_seconds: None,
        }
    }

    /// Times every trace pass on the GPU (timestamp queries, where the adapter has them;
    /// each batch then waits once more for its time): for benchmarks.
    pub fn timed(mut self) -> Self {
        if self.dev.has_timestamps() {
            self.gpu_seconds = Some(Mutex::new(0.0));
        }
        self
    }

    /// The GPU seconds of the trace passes so far, when [`timed`](Self::timed) on an
    /// adapter with timestamp queries.
    pub fn gpu_seconds(&self) -> Option<f64> {
        self.gpu_seconds
            .as_ref()
            .and_then(|m| m.lock().ok().map(|g| *g))
    }

    /// The first error a batch of the [`Intersector`] methods met, if any (taken).
    pub fn take_error(&self) -> Option<GpuError> {
        self.error.lock().ok().and_then(|mut g| g.take())
    }

    fn keep(&self, e: GpuError) {
        if let Ok(mut g) = self.error.lock() {
            g.get_or_insert(e);
        }
    }

    /// The closest hit of each ray, as [`Layered`](crate::psf::Layered) answers it.
    pub fn try_intersect_batch(
        &self,
        rays: &[Ray],
        out: &mut [Option<Hit>],
    ) -> Result<(), GpuError> {
        assert_eq!(rays.len(), out.len(), "one output slot per ray");
        for (r, o) in rays.chunks(CHUNK).zip(out.chunks_mut(CHUNK)) {
            let raw = self.dispatch(r, false)?;
            o.par_iter_mut()
                .zip(raw.par_iter())
                .with_min_len(4096)
                .for_each(|(o, h)| {
                    *o = (h[1] != u32::MAX).then(|| Hit {
                        t: f32::from_bits(h[0]),
                        tri: h[1],
                        u: f32::from_bits(h[2]),
                        v: f32::from_bits(h[3]),
                    })
                });
        }
        Ok(())
    }

    /// Whether anything blocks each ray.
    pub fn try_occluded_batch(&self, rays: &[Ray], out: &mut [bool]) -> Result<(), GpuError> {
        assert_eq!(rays.len(), out.len(), "one output slot per ray");
        for (r, o) in rays.chunks(CHUNK).zip(out.chunks_mut(CHUNK)) {
            let raw = self.dispatch(r, true)?;
            for (o, h) in o.iter_mut().zip(&raw) {
                *o = h[1] != u32::MAX;
            }
        }
        Ok(())
    }

    /// One dispatch over `rays` (at most [`CHUNK`]): `[t, tri, u, v]` bits per ray, `tri`
    /// `u32::MAX` for none.
    fn dispatch(&self, rays: &[Ray], any: bool) -> Result<Vec<[u32; 4]>, GpuError> {
        if rays.is_empty() {
            return Ok(Vec::new());
        }
        let dev = self.dev;
        let packed: Vec<GpuRay> = rays.par_iter().with_min_len(4096).map(pack_ray).collect();
        let n = rays.len() as u64;
        let ray_buf = dev.storage_with("the rays", bytemuck::cast_slice(&packed))?;
        let hits = dev.buffer(
            "the hits",
            n * 16,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        )?;
        let group = self.bind(&ray_buf, &hits, n, any)?;
        let (gx, gy, _) = GpuDevice::grid_of(n, 64);
        let mut enc = dev.device.create_command_encoder(&Default::default());
        let stamps = self.gpu_seconds.as_ref().and_then(|_| dev.stamps(1));
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("trace"),
                timestamp_writes: stamps.as_ref().map(|set| wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(0),
                    end_of_pass_write_index: Some(1),
                }),
            });
            pass.set_pipeline(&dev.trace_pipe);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        let bytes = dev.read_back(enc, &hits, n * 16)?;
        if let (Some(set), Some(total)) = (&stamps, &self.gpu_seconds) {
            let secs = dev.stamped_seconds(set, 1)?;
            if let Ok(mut g) = total.lock() {
                *g += secs;
            }
        }
        Ok(bytemuck::pod_collect_to_vec(&bytes[..rays.len() * 16]))
    }

    /// The trace kernel's uniform for `n` rays (closest hits, or any hits when `any`),
    /// as 40 words; the first is `n`, which the GPU frame path (`frame.rs`) rewrites on
    /// the GPU for each level (the rest, the row stride included, stay).
    pub(super) fn params_words(&self, n: u64, any: bool) -> Result<[u32; 40], GpuError> {
        let dev = self.dev;
        let n32 = u32::try_from(n).map_err(|_| dev.too_large("a ray batch", n * 48))?;
        let (_, _, stride) = GpuDevice::grid_of(n, 64);
        let (s, m) = (self.stat, self.moving);
        let (c, sh) = (&s.clip, &m.shape);
        let params = Params {
            // The zero that keeps products from being fused (trace.wgsl, `nc`).
            a: [n32, s.subfields, s.table_res, 0],
            b: [u32::from(any), m.count, s.triangles, stride],
            clip_lo: [c.min.x, c.min.y, c.min.z, s.margin],
            clip_hi: [c.max.x, c.max.y, c.max.z, 0.0],
            g_lo: [sh.lo.x, sh.lo.y, sh.lo.z, sh.cell],
            g_dims: [sh.dims[0], sh.dims[1], sh.dims[2], 0],
            m_lo: [sh.clip.min.x, sh.clip.min.y, sh.clip.min.z, sh.margin],
            m_hi: [sh.clip.max.x, sh.clip.max.y, sh.clip.max.z, 0.0],
            k: [s.tris.shift, s.tiles.shift, s.starts.shift, s.entries.shift],
            k2: [s.blocks.shift, 0, 0, 0],
        };
        Ok(bytemuck::cast(params))
    }

    /// The trace kernel's bind group for `n` rays in `rays` (`GpuRay`s, 48 bytes each)
    /// whose hits go to `hits` (`[t, tri, u, v]` bits, 16 bytes each): closest hits, or
    /// any hits when `any`. The rays and hits may be made and read by other kernels
    /// (the GPU frame path, `frame.rs`): nothing here reads them on the host.
    pub(super) fn bind(
        &self,
        rays: &wgpu::Buffer,
        hits: &wgpu::Buffer,
        n: u64,
        any: bool,
    ) -> Result<wgpu::BindGroup, GpuError> {
        let words = self.params_words(n, any)?;
        let uniform = self.dev.uniform(bytemuck::bytes_of(&words));
        Ok(self.bind_uniform(&uniform, rays, hits))
    }

    /// The trace kernel's bind group with its uniform in `uniform` (see
    /// [`params_words`](Self::params_words)).
    pub(super) fn bind_uniform(
        &self,
        uniform: &wgpu::Buffer,
        rays: &wgpu::Buffer,
        hits: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        let (dev, s, m) = (self.dev, self.stat, self.moving);
        let d = &s.dummy;
        let mut entries = vec![
            entry(0, uniform),
            entry(1, rays),
            entry(2, hits),
            entry(3, s.tris.binding(0, d)),
            entry(4, &s.subs),
            entry(5, s.tiles.binding(0, d)),
            entry(6, s.starts.binding(0, d)),
            entry(7, s.entries.binding(0, d)),
            entry(8, s.blocks.binding(0, d)),
            entry(9, &s.table),
            entry(10, &m.tris),
            entry(11, &m.cell_start),
            entry(12, &m.cell_tris),
        ];
        // Bindings 13.. : chunks 1..CHUNKS of each split array (trace.wgsl).
        let mut b = 13;
        for arr in [&s.tris, &s.tiles, &s.starts, &s.entries, &s.blocks] {
            for k in 1..super::static_part::CHUNKS {
                entries.push(entry(b, arr.binding(k, d)));
                b += 1;
            }
        }
        dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("trace"),
            layout: &dev.trace_layout,
            entries: &entries,
        })
    }

    /// Appends to `enc` the trace pass of `group` with the workgroup counts the GPU
    /// wrote into `args` at byte `at` (the grid as wide as the uniform's row stride).
    pub(super) fn encode_group_indirect(
        &self,
        enc: &mut wgpu::CommandEncoder,
        group: &wgpu::BindGroup,
        args: &wgpu::Buffer,
        at: u64,
    ) {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("trace"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.dev.trace_pipe);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups_indirect(args, at);
    }
}

impl Intersector for GpuTracer<'_> {
    /// A batch of one (a GPU answers batches; the renderer sends batches).
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let mut out = [None];
        self.intersect_batch(std::slice::from_ref(ray), &mut out);
        out[0]
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let mut out = [false];
        self.occluded_batch(std::slice::from_ref(ray), &mut out);
        out[0]
    }

    fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        if let Err(e) = self.try_intersect_batch(rays, out) {
            out.fill(None);
            self.keep(e);
        }
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        if let Err(e) = self.try_occluded_batch(rays, out) {
            out.fill(false);
            self.keep(e);
        }
    }
}
