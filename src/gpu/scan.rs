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

/// Levels of blocks a plan covers (`plan` in scan.wgsl): 256^4 values.
const PLAN_LEVELS: usize = 4;

/// The sizes of a scan whose length the GPU decides, up to a capacity: the lengths,
/// row strides and workgroups of its passes, written by the `plan` kernel from a count
/// the GPU holds (scan.wgsl) so that a scan of few values costs few workgroups; kept
/// with the buffers it reads, with the uniforms of its levels. Any number of
/// [`LiveScan`]s of that length share one plan.
pub(super) struct ScanPlan {
    /// Each level's capacity: the values, then the blocks of the level below.
    caps: Vec<u64>,
    /// Each level's uniform (length, row stride), copied from `out`.
    params: Vec<wgpu::Buffer>,
    /// The plan's words: the uniforms (4 a level), then the workgroups (6 a level).
    out: wgpu::Buffer,
    /// One bind group a buffer the count may be read from.
    groups: Vec<wgpu::BindGroup>,
}

impl ScanPlan {
    /// A plan for scans of at most `capacity` values whose length is word `word` of one
    /// of `counts` plus `plus`.
    pub(super) fn new(
        dev: &GpuDevice,
        capacity: u64,
        word: u32,
        plus: u32,
        counts: &[&wgpu::Buffer],
    ) -> Result<ScanPlan, GpuError> {
        let mut caps = vec![capacity.max(1)];
        while let Some(&c) = caps.last().filter(|&&c| c > BLOCK) {
            caps.push(c.div_ceil(BLOCK));
        }
        let cap32 = u32::try_from(capacity)
            .ok()
            .filter(|_| caps.len() <= PLAN_LEVELS)
            .ok_or_else(|| dev.too_large("a prefix sum", capacity * 4))?;
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::INDIRECT;
        let out = dev.buffer("a scan's plan", (PLAN_LEVELS as u64) * 10 * 4, usage)?;
        let unused = dev.buffer("an unused binding", 4, wgpu::BufferUsages::STORAGE)?;
        let setup = dev.uniform(bytemuck::cast_slice(&[cap32, 0, word, plus]));
        let groups = counts
            .iter()
            .map(|&c| {
                dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("scan plan"),
                    layout: &dev.scan_layout,
                    entries: &[
                        entry(0, &setup),
                        entry(1, c),
                        entry(2, &out),
                        entry(3, &unused),
                    ],
                })
            })
            .collect();
        let params = caps
            .iter()
            .map(|_| dev.uniform(&[0; 16]))
            .collect::<Vec<_>>();
        Ok(ScanPlan {
            caps,
            params,
            out,
            groups,
        })
    }

    /// Appends the plan for the count in `counts[which]` (as given to [`new`](Self::new)).
    pub(super) fn encode(&self, dev: &GpuDevice, enc: &mut wgpu::CommandEncoder, which: usize) {
        let Some(group) = self.groups.get(which) else {
            return;
        };
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&dev.plan_pipe);
            pass.set_bind_group(0, group, &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        for (j, p) in self.params.iter().enumerate() {
            enc.copy_buffer_to_buffer(&self.out, 16 * j as u64, p, 0, 16);
        }
    }
}

/// An exclusive prefix sum of a buffer into another, of the length a [`ScanPlan`]
/// plans: its block sums, block offsets and bind groups, made once and kept.
pub(super) struct LiveScan {
    scans: Vec<wgpu::BindGroup>,
    adds: Vec<wgpu::BindGroup>,
}

impl LiveScan {
    pub(super) fn new(
        dev: &GpuDevice,
        plan: &ScanPlan,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
    ) -> Result<LiveScan, GpuError> {
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        // Level j scans `ins[j]` into `outs[j]` and writes its blocks' totals into
        // `sums[j]`, which is level j + 1's input; its output is level j's offsets.
        let mut ins = vec![src.clone()];
        let mut outs = vec![dst.clone()];
        let mut sums = Vec::new();
        for (j, &c) in plan.caps.iter().enumerate() {
            let (gx, gy, _) = GpuDevice::grid_of(c, BLOCK as u32);
            let s = dev.buffer("scan block sums", u64::from(gx) * u64::from(gy) * 4, usage)?;
            if j + 1 < plan.caps.len() {
                ins.push(s.clone());
                outs.push(dev.buffer("scan block offsets", c.div_ceil(BLOCK) * 4, usage)?);
            }
            sums.push(s);
        }
        let group = |label, j: usize, third: &wgpu::Buffer| {
            dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout: &dev.scan_layout,
                entries: &[
                    entry(0, &plan.params[j]),
                    entry(1, &ins[j]),
                    entry(2, &outs[j]),
                    entry(3, third),
                ],
            })
        };
        let scans = (0..plan.caps.len())
            .map(|j| group("scan", j, &sums[j]))
            .collect();
        let adds = (0..plan.caps.len() - 1)
            .map(|j| group("scan add", j, &outs[j + 1]))
            .collect();
        Ok(LiveScan { scans, adds })
    }

    /// Appends the passes (after the plan's).
    pub(super) fn encode(&self, dev: &GpuDevice, enc: &mut wgpu::CommandEncoder, plan: &ScanPlan) {
        let mut pass = |pipe: &wgpu::ComputePipeline, g: &wgpu::BindGroup, at: u64| {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipe);
            pass.set_bind_group(0, g, &[]);
            pass.dispatch_workgroups_indirect(&plan.out, at * 4);
        };
        let at = |j: usize| (4 * PLAN_LEVELS + 6 * j) as u64;
        for (j, g) in self.scans.iter().enumerate() {
            pass(&dev.scan_pipe, g, at(j));
        }
        for (j, g) in self.adds.iter().enumerate().rev() {
            pass(&dev.add_pipe, g, at(j) + 3);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A live scan gives the CPU's exclusive sums of its count's values and one more,
    /// and writes nothing past them: counts on both sides of the block edges, one to
    /// three levels of blocks, in one kept plan whose scratch the larger counts left
    /// full.
    #[test]
    fn live_scans_equal_the_cpus_and_stop_at_the_count() {
        let Some(dev) = super::super::test_device() else {
            return;
        };
        let cap: u64 = (1 << 17) + 1;
        let values: Vec<u32> = (0..cap as u32)
            .map(|i| i.wrapping_mul(2_654_435_761) >> 30)
            .collect();
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let src = dev.buffer("values", cap * 4, usage).unwrap();
        dev.write(&src, 0, bytemuck::cast_slice(&values));
        let dst = dev.buffer("sums", cap * 4, usage).unwrap();
        // The count is word 1 of this buffer.
        let count = dev.buffer("count", 16, usage).unwrap();
        let plan = ScanPlan::new(&dev, cap, 1, 1, &[&count]).unwrap();
        assert_eq!(plan.caps, [cap, 513, 3]);
        let scan = LiveScan::new(&dev, &plan, &src, &dst).unwrap();
        for n in [
            131_072u32, 0, 1, 254, 255, 256, 257, 511, 65_535, 65_536, 65_537, 300, 100_000,
        ] {
            dev.write(&count, 0, bytemuck::cast_slice(&[7u32, n, 7, 7]));
            dev.write(&dst, 0, &vec![0xffu8; cap as usize * 4]);
            let mut enc = dev.device.create_command_encoder(&Default::default());
            plan.encode(&dev, &mut enc, 0);
            scan.encode(&dev, &mut enc, &plan);
            let got: Vec<u32> = bytemuck::pod_collect_to_vec(
                &dev.read_back(enc, &dst, cap * 4).unwrap()[..cap as usize * 4],
            );
            let mut sum = 0u32;
            for (i, &g) in got.iter().enumerate() {
                if i <= n as usize {
                    assert_eq!(g, sum, "count {n}: sum {i}");
                    sum += values[i];
                } else {
                    assert_eq!(g, u32::MAX, "count {n}: word {i} written");
                }
            }
        }
    }
}
