//! An exclusive prefix sum of `u32`s on the GPU (scan.wgsl): blocks of 256 scanned in
//! workgroup memory, the blocks' totals scanned the same way one level up, and added
//! back. Three levels cover 2^24 values; the moving grid has at most 2^21 + 1 cells.

use super::moving::entry;
use super::{GpuDevice, GpuError};

const BLOCK: u64 = 256;

/// Appends to `enc` the passes that write the exclusive sums of `src[..n]` to `dst`.
pub(super) fn exclusive_scan(
    dev: &GpuDevice,
    enc: &mut wgpu::CommandEncoder,
    src: &wgpu::Buffer,
    dst: &wgpu::Buffer,
    n: u64,
) -> Result<(), GpuError> {
    let blocks = n.div_ceil(BLOCK).max(1);
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
    let sums = dev.buffer("scan block sums", blocks * 4, usage)?;
    let (gx, gy, stride) = GpuDevice::grid_of(n, BLOCK as u32);
    let n32 = u32::try_from(n).map_err(|_| dev.too_large("a prefix sum", n * 4))?;
    let params = dev.uniform(bytemuck::cast_slice(&[n32, stride, 0, 0]));
    let group = |pipe_src: &wgpu::Buffer| {
        dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scan"),
            layout: &dev.scan_layout,
            entries: &[
                entry(0, &params),
                entry(1, pipe_src),
                entry(2, dst),
                entry(3, &sums),
            ],
        })
    };
    {
        let g = group(src);
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&dev.scan_pipe);
        pass.set_bind_group(0, &g, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
    }
    if blocks > 1 {
        let scanned = dev.buffer("scan block offsets", blocks * 4, usage)?;
        exclusive_scan(dev, enc, &sums, &scanned, blocks)?;
        let g = dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scan add"),
            layout: &dev.scan_layout,
            entries: &[
                entry(0, &params),
                entry(1, src),
                entry(2, dst),
                entry(3, &scanned),
            ],
        });
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&dev.add_pipe);
        pass.set_bind_group(0, &g, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
    }
    Ok(())
}
