//! The GPU back end of the tracer seam ([`Intersector`](crate::geometry::Intersector)):
//! wgpu compute over Vulkan. One concept a file:
//!
//! * `device`: the adapter (a discrete GPU, any GPU, or none) and the compiled kernels.
//! * `static_part`: a [`Psf`](crate::psf::Psf) uploaded once as storage buffers.
//! * `moving`: the moving triangles of a frame, gridded on the GPU (count, scan, scatter).
//! * `trace`: [`GpuTracer`], closest hit and any hit of ray batches over both.
//! * `scan`: the prefix sum the grid build and the frame path use.
//! * `frame`: [`GpuShading`], the GPU frame path: a wavefront traced and shaded on the
//!   GPU from camera rays to pixels (shade.wgsl), for the scenes `render` admits;
//!   `shade_tables`: the materials, lights, camera and surfaces its kernels read.
//!
//! The kernels (`*.wgsl` beside the files) answer exactly what the CPU tracer answers:
//! the same triangle, `t`, `u` and `v` to the bit (docs/GPU.md says why each number is
//! exact, and what the walk may do differently without changing a hit).

mod device;
mod frame;
mod moving;
mod scan;
mod shade_tables;
mod static_part;
mod trace;

pub use device::{AdapterPolicy, GpuDevice};
#[cfg(test)]
pub(crate) use frame::MAX_PASSES;
pub use frame::{packed_on_cpu, ChunkOut, GpuEnvironment, GpuShading, GpuSurfaces, ROOMS};
pub use moving::GpuMoving;
pub use shade_tables::{
    CameraRays, GpuTextures, ShadeEmitter, ShadeLight, ShadeMaterial, ShadeParams, SurfaceTriangle,
    TEXTURE_VIEW_WORDS,
};
pub use static_part::GpuStatic;
pub use trace::GpuTracer;

/// What can go wrong on the GPU path. `NoAdapter`, `MissingFeature` and `TooLarge` are
/// known before anything is traced; `OutOfMemory` and `Lost` come from the driver at
/// upload or trace time (exit code 5 in the CLI: retry, perhaps elsewhere).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    #[error(
        "no {wanted} found: looked for a Vulkan adapter through wgpu, found {seen}; install \
         a Vulkan driver: the GPU vendor's (e.g. NVIDIA's), or Debian's mesa-vulkan-drivers \
         and libvulkan1 for lavapipe, a CPU fallback"
    )]
    NoAdapter {
        /// "GPU adapter" or "discrete GPU adapter".
        wanted: &'static str,
        /// The adapters that were found, in words, or "none".
        seen: String,
    },
    #[error("the GPU adapter '{adapter}' lacks {feature}, which the GPU tracer needs ({why})")]
    MissingFeature {
        adapter: String,
        feature: &'static str,
        why: &'static str,
    },
    #[error("the GPU adapter could not be opened: {0}")]
    RequestDevice(String),
    #[error(
        "{what} needs {needed} bytes in one GPU storage binding; the adapter '{adapter}' \
         allows {available}"
    )]
    TooLarge {
        what: &'static str,
        needed: u64,
        available: u64,
        adapter: String,
    },
    #[error("the GPU ran out of memory ({0})")]
    OutOfMemory(String),
    #[error("the GPU device was lost or failed ({0})")]
    Lost(String),
    #[error(transparent)]
    Triangles(#[from] crate::psf::PsfError),
}

/// For unit tests: the adapter, or `None` after saying why the test skips (a failure
/// under `CI`, where lavapipe must be there).
#[cfg(test)]
pub(crate) fn test_device() -> Option<GpuDevice> {
    match GpuDevice::open(AdapterPolicy::Any) {
        Ok(Some(d)) => Some(d),
        other => {
            let why = format!("{:?}", other.err());
            assert!(
                std::env::var_os("CI").is_none(),
                "no GPU adapter under CI: {why}"
            );
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "SKIPPED: no GPU adapter: {why}");
            None
        }
    }
}
