//! The GPU frame path: a chunk of a frame's samples traced and shaded on the GPU from
//! its camera rays (made there, the CPU's to the bit) to its pixels, the wavefront
//! staying on the GPU between depth levels (shade.wgsl): per level the closest hits
//! (trace.wgsl, bound by [`GpuTracer::bind_uniform`]), the shading (emission, ambient,
//! a shadow ray a punctual light, the refracted and mirror rays), the shadow rays and
//! the next level's rays compacted by prefix sums (scan.wgsl) in the CPU's order, the
//! next level's uniforms and workgroup counts made on the GPU from the sums, the any
//! hits of the shadow rays, and each sample's sum. The host encodes every level at once
//! and reads back only the finished pixels, the chunk's totals (an overflow flag, the
//! ray counts) and, when asked, the camera rays' hits (for the AOVs and Cryptomatte,
//! which the CPU makes from them).
//!
//! What is shaded here is what `render::gpu_frame` admits; the tables it hands over
//! ([`ShadeMaterial`], [`ShadeLight`]) hold what depends on the material or the light
//! alone, computed by the CPU's own code.

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

use super::device::{storage_entry, uniform_entry};
use super::moving::entry;
use super::scan::{LiveScan, ScanPlan};
use super::shade_tables::{
    CameraRays, GpuTextures, ShadeEmitter, ShadeLight, ShadeMaterial, ShadeParams, SurfaceTriangle,
};
use super::trace::pack_ray;
use super::{GpuDevice, GpuError, GpuMoving, GpuStatic, GpuTracer};
use crate::geometry::{Hit, Ray};

/// `FP` in shade.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Params {
    a: [u32; 4],
    b: [u32; 4],
    c: [f32; 4],
    d: [f32; 4],
    e: [f32; 4],
    g: [u32; 4],
    h: [u32; 4],
}

/// The surfaces of a frame's moving triangles, uploaded ([`GpuShading::moving`]).
pub struct GpuSurfaces {
    buf: wgpu::Buffer,
    count: u32,
}

/// What a chunk's samples gave.
#[derive(Clone, Debug, Default)]
pub struct ChunkOut {
    /// Each pixel's RGB (averaged over its samples) and coverage.
    pub rgba: Vec<[f32; 4]>,
    /// The camera rays' closest hits, when asked for.
    pub camera_hits: Option<Vec<Option<Hit>>>,
    pub shadow_rays: u64,
    pub secondary_rays: u64,
    /// With the light-path passes: each pixel's four (diffuse, specular, transmission,
    /// emission; RGB and 0), pixel by pixel, averaged (or summed) as `rgba` is.
    pub passes: Option<Vec<[f32; 4]>>,
}

/// The camera's uniform (shade.wgsl's bindings: 0 and this uniforms, 1..=22 and
/// 24..=`LAST` storage).
const CAMERA: u32 = 23;
/// The last binding: 24..=26 are the next level's templates, uniforms and totals, 27 the
/// emitters (area lights), 28 the environment map, 29 and 30 the textures' tables and
/// texels ([`GpuTextures`]).
const LAST: u32 = 30;
// Every binding but the two uniforms is storage: what the device is opened for.
const _: () = assert!(LAST + 1 - 2 == super::device::FRAME_BINDINGS);
/// Next-level ray candidates an item may make: a pass-through, a diffuse bounce, a
/// refraction, a reflection (shade.wgsl's `NEXT_SLOTS`).
const NEXT_SLOTS: u64 = 4;
/// Passes through surfaces of alpha below 1 a ray may make (`render::shade`'s
/// `MAX_PASSES`, shade.wgsl's; a test in `render::gpu_frame` holds them equal).
pub const MAX_PASSES: u32 = 16;

/// The frame path's kernels and the static triangles' surfaces (uploaded once).
pub struct GpuShading {
    layout: wgpu::BindGroupLayout,
    shade_pipe: wgpu::ComputePipeline,
    compact_pipe: wgpu::ComputePipeline,
    accum_pipe: wgpu::ComputePipeline,
    pixels_pipe: wgpu::ComputePipeline,
    shear_pipe: wgpu::ComputePipeline,
    camera_pipe: wgpu::ComputePipeline,
    next_pipe: wgpu::ComputePipeline,
    static_surf: wgpu::Buffer,
    static_count: u32,
    /// The render's textures (`None`: the scene has none, the bindings get dummies).
    textures: Option<(wgpu::Buffer, wgpu::Buffer)>,
    /// A small buffer for each storage binding a kernel does not read, and a camera.
    dummies: Vec<wgpu::Buffer>,
    dummy_camera: wgpu::Buffer,
    /// The last chunks' buffers, for the next chunks or frames that fit them: one a
    /// frame in flight (frames rendered at once each take one), [`ROOMS`] at most.
    room: std::sync::Mutex<Vec<Room>>,
    /// The environment map (shade.wgsl's `env`) and what names it, uploaded once for
    /// the frames that use it ([`GpuShading::set_environment`]).
    env: std::sync::Mutex<Option<(String, GpuEnvironment)>>,
}

/// An environment map on the GPU ([`GpuShading::environment`]).
#[derive(Clone, Debug)]
pub struct GpuEnvironment(std::sync::Arc<wgpu::Buffer>);

/// Chunk buffers kept for later chunks, at most: one for each of the frames the GPU
/// path renders at once (`--frames-in-flight`, at most this many on the GPU).
pub const ROOMS: usize = 4;

/// What a chunk's buffers hold: items a level, shadow rays a level, shadow ray
/// candidates (items × lights), samples, pixels.
#[derive(Clone, Copy, Debug)]
struct RoomSize {
    cap: u64,
    caps: u64,
    cand: u64,
    nsamples: u64,
    npix: u64,
    /// With the light-path passes: the words an item's splits take in `local` (its four
    /// and two a shadow ray slot; shade.wgsl's `split_stride`), else 0.
    split: u64,
}

impl RoomSize {
    fn holds(&self, o: &RoomSize) -> bool {
        self.cap >= o.cap
            && self.caps >= o.caps
            && self.cand >= o.cand
            && self.nsamples >= o.nsamples
            && self.npix >= o.npix
            && self.split >= o.split
    }
}

/// A chunk's buffers (see `render_chunk`).
struct Room {
    size: RoomSize,
    /// The items of a level and of the next, in turn.
    rays: [wgpu::Buffer; 2],
    items: [wgpu::Buffer; 2],
    radiance: wgpu::Buffer,
    hits: wgpu::Buffer,
    local: wgpu::Buffer,
    sh_cand: wgpu::Buffer,
    nx_cand_r: wgpu::Buffer,
    nx_cand_i: wgpu::Buffer,
    sh_count: wgpu::Buffer,
    nx_count: wgpu::Buffer,
    sh_start: wgpu::Buffer,
    nx_start: wgpu::Buffer,
    sh_rays: wgpu::Buffer,
    sh_add: wgpu::Buffer,
    sh_hits: wgpu::Buffer,
    cam_hits: wgpu::Buffer,
    rgba: wgpu::Buffer,
    /// The uniforms' templates and the next level's uniforms (`next_level`).
    templates: wgpu::Buffer,
    made: wgpu::Buffer,
    /// The two scans of a level (shadow rays, next-level rays) over its items and one
    /// more, their length read on the GPU: from `templates` at the camera rays' level,
    /// from `made` after.
    plan: ScanPlan,
    sh_scan: LiveScan,
    nx_scan: LiveScan,
}

impl Room {
    fn new(dev: &GpuDevice, size: RoomSize) -> Result<Room, GpuError> {
        let RoomSize {
            cap,
            caps,
            cand,
            nsamples,
            npix,
            split,
        } = size;
        // The light-path passes' words after the beauty's (shade.wgsl `light_paths`).
        let paths = u64::from(split > 0);
        let b = |what, bytes| dev.buffer(what, bytes, USAGE);
        let (sh_count, nx_count) = (
            b("the shadow ray counts", (cap + 1) * 4)?,
            b("the next ray counts", (cap + 1) * 4)?,
        );
        let (sh_start, nx_start) = (
            b("the shadow ray starts", (cap + 1) * 4)?,
            b("the next ray starts", (cap + 1) * 4)?,
        );
        let templates = b("the uniforms' templates", 108 * 4)?;
        let made = dev.buffer(
            "the next level's uniforms",
            117 * 4,
            USAGE | wgpu::BufferUsages::INDIRECT,
        )?;
        // The items' count is word 0 of either (shade.wgsl's `F.a.x`).
        let plan = ScanPlan::new(dev, cap + 1, 0, 1, &[&templates, &made])?;
        Ok(Room {
            size,
            rays: [b("the rays", cap * 48)?, b("the next rays", cap * 48)?],
            items: [b("the items", cap * 48)?, b("the next items", cap * 48)?],
            radiance: b("the samples' radiance", nsamples * (1 + 4 * paths) * 16)?,
            hits: b("the hits", cap * 16)?,
            local: b("the items' light", cap * (1 + split) * 16)?,
            sh_cand: b("the shadow ray candidates", cand * 64)?,
            nx_cand_r: b("the next rays' candidates", cap * NEXT_SLOTS * 48)?,
            nx_cand_i: b("the next items' candidates", cap * NEXT_SLOTS * 48)?,
            sh_scan: LiveScan::new(dev, &plan, &sh_count, &sh_start)?,
            nx_scan: LiveScan::new(dev, &plan, &nx_count, &nx_start)?,
            sh_count,
            nx_count,
            sh_start,
            nx_start,
            sh_rays: b("the shadow rays", caps * 48)?,
            sh_add: b("the shadow rays' light", caps * (1 + 2 * paths) * 16)?,
            sh_hits: b("the shadow rays' hits", caps * 16)?,
            cam_hits: b("the camera rays' hits", nsamples * 16)?,
            rgba: b("the pixels", npix * (1 + 4 * paths) * 16)?,
            templates,
            made,
            plan,
        })
    }
}

impl std::fmt::Debug for GpuShading {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GpuShading({} static triangles)", self.static_count)
    }
}

const USAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);

impl GpuShading {
    /// Compiles the kernels and uploads the static triangles' surfaces (numbered as
    /// the tracer numbers them); no textures.
    pub fn new(dev: &GpuDevice, static_surf: &[SurfaceTriangle]) -> Result<GpuShading, GpuError> {
        Self::new_textured(dev, static_surf, &GpuTextures::default())
    }

    /// [`new`](Self::new) with the render's textures (their tables and every mip
    /// level), uploaded once; each of the two arrays must fit one storage binding
    /// (`TooLarge` else).
    pub fn new_textured(
        dev: &GpuDevice,
        static_surf: &[SurfaceTriangle],
        textures: &GpuTextures,
    ) -> Result<GpuShading, GpuError> {
        let device = &dev.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shade.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shade.wgsl").into()),
        });
        // The parameters (0) and the camera (`CAMERA`) uniform, every other binding
        // storage.
        let entries: Vec<wgpu::BindGroupLayoutEntry> = (0..=LAST)
            .map(|b| match b {
                0 | CAMERA => uniform_entry(b),
                _ => storage_entry(b, false),
            })
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame"),
            entries: &entries,
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("frame"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipe = |name: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: Some(&pl),
                module: &module,
                entry_point: Some(name),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let (shade_pipe, compact_pipe, accum_pipe, pixels_pipe, shear_pipe, camera_pipe) = (
            pipe("shade"),
            pipe("compact"),
            pipe("accum"),
            pipe("pixels"),
            pipe("shear_test"),
            pipe("camera"),
        );
        let next_pipe = pipe("next_level");
        let dummy_camera = dev.uniform(bytemuck::bytes_of(&CameraRays::default()));
        let dummies = (0..=LAST)
            .map(|_| dev.buffer("an unused binding", 512, USAGE))
            .collect::<Result<Vec<_>, _>>()?;
        let static_count = u32::try_from(static_surf.len())
            .map_err(|_| dev.too_large("the static surfaces", static_surf.len() as u64 * 128))?;
        let static_surf =
            dev.storage_with("the static surfaces", bytemuck::cast_slice(static_surf))?;
        let textures = if textures.meta.is_empty() {
            None
        } else {
            Some((
                dev.storage_with("the textures' tables", bytemuck::cast_slice(&textures.meta))?,
                dev.storage_with(
                    "the textures' texels",
                    bytemuck::cast_slice(&textures.texels),
                )?,
            ))
        };
        dev.wait()?;
        Ok(GpuShading {
            layout,
            shade_pipe,
            compact_pipe,
            accum_pipe,
            pixels_pipe,
            shear_pipe,
            camera_pipe,
            next_pipe,
            static_surf,
            static_count,
            textures,
            dummies,
            dummy_camera,
            room: std::sync::Mutex::new(Vec::new()),
            env: std::sync::Mutex::new(None),
        })
    }

    /// An environment map for the frames' misses (`table`: shade.wgsl's `env`, a header
    /// of 8 words then the texels' RGB), named by `key`: uploaded once, and again only
    /// when the key differs from the last one's.
    pub fn environment(
        &self,
        dev: &GpuDevice,
        key: &str,
        table: impl FnOnce() -> Vec<f32>,
    ) -> Result<GpuEnvironment, GpuError> {
        let mut g = match self.env.lock() {
            Ok(g) => g,
            Err(p) => p.into_inner(),
        };
        if let Some((k, e)) = g.as_ref() {
            if k == key {
                return Ok(e.clone());
            }
        }
        *g = None;
        let buf = dev.storage_with("the environment map", bytemuck::cast_slice(&table()))?;
        let e = GpuEnvironment(std::sync::Arc::new(buf));
        *g = Some((key.to_string(), e.clone()));
        Ok(e)
    }

    /// A frame's moving triangles' surfaces, uploaded (numbered after the static ones).
    pub fn moving(
        &self,
        dev: &GpuDevice,
        surf: &[SurfaceTriangle],
    ) -> Result<GpuSurfaces, GpuError> {
        let count = u32::try_from(surf.len())
            .map_err(|_| dev.too_large("the moving surfaces", surf.len() as u64 * 128))?;
        Ok(GpuSurfaces {
            buf: dev.storage_with("the moving surfaces", bytemuck::cast_slice(surf))?,
            count,
        })
    }

    fn group(&self, dev: &GpuDevice, bufs: &[Option<&wgpu::Buffer>]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry<'_>> = bufs
            .iter()
            .enumerate()
            .map(|(k, b)| {
                let dummy = match k as u32 {
                    CAMERA => &self.dummy_camera,
                    _ => &self.dummies[k],
                };
                entry(k as u32, b.unwrap_or(dummy))
            })
            .collect();
        dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame"),
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// A dispatch whose workgroup counts the GPU wrote (`args` at byte `at`).
    fn dispatch_indirect(
        enc: &mut wgpu::CommandEncoder,
        pipe: &wgpu::ComputePipeline,
        group: &wgpu::BindGroup,
        args: &wgpu::Buffer,
        at: u64,
    ) {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipe);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups_indirect(args, at);
    }

    fn dispatch(
        enc: &mut wgpu::CommandEncoder,
        pipe: &wgpu::ComputePipeline,
        group: &wgpu::BindGroup,
        n: u64,
    ) {
        if n == 0 {
            return;
        }
        let (gx, gy, _) = GpuDevice::grid_of(n, 64);
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipe);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(gx, gy, 1);
    }

    /// For the tests: the camera rays of `npix` pixels from `camera.first_pixel` on, as
    /// the frame path makes them (each word's bits, as [`packed_on_cpu`] gives them).
    pub fn camera_rays_made_on_gpu(
        &self,
        dev: &GpuDevice,
        camera: &CameraRays,
        npix: u64,
    ) -> Result<Vec<[u32; 12]>, GpuError> {
        let n = npix * u64::from(camera.spp.max(1));
        if n == 0 {
            return Ok(Vec::new());
        }
        let buf = dev.buffer("the camera rays", n * 48, USAGE)?;
        let (_, _, stride) = GpuDevice::grid_of(n, 64);
        let params = params(n, 0, true, 0, 0, stride, 0, 1, None);
        let uni = dev.uniform(bytemuck::bytes_of(&params));
        let cam = dev.uniform(bytemuck::bytes_of(camera));
        let mut bufs: Vec<Option<&wgpu::Buffer>> = vec![None; LAST as usize + 1];
        bufs[0] = Some(&uni);
        bufs[1] = Some(&buf);
        bufs[CAMERA as usize] = Some(&cam);
        let group = self.group(dev, &bufs);
        let mut enc = dev.device.create_command_encoder(&Default::default());
        Self::dispatch(&mut enc, &self.camera_pipe, &group, n);
        let bytes = dev.read_back(enc, &buf, n * 48)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..n as usize * 48]))
    }

    /// For the tests: the rays as the GPU frame path makes them (`trace::pack_ray`'s 48
    /// bytes: origin and `t_min`, direction and `t_max`, the shear and its axis bits),
    /// each word's bits; [`packed_on_cpu`] gives the CPU's.
    pub fn rays_made_on_gpu(
        &self,
        dev: &GpuDevice,
        rays: &[Ray],
    ) -> Result<Vec<[u32; 12]>, GpuError> {
        let n = rays.len() as u64;
        if n == 0 {
            return Ok(Vec::new());
        }
        // Sent with no shear: the kernel makes it.
        let plain: Vec<[f32; 12]> = rays
            .iter()
            .map(|r| {
                let (o, d) = (r.origin, r.dir);
                [
                    o.x, o.y, o.z, r.t_min, d.x, d.y, d.z, r.t_max, 0.0, 0.0, 0.0, 0.0,
                ]
            })
            .collect();
        let buf = dev.buffer("the rays", n * 48, USAGE)?;
        dev.write(&buf, 0, bytemuck::cast_slice(&plain));
        let (_, _, stride) = GpuDevice::grid_of(n, 64);
        let params = params(n, 0, true, 0, 0, stride, 0, 1, None);
        let uni = dev.uniform(bytemuck::bytes_of(&params));
        let mut bufs: Vec<Option<&wgpu::Buffer>> = vec![None; LAST as usize + 1];
        bufs[0] = Some(&uni);
        bufs[1] = Some(&buf);
        let group = self.group(dev, &bufs);
        let mut enc = dev.device.create_command_encoder(&Default::default());
        Self::dispatch(&mut enc, &self.shear_pipe, &group, n);
        let bytes = dev.read_back(enc, &buf, n * 48)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..rays.len() * 48]))
    }

    /// The most items a level can hold: what one binding and a budget of 256 MiB for a
    /// chunk's buffers allow. The frame path's buffers take some 656 + 144 · slots
    /// bytes an item, `slots` the shadow rays an item may make (the punctual lights,
    /// and the area-light samples at a camera ray's hit), and with the light-path
    /// passes (`paths`) 192 + 96 · slots more (the items' splits, the shadow rays',
    /// the samples').
    pub fn max_capacity(dev: &GpuDevice, slots: usize, paths: bool) -> u64 {
        let l = slots as u64;
        let p = u64::from(paths);
        // The largest binding per item: the shadow candidates, the next rays', or the
        // items' light with their splits.
        let widest = (64 * l)
            .max(NEXT_SLOTS * 48)
            .max(16 * (1 + p * (4 + 2 * l)));
        let per_binding = dev.max_binding() / widest;
        let budget = (256u64 << 20) / (656 + 144 * l + p * (192 + 96 * l));
        per_binding.min(budget).clamp(1024, 1 << 22)
    }

    /// Traces and shades the camera rays of `npix` pixels from `camera.first_pixel` on
    /// (made here, `camera.spp` a pixel, in the CPU's sample order) over the static
    /// part and the frame's moving part (`moving`, `surfaces`), with `materials`
    /// (indexed by the surfaces' material numbers), `lights` and `emitters` (the area
    /// lights, `shading.light_samples` shadow rays to them at a camera ray's hit, one
    /// deeper), and `env` for the misses (else the background): each pixel's averaged
    /// RGB and coverage, and the camera rays' hits when `want_hits`.
    ///
    /// The levels run without the host: each level's buffers hold `capacity` items (at
    /// least the chunk's samples) and `capacity` × slots shadow rays, and the next
    /// level's counts go into its uniforms on the GPU. `Ok(None)`: a level outgrew them
    /// (nothing of the chunk is kept; trace it again with more room or fewer pixels).
    #[allow(clippy::too_many_arguments)]
    pub fn render_chunk(
        &self,
        dev: &GpuDevice,
        stat: &GpuStatic,
        moving: &GpuMoving,
        surfaces: &GpuSurfaces,
        materials: &[ShadeMaterial],
        lights: &[ShadeLight],
        emitters: &[ShadeEmitter],
        env: Option<&GpuEnvironment>,
        shading: &ShadeParams,
        camera: &CameraRays,
        npix: u64,
        picked: Option<&[u32]>,
        capacity: u64,
        want_hits: bool,
    ) -> Result<Option<ChunkOut>, GpuError> {
        let spp = camera.spp.max(1);
        let nsamples = npix * u64::from(spp);
        // The camera rays traced: every sample, or a blurred frame's step's (`picked`,
        // ascending chunk numbers, each under `nsamples`; the kernels' reads and writes
        // stay inside their buffers whatever the numbers, by WGSL's bounds).
        let traced = picked.map_or(nsamples, |p| p.len() as u64);
        if nsamples == 0 || traced == 0 {
            return Ok(Some(ChunkOut {
                rgba: vec![[0.0; 4]; npix as usize],
                ..ChunkOut::default()
            }));
        }
        let cap = capacity.max(traced);
        let nl = lights.len() as u64;
        // An item's shadow ray slots: one a punctual light, and the area-light samples
        // of a camera ray's hit (deeper hits make one).
        let area_samples = if emitters.is_empty() {
            0
        } else {
            u64::from(shading.light_samples.max(1))
        };
        let slots = nl + area_samples;
        let caps = (cap * slots).max(1);
        let (cap32, caps32, nl32, ne32) = match (
            u32::try_from(cap),
            u32::try_from(caps),
            u32::try_from(nl),
            u32::try_from(emitters.len()),
        ) {
            (Ok(a), Ok(b), Ok(c), Ok(d)) => (a, b, c, d),
            _ => return Err(dev.too_large("a level of the frame path", caps * 48)),
        };
        let tracer = GpuTracer::new(dev, stat, moving);
        let mats = dev.storage_with("the materials", bytemuck::cast_slice(materials))?;
        let lts = dev.storage_with("the lights", bytemuck::cast_slice(lights))?;
        let ems = match emitters.is_empty() {
            true => None,
            false => Some(dev.storage_with("the emitters", bytemuck::cast_slice(emitters))?),
        };
        let cam = dev.uniform(bytemuck::bytes_of(&CameraRays {
            cone: shading.cone,
            light_paths: if shading.light_paths { 1.0 } else { 0.0 },
            ..*camera
        }));
        // The buffers of the last chunk when they are large enough (every one is written
        // before it is read), else new ones.
        let size = RoomSize {
            cap,
            caps,
            cand: cap * slots,
            nsamples,
            npix,
            split: if shading.light_paths {
                4 + 2 * slots
            } else {
                0
            },
        };
        // One that holds the chunk, else new buffers (a room too small is dropped).
        let kept = self.room.lock().ok().and_then(|mut g| {
            let at = g.iter().position(|r| r.size.holds(&size));
            match at {
                Some(i) => Some(g.swap_remove(i)),
                None => {
                    g.pop();
                    None
                }
            }
        });
        let room = match kept {
            Some(r) => r,
            None => Room::new(dev, size)?,
        };
        let Room {
            rays,
            items,
            radiance,
            hits,
            local,
            sh_cand,
            nx_cand_r,
            nx_cand_i,
            sh_count,
            nx_count,
            sh_start,
            nx_start,
            sh_rays,
            sh_add,
            sh_hits,
            cam_hits,
            rgba,
            templates,
            made,
            plan,
            sh_scan,
            nx_scan,
            ..
        } = &room;
        // The uniforms: this file's for the items (a grid over the capacity and one
        // more), the trace kernel's for the closest hits (a grid over the capacity) and
        // for the any hits; the level's counts are written into them on the GPU.
        let (_, _, stride) = GpuDevice::grid_of(cap + 1, 64);
        let total_tris = self.static_count.saturating_add(surfaces.count);
        let mut p = params(
            traced,
            nl32,
            true,
            shading.max_depth,
            self.static_count,
            stride,
            npix,
            spp,
            Some((shading, total_tris)),
        );
        // Seeds are made only when a ray reads them (a glossy lobe, area lights), as the CPU's
        // `ShadeContext::random`: their values matter only where they are read.
        if materials.iter().any(|m| m.reflects == 2)
            || !emitters.is_empty()
            || shading.diffuse_bounces > 0
        {
            p.e[1] = 1.0;
        }
        // Small integers: exact as f32.
        p.e[2] = shading.diffuse_bounces as f32;
        p.e[3] = if env.is_some() { 1.0 } else { 0.0 };
        p.g[1] = cap32;
        p.g[2] = caps32;
        p.g[3] = ne32;
        let x_of = |n: u64| GpuDevice::grid_of(n, 64).0;
        let x_caps = [x_of(cap + 1), x_of(cap), x_of(caps)];
        p.h = [x_caps[0], x_caps[1], x_caps[2], area_samples as u32];
        let mut closest = tracer.params_words(cap, false)?;
        let any = tracer.params_words(caps, true)?;
        closest[0] = traced as u32;
        if let Some(sel) = picked {
            // A step's first level: item i is sample `sel[i]` (the camera kernel and
            // `shade` read it from the item), and the samples not traced stay 0.
            p.a[2] = 2;
            let mut words = vec![0u32; sel.len() * 12];
            for (w, &s) in words.chunks_exact_mut(12).zip(sel) {
                w[4] = s;
            }
            dev.write(&items[0], 0, bytemuck::cast_slice(&words));
        }
        let tc_uni = dev.uniform(bytemuck::bytes_of(&closest));
        let ta_uni = dev.uniform(bytemuck::bytes_of(&any));
        let f_uni = dev.uniform(bytemuck::bytes_of(&p));
        let mut words: Vec<u32> = bytemuck::cast_slice(bytemuck::bytes_of(&p)).to_vec();
        words.extend_from_slice(&closest);
        words.extend_from_slice(&any);
        dev.write(templates, 0, bytemuck::cast_slice(&words));
        let indirect = USAGE | wgpu::BufferUsages::INDIRECT;
        // The workgroups of the items' kernels, the closest hits and the any hits (as
        // `next_level` counts them); the camera rays' level's from here.
        let groups = |n: u64, x_cap: u32| {
            let g = n.div_ceil(64) as u32;
            [g.min(x_cap), g.div_ceil(x_cap), 1]
        };
        let args = dev.buffer("the dispatches' workgroups", 9 * 4, indirect)?;
        let first_args: Vec<u32> = [
            groups(traced, x_caps[0]),
            groups(traced, x_caps[1]),
            [0, 0, 1],
        ]
        .concat();
        dev.write(&args, 0, bytemuck::cast_slice(&first_args));
        let totals = dev.buffer("the frame path's totals", 16, USAGE)?;
        dev.write(&totals, 0, &[0u8; 16]);
        // A bind group a parity: level k reads set k % 2 and writes the other.
        let group = |k: usize| {
            let bufs: Vec<Option<&wgpu::Buffer>> = vec![
                Some(&f_uni),
                Some(&rays[k]),
                Some(&items[k]),
                Some(hits),
                Some(&self.static_surf),
                Some(&surfaces.buf),
                Some(&mats),
                Some(&lts),
                Some(local),
                Some(sh_cand),
                Some(nx_cand_r),
                Some(nx_cand_i),
                Some(sh_count),
                Some(nx_count),
                Some(sh_start),
                Some(nx_start),
                Some(sh_rays),
                Some(sh_add),
                Some(&rays[1 - k]),
                Some(&items[1 - k]),
                Some(sh_hits),
                Some(radiance),
                None,
                Some(&cam),
                Some(templates),
                Some(made),
                Some(&totals),
                ems.as_ref(),
                env.map(|e| &*e.0),
                self.textures.as_ref().map(|t| &t.0),
                self.textures.as_ref().map(|t| &t.1),
            ];
            self.group(dev, &bufs)
        };
        let bind = [group(0), group(1)];
        let trace_closest = [
            tracer.bind_uniform(&tc_uni, &rays[0], hits),
            tracer.bind_uniform(&tc_uni, &rays[1], hits),
        ];
        let trace_any = tracer.bind_uniform(&ta_uni, sh_rays, sh_hits);
        let mut enc = dev.device.create_command_encoder(&Default::default());
        // Every level up to the deepest the items can reach: `--max-depth`, or the
        // camera rays' level alone when no material makes a ray (no mirror reflection,
        // no transmission: `shade` then writes no next-level ray, whatever the depth).
        // A level that turns out empty costs the plan and a few passes of no
        // workgroups.
        // Diffuse bounces go on past `--max-depth` (a bounce is not a secondary ray):
        // at most that many levels more.
        // The light-path passes' words after the beauty's (shade.wgsl `light_paths`).
        let paths = u64::from(shading.light_paths);
        let makes_rays = materials
            .iter()
            .any(|m| m.reflects != 0 || m.transmission != 0.0);
        // A pass-through ray keeps its depth: up to `MAX_PASSES` levels more where a
        // material may pass rays through (alpha below 1).
        let passes = if materials.iter().any(|m| m.alpha[3] != 0.0) {
            MAX_PASSES
        } else {
            0
        };
        let deepest = if makes_rays { shading.max_depth } else { 0 }
            .saturating_add(shading.diffuse_bounces)
            .saturating_add(passes);
        // Word offsets in `made`: this file's uniform, the closest hits', the any
        // hits', then the workgroups (items, closest, any).
        let (w_f, w_tc, w_ta, w_args) = (0u64, 28u64, 68u64, 108u64);
        for level in 0..=deepest as usize {
            let (g, k) = (&bind[level % 2], level % 2);
            if level == 0 {
                if picked.is_some() {
                    enc.clear_buffer(radiance, 0, Some(nsamples * (1 + 4 * paths) * 16));
                }
                Self::dispatch(&mut enc, &self.camera_pipe, g, traced);
            }
            tracer.encode_group_indirect(&mut enc, &trace_closest[k], &args, 12);
            if level == 0 && want_hits {
                enc.copy_buffer_to_buffer(hits, 0, cam_hits, 0, traced * 16);
            }
            Self::dispatch_indirect(&mut enc, &self.shade_pipe, g, &args, 0);
            // The scans over the level's items and one more (the totals), their count
            // read on the GPU: the camera rays' from the templates, the others from what
            // the last level's `next_level` made.
            plan.encode(dev, &mut enc, usize::from(level > 0));
            sh_scan.encode(dev, &mut enc, plan);
            nx_scan.encode(dev, &mut enc, plan);
            Self::dispatch(&mut enc, &self.next_pipe, g, 1);
            enc.copy_buffer_to_buffer(made, w_ta * 4, &ta_uni, 0, 40 * 4);
            enc.copy_buffer_to_buffer(made, (w_args + 6) * 4, &args, 24, 12);
            Self::dispatch_indirect(&mut enc, &self.compact_pipe, g, &args, 0);
            tracer.encode_group_indirect(&mut enc, &trace_any, &args, 24);
            Self::dispatch_indirect(&mut enc, &self.accum_pipe, g, &args, 0);
            enc.copy_buffer_to_buffer(made, w_f * 4, &f_uni, 0, 28 * 4);
            enc.copy_buffer_to_buffer(made, w_tc * 4, &tc_uni, 0, 40 * 4);
            enc.copy_buffer_to_buffer(made, w_args * 4, &args, 0, 24);
        }
        let (_, _, stride) = GpuDevice::grid_of(npix, 64);
        let mut p = params(0, 0, false, 0, 0, stride, npix, spp, None);
        if picked.is_some() {
            // A step's pixels: their samples' sums (`finish_blurred` divides and clamps).
            p.a[2] = 1;
            p.d[3] = 1.0;
        }
        p.a[3] = paths as u32;
        let uni = dev.uniform(bytemuck::bytes_of(&p));
        let mut bufs: Vec<Option<&wgpu::Buffer>> = vec![None; LAST as usize + 1];
        bufs[0] = Some(&uni);
        bufs[21] = Some(radiance);
        bufs[22] = Some(rgba);
        let group = self.group(dev, &bufs);
        Self::dispatch(&mut enc, &self.pixels_pipe, &group, npix);
        let b = dev.read_back(enc, rgba, npix * (1 + 4 * paths) * 16)?;
        let t = dev.read_back(
            dev.device.create_command_encoder(&Default::default()),
            &totals,
            16,
        )?;
        let t: Vec<u32> = bytemuck::pod_collect_to_vec(&t[..16]);
        let hits_back = if want_hits && t[0] == 0 {
            let enc = dev.device.create_command_encoder(&Default::default());
            Some(dev.read_back(enc, cam_hits, traced * 16)?)
        } else {
            None
        };
        // Kept for the next chunk (only once everything read back is read).
        if let Ok(mut g) = self.room.lock() {
            if g.len() < ROOMS {
                g.push(room);
            }
        }
        if t[0] != 0 {
            return Ok(None);
        }
        let mut out = ChunkOut {
            rgba: bytemuck::pod_collect_to_vec(&b[..npix as usize * 16]),
            camera_hits: None,
            shadow_rays: u64::from(t[1]),
            secondary_rays: u64::from(t[2]),
            passes: (paths == 1)
                .then(|| bytemuck::pod_collect_to_vec(&b[npix as usize * 16..npix as usize * 80])),
        };
        if let Some(b) = hits_back {
            let raw: Vec<[u32; 4]> = bytemuck::pod_collect_to_vec(&b[..traced as usize * 16]);
            out.camera_hits = Some(
                raw.par_iter()
                    .with_min_len(4096)
                    .map(|h| {
                        (h[1] != u32::MAX).then(|| Hit {
                            t: f32::from_bits(h[0]),
                            tri: h[1],
                            u: f32::from_bits(h[2]),
                            v: f32::from_bits(h[3]),
                        })
                    })
                    .collect(),
            );
        }
        Ok(Some(out))
    }
}

/// The uniform of shade.wgsl.
#[allow(clippy::too_many_arguments)]
fn params(
    n: u64,
    lights: u32,
    first: bool,
    max_depth: u32,
    static_tris: u32,
    stride: u32,
    npix: u64,
    spp: u32,
    shading: Option<(&ShadeParams, u32)>,
) -> Params {
    let (amb, bg, extent, min_w, total) = match shading {
        Some((s, total)) => (s.ambient, s.background, s.extent, s.min_weight, total),
        None => ([0.0; 3], [0.0; 3], 1.0, 0.0, 0),
    };
    Params {
        a: [n as u32, lights, u32::from(first), max_depth],
        b: [static_tris, stride, npix as u32, spp],
        c: [amb[0], amb[1], amb[2], extent],
        d: [bg[0], bg[1], bg[2], 1.0 / spp.max(1) as f32],
        e: [min_w, 0.0, 0.0, 0.0],
        g: [total, 0, 0, 0],
        h: [0; 4],
    }
}

/// For the tests: a ray as the CPU packs it for the trace kernel (`trace::pack_ray`),
/// each word's bits.
pub fn packed_on_cpu(r: &Ray) -> [u32; 12] {
    bytemuck::cast(pack_ray(r))
}
