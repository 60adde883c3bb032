//! The adapter and the compiled kernels. Vulkan alone (the one back end we test, on
//! lavapipe and on NVIDIA); the adapter must offer `SHADER_F64` (the walk and the exact
//! division run in f64, docs/GPU.md), as lavapipe and NVIDIA's driver do.

use std::future::Future;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, Waker};

use super::GpuError;

/// The trace kernel's storage bindings (trace.wgsl: 12, and 3 more parts of each of the
/// static part's 5 split arrays).
const TRACE_BINDINGS: u32 = 27;
/// The frame path's storage bindings (shade.wgsl: 0..=30 but the two uniforms; a test in
/// `gpu::frame` holds it to the layout).
pub(super) const FRAME_BINDINGS: u32 = 29;

/// Which adapters may be taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdapterPolicy {
    /// The best adapter found: a discrete GPU, else an integrated one, else a CPU
    /// driver such as lavapipe (`--device gpu`).
    Any,
    /// A discrete GPU only (`--device auto`, which otherwise traces on the CPU).
    Discrete,
}

/// An opened adapter with the tracer's kernels compiled.
pub struct GpuDevice {
    pub(super) device: wgpu::Device,
    pub(super) queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    /// The most one storage binding may hold (`max_storage_buffer_binding_size`).
    pub(super) max_binding: u64,
    /// The first error the driver reported outside a call that returns one.
    errors: Arc<Mutex<Option<String>>>,
    /// Whether the adapter has timestamp queries (`TIMESTAMP_QUERY`), which the
    /// benchmark's GPU times come from.
    timestamps: bool,
    pub(super) trace_layout: wgpu::BindGroupLayout,
    pub(super) trace_pipe: wgpu::ComputePipeline,
    pub(super) grid_layout: wgpu::BindGroupLayout,
    pub(super) count_pipe: wgpu::ComputePipeline,
    pub(super) scatter_pipe: wgpu::ComputePipeline,
    pub(super) scan_layout: wgpu::BindGroupLayout,
    pub(super) scan_pipe: wgpu::ComputePipeline,
    pub(super) add_pipe: wgpu::ComputePipeline,
    pub(super) plan_pipe: wgpu::ComputePipeline,
}

impl std::fmt::Debug for GpuDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GpuDevice({})", self.describe())
    }
}

/// Drives a future that wgpu completes on the calling thread (native back ends resolve
/// adapter and device requests at once), without an executor crate.
pub(super) fn block_on<F: Future>(fut: F) -> F::Output {
    let mut fut = std::pin::pin!(fut);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
            return v;
        }
        std::thread::yield_now();
    }
}

fn kind(t: wgpu::DeviceType) -> &'static str {
    match t {
        wgpu::DeviceType::DiscreteGpu => "discrete GPU",
        wgpu::DeviceType::IntegratedGpu => "integrated GPU",
        wgpu::DeviceType::VirtualGpu => "virtual GPU",
        wgpu::DeviceType::Cpu => "CPU",
        wgpu::DeviceType::Other => "other",
    }
}

fn rank(t: wgpu::DeviceType) -> u32 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

/// How long a read-back waits for its buffer's mapping once its submission has run
/// (the callback may run on another thread's poll): beyond it the device is taken as
/// lost.
const READ_BACK_ANSWER: std::time::Duration = std::time::Duration::from_secs(60);

impl GpuDevice {
    /// Opens the adapter `policy` picks. `Ok(None)` when `policy` is `Discrete` and
    /// there is no discrete GPU; `Err(NoAdapter)` when it is `Any` and there is none.
    pub fn open(policy: AdapterPolicy) -> Result<Option<GpuDevice>, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::VULKAN;
        let instance = wgpu::Instance::new(desc);
        let mut adapters = block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
        let seen = if adapters.is_empty() {
            "none".to_string()
        } else {
            let names: Vec<String> = adapters
                .iter()
                .map(|a| {
                    let i = a.get_info();
                    format!("{} '{}'", kind(i.device_type), i.name)
                })
                .collect();
            names.join(", ")
        };
        // The best kind first; among equals, the enumeration order.
        adapters.sort_by_key(|a| rank(a.get_info().device_type));
        let adapter = match policy {
            AdapterPolicy::Any => adapters.into_iter().next(),
            AdapterPolicy::Discrete => adapters
                .into_iter()
                .find(|a| a.get_info().device_type == wgpu::DeviceType::DiscreteGpu),
        };
        let Some(adapter) = adapter else {
            return match policy {
                AdapterPolicy::Any => Err(GpuError::NoAdapter {
                    wanted: "GPU adapter",
                    seen,
                }),
                AdapterPolicy::Discrete => Ok(None),
            };
        };
        Self::from_adapter(adapter).map(Some)
    }

    fn from_adapter(adapter: wgpu::Adapter) -> Result<GpuDevice, GpuError> {
        let info = adapter.get_info();
        if !adapter.features().contains(wgpu::Features::SHADER_F64) {
            return Err(GpuError::MissingFeature {
                adapter: info.name.clone(),
                feature: "SHADER_F64",
                why: "the walk and the exact division run in f64",
            });
        }
        // The adapter's own limits: as many storage buffers and as large ones as it has.
        let limits = adapter.limits();
        if limits.max_storage_buffers_per_shader_stage < TRACE_BINDINGS.max(FRAME_BINDINGS) {
            return Err(GpuError::MissingFeature {
                adapter: info.name.clone(),
                feature: "29 storage buffers a shader stage",
                why: "the trace kernel binds the static part's arrays in up to 4 parts each, \
                      and the frame path its rays, items, tables and textures",
            });
        }
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
            // Bindings are addressed by u32 words' indices in the kernels.
            .min(u64::from(u32::MAX) & !3);
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut features = wgpu::Features::SHADER_F64;
        if timestamps {
            features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        let (device, queue) = block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("subfield"),
            required_features: features,
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|e| GpuError::RequestDevice(e.to_string()))?;
        let errors: Arc<Mutex<Option<String>>> = Arc::default();
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let msg = match &e {
                wgpu::Error::OutOfMemory { .. } => format!("out of memory: {e}"),
                _ => e.to_string(),
            };
            if let Ok(mut g) = sink.lock() {
                g.get_or_insert(msg);
            }
        }));
        let sink = errors.clone();
        device.set_device_lost_callback(move |reason, msg| {
            if let Ok(mut g) = sink.lock() {
                g.get_or_insert(format!("device lost ({reason:?}): {msg}"));
            }
        });

        let module = |label: &str, src: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            })
        };
        let trace_mod = module("trace.wgsl", include_str!("trace.wgsl"));
        let moving_mod = module("moving.wgsl", include_str!("moving.wgsl"));
        let scan_mod = module("scan.wgsl", include_str!("scan.wgsl"));

        let storage = storage_entry;
        let uniform = uniform_entry(0);
        let layout = |label: &str, entries: &[wgpu::BindGroupLayoutEntry]| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries,
            })
        };
        let mut trace_entries = vec![uniform];
        trace_entries.extend((1..=TRACE_BINDINGS).map(|b| storage(b, b != 2)));
        let trace_layout = layout("trace", &trace_entries);
        let grid_layout = layout(
            "grid",
            &[
                uniform,
                storage(1, true),
                storage(2, false),
                storage(3, true),
                storage(4, false),
            ],
        );
        let scan_layout = layout(
            "scan",
            &[
                uniform,
                storage(1, true),
                storage(2, false),
                storage(3, false),
            ],
        );
        let pipe = |label: &str, l: &wgpu::BindGroupLayout, m: &wgpu::ShaderModule| {
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(l)],
                immediate_size: 0,
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&pl),
                module: m,
                entry_point: Some(label),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let trace_pipe = pipe("trace", &trace_layout, &trace_mod);
        let count_pipe = pipe("count", &grid_layout, &moving_mod);
        let scatter_pipe = pipe("scatter", &grid_layout, &moving_mod);
        let scan_pipe = pipe("scan", &scan_layout, &scan_mod);
        let add_pipe = pipe("add", &scan_layout, &scan_mod);
        let plan_pipe = pipe("plan", &scan_layout, &scan_mod);
        let dev = GpuDevice {
            device,
            queue,
            info,
            max_binding,
            errors,
            timestamps,
            trace_layout,
            trace_pipe,
            grid_layout,
            count_pipe,
            scatter_pipe,
            scan_layout,
            scan_pipe,
            add_pipe,
            plan_pipe,
        };
        // A kernel that does not compile is reported here, not at the first trace.
        dev.wait()?;
        Ok(dev)
    }

    /// The adapter, in words: `NVIDIA H200 (discrete GPU, Vulkan)`.
    pub fn describe(&self) -> String {
        format!(
            "{} ({}, {:?})",
            self.info.name,
            kind(self.info.device_type),
            self.info.backend
        )
    }

    /// Whether the adapter is a discrete GPU.
    pub fn is_discrete(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::DiscreteGpu
    }

    /// The largest storage binding, in bytes.
    pub fn max_binding(&self) -> u64 {
        self.max_binding
    }

    /// Whether GPU times (timestamp queries) can be taken on this adapter.
    pub fn has_timestamps(&self) -> bool {
        self.timestamps
    }

    /// `2 k` timestamp queries, `k` spans each from a pass's start to a (later) pass's
    /// end, when the adapter has them.
    pub(super) fn stamps(&self, spans: u32) -> Option<wgpu::QuerySet> {
        self.timestamps.then(|| {
            self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("gpu time"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * spans,
            })
        })
    }

    /// The seconds the `spans` spans of `set` cover together (after their passes were
    /// submitted).
    pub(super) fn stamped_seconds(
        &self,
        set: &wgpu::QuerySet,
        spans: u32,
    ) -> Result<f64, GpuError> {
        let bytes = 16 * u64::from(spans);
        let resolve = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("gpu time"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.resolve_query_set(set, 0..2 * spans, &resolve, 0);
        let b = self.read_back(enc, &resolve, bytes)?;
        let t: Vec<u64> = bytemuck::pod_collect_to_vec(&b[..bytes as usize]);
        let ticks: f64 = t
            .chunks_exact(2)
            .map(|p| p[1].saturating_sub(p[0]) as f64)
            .sum();
        Ok(ticks * f64::from(self.queue.get_timestamp_period()) * 1e-9)
    }

    /// Waits until everything submitted has run (a benchmark's clock stops after it).
    pub fn finish(&self) -> Result<(), GpuError> {
        self.wait()
    }

    /// The first error the driver reported since the last check, as a [`GpuError`].
    pub(super) fn check(&self) -> Result<(), GpuError> {
        let taken = self.errors.lock().ok().and_then(|mut g| g.take());
        match taken {
            None => Ok(()),
            Some(m) if m.starts_with("out of memory") => Err(GpuError::OutOfMemory(m)),
            Some(m) => Err(GpuError::Lost(m)),
        }
    }

    /// Waits for everything submitted, then [`check`](Self::check)s.
    pub(super) fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Lost(e.to_string()))?;
        self.check()
    }

    /// A buffer of `size` bytes, refused with one line when one binding cannot hold it.
    /// At least 256 bytes: wgpu binds no empty buffer, nor one smaller than an element of
    /// the kernel's array (a `Block` is 96 bytes).
    pub(super) fn buffer(
        &self,
        what: &'static str,
        size: u64,
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        if size > self.max_binding {
            return Err(self.too_large(what, size));
        }
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(what),
            size: size.max(256).next_multiple_of(4),
            usage,
            mapped_at_creation: false,
        }))
    }

    /// A storage buffer holding `data` (refused like [`buffer`](Self::buffer)).
    pub(super) fn storage_with(
        &self,
        what: &'static str,
        data: &[u8],
    ) -> Result<wgpu::Buffer, GpuError> {
        let b = self.buffer(
            what,
            data.len() as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        )?;
        self.write(&b, 0, data);
        Ok(b)
    }

    /// Writes `data` at `offset` (padded to a multiple of 4 bytes, as wgpu asks).
    pub(super) fn write(&self, b: &wgpu::Buffer, offset: u64, data: &[u8]) {
        if data.is_empty() {
            return;
        }
        if data.len().is_multiple_of(4) {
            self.queue.write_buffer(b, offset, data);
        } else {
            let mut v = data.to_vec();
            v.resize(data.len().next_multiple_of(4), 0);
            self.queue.write_buffer(b, offset, &v);
        }
    }

    /// A uniform buffer holding `data`.
    pub(super) fn uniform(&self, data: &[u8]) -> wgpu::Buffer {
        let b = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: (data.len() as u64).max(16).next_multiple_of(16),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.write(&b, 0, data);
        b
    }

    pub(super) fn too_large(&self, what: &'static str, needed: u64) -> GpuError {
        GpuError::TooLarge {
            what,
            needed,
            available: self.max_binding,
            adapter: self.info.name.clone(),
        }
    }

    /// Reads `size` bytes of `src` back (copied through a mappable buffer).
    pub(super) fn read_back(
        &self,
        mut encoder: wgpu::CommandEncoder,
        src: &wgpu::Buffer,
        size: u64,
    ) -> Result<Vec<u8>, GpuError> {
        let size = size.max(4).next_multiple_of(4);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read back"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(src, 0, &staging, 0, size);
        let index = self.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        // This submission's end, not the queue's: frames in flight submit from other
        // threads, and this one need not wait for their work.
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: None,
            })
            .map_err(|e| GpuError::Lost(e.to_string()))?;
        self.check()?;
        // Another thread's poll may have taken the callback and not yet run it when
        // this poll returns: its answer is waited for, not assumed missing.
        match rx.recv_timeout(READ_BACK_ANSWER) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(GpuError::Lost(format!("reading results back: {e}"))),
            Err(_) => return Err(GpuError::Lost("reading results back: no answer".into())),
        }
        let bytes = staging
            .get_mapped_range(..)
            .map_err(|e| GpuError::Lost(format!("reading results back: {e}")))?
            .to_vec();
        staging.unmap();
        Ok(bytes)
    }

    /// Workgroups for `n` invocations of `size`, as `(x, y)` within the 65,535 a
    /// dimension allows, and the invocations a row (`x · size`) the kernel indexes by.
    pub(super) fn grid_of(n: u64, size: u32) -> (u32, u32, u32) {
        const ROW: u64 = 32_768;
        let groups = n.div_ceil(u64::from(size)).max(1);
        let x = groups.min(ROW) as u32;
        let y = groups.div_ceil(ROW) as u32;
        (x, y, x * size)
    }
}

/// A compute kernel's storage buffer at `binding`.
pub(super) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    buffer_entry(binding, wgpu::BufferBindingType::Storage { read_only })
}

/// A compute kernel's uniform buffer at `binding`.
pub(super) fn uniform_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    buffer_entry(binding, wgpu::BufferBindingType::Uniform)
}

fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}
