// The GPU frame path (frame.rs): one depth level of a wavefront shaded on the GPU, its
// shadow and next-level rays compacted in the CPU's order, its light summed into the
// samples in the CPU's order, and the pixels averaged. The shading is
// `render::shade::ShadeContext::shade` restricted to the subset `render::gpu_frame`
// admits (materials textured or not, alpha below 1 passing rays through; a mirror, GGX
// or no reflection ray; punctual and area lights; a background or environment map;
// diffuse bounces), step for step; the random numbers are the CPU's (`sampling::Seed`, carried by each item);
// what depends on the material alone (F0, the Blinn-Phong exponent and its
// normalisation, 1/ior, the spot's cone cosines) comes computed by the CPU's own code in
// the tables, and `textured` recomputes per hit what a texture changes.
//
// Determinism: every kernel writes only slots it owns (an item's candidates, a sample's
// run, a pixel); compaction is by prefix sums (scan.wgsl) of per-item counts, so the
// rays of the next level and the shadow rays are in item order and, per item, in the
// CPU's order (lights in table order; refraction before reflection). Items stay sorted
// by sample (children follow their parent), so one invocation a run of equal samples
// adds that sample's terms one after the other, in the order the CPU adds them: the
// level's own terms (emission, ambient, background) in item order, then light by light
// the unblocked shadow rays in item order. No atomics.
//
// The rays made here go to the trace kernel (trace.wgsl) as they are, so their shear is
// computed here as `geometry::Shear::new` computes it, to the bit: the axis choice by
// comparisons, the divisions in f64 rounded once to f32 (the quotient of two f32 is
// never an f32 midpoint and lies far enough from one that an f64 quotient a few ulps
// off still rounds to the correctly rounded f32; docs/GPU.md). `shear_test` checks it.

struct FP {
    // items this level, lights, 1 at the camera rays' level, max depth
    a: vec4<u32>,
    // static triangles, row stride (invocations), pixels, samples a pixel
    b: vec4<u32>,
    // ambient light (RGB), scene extent
    c: vec4<f32>,
    // background (RGB), 1 / spp
    d: vec4<f32>,
    // MIN_WEIGHT, 1 when a ray reads random numbers (a glossy lobe, area lights, diffuse
    // bounces), the diffuse bounces (--diffuse-bounces, a small integer), 1 when misses
    // see the environment map (`env`)
    e: vec4<f32>,
    // triangles in all, the items a level holds at most, the shadow rays likewise,
    // the emitters (area lights)
    g: vec4<u32>,
    // workgroups along x of the grids over the capacities (the row strides / 64): the
    // items' kernels, the closest hits, the any hits; the area-light samples at a
    // camera ray's hit (0 without emitters)
    h: vec4<u32>,
}

// trace.wgsl's `Ray`, the shear's axis bits as a u32 (the same 48 bytes).
struct Ray {
    o: vec4<f32>,
    d: vec4<f32>,
    s: vec3<f32>,
    k: u32,
}

struct Item {
    // weight (RGB); the diffuse bounces made, + 256 for a diffuse bounce's own ray, +
    // 512 × the light path (0 none yet, else its pass + 1; `Item::path`) (a small
    // integer, exact as f32)
    w: vec4<f32>,
    // sample, depth, the random numbers' seed (`sampling::Seed`, low and high words;
    // made only when a ray reads it: F.e.y)
    m: vec4<u32>,
    // the ray cone's width where the ray starts and its spread (the texture level of
    // detail); the share of the sample's coverage the ray decides (`Item::coverage`:
    // 1 for a camera ray, the (1 - alpha) products for its pass-through rays, 0 for
    // others) and the passes made through surfaces of alpha below 1 (a small integer)
    c: vec4<f32>,
}

struct Shadow {
    r: Ray,
    // what it adds when unblocked (RGB), the light's number (as f32)
    c: vec4<f32>,
}

// frame.rs `ShadeMaterial`.
struct Mat {
    albedo: vec3<f32>,
    metallic: f32,
    f0: vec3<f32>,
    roughness: f32,
    emission: vec3<f32>,
    transmission: f32,
    gloss: f32,
    shininess: f32,
    eta_entering: f32,
    eta_leaving: f32,
    double_sided: u32,
    reflects: u32,
    glint_norm: f32,
    glint_scale: f32,
    // The texture slots' views (base colour, metallic-roughness, emissive, normal; NONE:
    // none), the factors the textures multiply (metallic, roughness, transmission clamped,
    // the normal map's scale), each slot's transform (scale, sin, cos; offset, 1 if any).
    tex: vec4<u32>,
    factors: vec4<f32>,
    xf: array<vec4<f32>, 8>,
    // The material's own ambient colour (AFF; w 1 when it has one), which the ambient
    // light is reflected with instead of the diffuse colour.
    aff: vec4<f32>,
    // The base colour's alpha (the factor's; `textured` multiplies the texture's in),
    // the MASK cutoff, the mode (0 OPAQUE, 1 MASK, 2 BLEND), 1 when a hit may pass rays
    // through (for the host).
    alpha: vec4<f32>,
}

// frame.rs `ShadeLight`.
struct Light {
    position: vec3<f32>,
    kind: u32,
    direction: vec3<f32>,
    range: f32,
    power: vec3<f32>,
    no_falloff: u32,
    cos_outer: f32,
    cone_scale: f32,
    has_range: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> F: FP;
@group(0) @binding(1) var<storage, read_write> rays: array<Ray>;
@group(0) @binding(2) var<storage, read_write> items: array<Item>;
@group(0) @binding(3) var<storage, read_write> hits: array<vec4<u32>>;
@group(0) @binding(4) var<storage, read_write> surf_s: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> surf_m: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> mats: array<Mat>;
@group(0) @binding(7) var<storage, read_write> lights: array<Light>;
@group(0) @binding(8) var<storage, read_write> local: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> sh_cand: array<Shadow>;
@group(0) @binding(10) var<storage, read_write> nx_cand_r: array<Ray>;
@group(0) @binding(11) var<storage, read_write> nx_cand_i: array<Item>;
@group(0) @binding(12) var<storage, read_write> sh_count: array<u32>;
@group(0) @binding(13) var<storage, read_write> nx_count: array<u32>;
@group(0) @binding(14) var<storage, read_write> sh_start: array<u32>;
@group(0) @binding(15) var<storage, read_write> nx_start: array<u32>;
@group(0) @binding(16) var<storage, read_write> sh_rays: array<Ray>;
@group(0) @binding(17) var<storage, read_write> sh_add: array<vec4<f32>>;
@group(0) @binding(18) var<storage, read_write> nx_rays: array<Ray>;
@group(0) @binding(19) var<storage, read_write> nx_items: array<Item>;
@group(0) @binding(20) var<storage, read_write> sh_hits: array<vec4<u32>>;
@group(0) @binding(21) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(22) var<storage, read_write> rgba: array<vec4<f32>>;

// frame.rs `ShadeEmitter`: an emissive triangle, drawn by `cdf`.
struct Emitter {
    p0: vec3<f32>,
    area: f32,
    e1: vec3<f32>,
    tri: u32,
    e2: vec3<f32>,
    material: u32,
    normal: vec3<f32>,
    two_sided: u32,
    cdf: f32,
    cdf_below: f32,
    pad0: u32,
    pad1: u32,
}

// The camera (frame.rs `CameraRays`), for the camera rays' level.
struct Cam {
    // origin, tan(yfov / 2)
    o: vec4<f32>,
    // the rotation's columns; w: aspect, xmag, ymag
    rx: vec4<f32>,
    ry: vec4<f32>,
    rz: vec4<f32>,
    // image width, height, frame, samples a pixel
    a: vec4<u32>,
    // the jitter grid's columns and rows, overscan, the data window's width
    b: vec4<u32>,
    // the chunk's first pixel, 1 for orthographic, the zero of `nc`
    c: vec4<u32>,
    // the camera rays' cone: width, spread (`wavefront::primary_cone`); 1 when the
    // light-path passes are traced (`light_paths`)
    d: vec4<f32>,
}

@group(0) @binding(23) var<uniform> C: Cam;

// The next level's uniforms, made on the GPU (`next_level`): templates in, uniforms
// out (this file's FP, then trace.wgsl's Params for the closest hits and for the any
// hits) and then the dispatches' workgroup counts (the next level's items, its closest
// hits, this level's any hits); and the frame's running totals (overflow, shadow rays,
// next-level rays).
@group(0) @binding(24) var<storage, read_write> templates: array<u32>;
@group(0) @binding(25) var<storage, read_write> made: array<u32>;
@group(0) @binding(26) var<storage, read_write> totals: array<u32>;
// The area lights (F.g.w of them).
@group(0) @binding(27) var<storage, read_write> emitters: array<Emitter>;
// The environment map (frame.rs `GpuShading::environment`): width and height (u32 bits),
// the turn's cos and sin, the intensity, three unused words, then the texels' RGB,
// row-major from the top row.
@group(0) @binding(28) var<storage, read_write> env: array<f32>;

// The textures (frame.rs `GpuTextures`): the decoding tables, views and levels; the
// texels (RGBA8, R in the low byte).
@group(0) @binding(29) var<storage, read_write> tex_meta: array<u32>;
@group(0) @binding(30) var<storage, read_write> texels: array<u32>;

const NONE: u32 = 0xffffffffu;
// `render::shade`'s constants (a test in `render::gpu_frame` holds them to the CPU's).
const GLOSSY_LIMIT: f32 = 0.4;
const MIRROR_ALPHA: f32 = 0.001;
const MAX_SHININESS: f32 = 256.0;
const MAX_PASSES: f32 = 16.0;
const FRAC_1_PI: f32 = 0.31830988618379067;
// Next-level ray slots an item has: a pass-through, a diffuse bounce, a refraction, a
// reflection (frame.rs `NEXT_SLOTS`).
const NEXT_SLOTS: u32 = 4u;
const PI: f32 = 3.14159265358979323846;

fn inf() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

// Tests by bits, which a driver may not assume NaN-free.
fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn finite3(v: vec3<f32>) -> bool {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

fn is_nan(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u;
}

fn is_zero3(v: vec3<f32>) -> bool {
    return ((bitcast<u32>(v.x) | bitcast<u32>(v.y) | bitcast<u32>(v.z)) & 0x7fffffffu) == 0u;
}

fn max3(v: vec3<f32>) -> f32 {
    return max(max(v.x, v.y), v.z);
}

// glam's `normalize_or_zero`.
fn nz(v: vec3<f32>) -> vec3<f32> {
    let r = 1.0 / sqrt(dot(v, v));
    if finite(r) && r > 0.0 {
        return v * r;
    }
    return vec3<f32>(0.0);
}

// `geometry::Shear::new(d)`: (sx, sy, sz) and kx | ky << 2 | kz << 4 | 1 << 8.
fn shear(d: vec3<f32>, s: ptr<function, vec3<f32>>) -> u32 {
    let a = abs(d);
    var kz = 2u;
    if a.x >= a.y && a.x >= a.z {
        kz = 0u;
    } else if a.y >= a.z {
        kz = 1u;
    }
    let neg = d[kz] < 0.0;
    var kx = 0u;
    var ky = 1u;
    switch kz {
        case 0u: {
            if neg { kx = 2u; ky = 1u; } else { kx = 1u; ky = 2u; }
        }
        case 1u: {
            if neg { kx = 0u; ky = 2u; } else { kx = 2u; ky = 0u; }
        }
        default: {
            if neg { kx = 1u; ky = 0u; } else { kx = 0u; ky = 1u; }
        }
    }
    let z = f64(d[kz]);
    *s = vec3<f32>(f32(f64(d[kx]) / z), f32(f64(d[ky]) / z), f32(1.0lf / z));
    return kx | (ky << 2u) | (kz << 4u) | (1u << 8u);
}

// `trace::pack_ray` of `Ray::segment(o, d, t0, t1)`: the shear of a valid ray.
fn make_ray(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> Ray {
    var r: Ray;
    r.o = vec4<f32>(o, t0);
    r.d = vec4<f32>(d, t1);
    r.s = vec3<f32>(0.0);
    r.k = 0u;
    if finite3(o) && finite3(d) && !is_zero3(d) && !is_nan(t0) && !is_nan(t1) {
        var s = vec3<f32>(0.0);
        r.k = shear(d, &s);
        r.s = s;
    }
    return r;
}

// The camera rays, as `wavefront::sample_offset` and `CameraModel::ray` make them, to
// the bit: Vulkan rounds f32 + - * correctly; a product that feeds an add goes through
// `nc` (an xor with a zero from the uniform, as in trace.wgsl) so that nothing is fused;
// the divisions are made in f64 and rounded once (correctly rounded, see `shear`); the
// hash's 64-bit arithmetic is done on pairs of u32.
fn nc(x: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(x) ^ C.c.z);
}

fn nc3(v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(nc(v.x), nc(v.y), nc(v.z));
}

fn div_rn(a: f32, b: f32) -> f32 {
    return f32(f64(a) / f64(b));
}

// u64 as (low, high) words.
fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// a >> s for 0 < s < 32.
fn shr64(a: vec2<u32>, s: u32) -> vec2<u32> {
    return vec2<u32>((a.x >> s) | (a.y << (32u - s)), a.y >> s);
}

// The full 64-bit product of two u32.
fn mul32(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let p11 = a1 * b1;
    let mid = (p00 >> 16u) + (p01 & 0xffffu) + (p10 & 0xffffu);
    return vec2<u32>((p00 & 0xffffu) | (mid << 16u), p11 + (p01 >> 16u) + (p10 >> 16u) + (mid >> 16u));
}

// a * b mod 2^64.
fn mul64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let p = mul32(a.x, b.x);
    return vec2<u32>(p.x, p.y + a.x * b.y + a.y * b.x);
}

// SplitMix64's finaliser (`sampling::mix`).
fn mix64(x: vec2<u32>) -> vec2<u32> {
    var h = mul64(x ^ shr64(x, 30u), vec2<u32>(0x1CE4E5B9u, 0xBF58476Du));
    h = mul64(h ^ shr64(h, 27u), vec2<u32>(0x133111EBu, 0x94D049BBu));
    return h ^ shr64(h, 31u);
}

// `wavefront::hash`.
fn hash4(v: vec4<u32>) -> vec2<u32> {
    let g = vec2<u32>(0x7F4A7C15u, 0x9E3779B9u);
    var h = g;
    for (var i = 0u; i < 4u; i = i + 1u) {
        h.x = h.x ^ v[i];
        h = mix64(add64(h, g));
    }
    return h;
}

// `Seed::camera(frame, x, y, k)` of this chunk's frame; `p`: x, y, k.
fn seed_camera(p: vec3<u32>) -> vec2<u32> {
    let g = vec2<u32>(0x7F4A7C15u, 0x9E3779B9u);
    var h = vec2<u32>(0xD1CE4E5Bu, 0x5DEECE66u);
    let v = vec4<u32>(C.a.z, p.x, p.y, p.z);
    for (var i = 0u; i < 4u; i = i + 1u) {
        h.x = h.x ^ v[i];
        h = add64(mix64(h), g);
    }
    return h;
}

// `Seed::child(kind)`: the seed of a ray this one spawns (0 reflection, 1 refraction).
fn seed_child(s: vec2<u32>, kind: u32) -> vec2<u32> {
    return mix64(s ^ mul64(vec2<u32>(kind + 1u, 0u), vec2<u32>(0x6659FD93u, 0xD6E8FEB8u)));
}

// `Seed::get(purpose, i)`: two uniform numbers in [0, 1), the CPU's to the bit
// (integers under 2^24 times 2^-24).
fn seed_get(s: vec2<u32>, purpose: u32, i: u32) -> vec2<f32> {
    return unit2(mix64(s ^ mix64(vec2<u32>(i, purpose))));
}

// Two uniform numbers in [0, 1) from a 64-bit hash's bits 40..64 and 16..40, as the
// CPU takes them (integers under 2^24 times 2^-24: exact).
fn unit2(h: vec2<u32>) -> vec2<f32> {
    return vec2<f32>(
        f32(h.y >> 8u) * (1.0 / 16777216.0),
        f32(((h.y << 16u) | (h.x >> 16u)) & 0xffffffu) * (1.0 / 16777216.0),
    );
}

// `wavefront::sample_offset(frame, x, y, k, spp)`.
fn sample_offset(x: u32, y: u32, k: u32) -> vec2<f32> {
    if C.a.w <= 1u {
        return vec2<f32>(0.5);
    }
    let sx = C.b.x;
    let sy = C.b.y;
    let r = unit2(hash4(vec4<u32>(C.a.z, x, y, k)));
    return vec2<f32>(
        min(div_rn(f32(k % sx) + r.x, f32(sx)), top()),
        min(div_rn(f32(k / sx) + r.y, f32(sy)), top()),
    );
}

// The rotation times v: (X·vx + Y·vy) + Z·vz, as glam's Mat3 * Vec3.
fn rotate(v: vec3<f32>) -> vec3<f32> {
    return (nc3(C.rx.xyz * v.x) + nc3(C.ry.xyz * v.y)) + nc3(C.rz.xyz * v.z);
}

// `CameraModel::ray(px, py)`.
fn camera_ray(px: f32, py: f32) -> Ray {
    let sx = div_rn(2.0 * px, f32(C.a.x)) - 1.0;
    let sy = 1.0 - div_rn(2.0 * py, f32(C.a.y));
    if C.c.y == 0u {
        let d = vec3<f32>(sx * C.rx.w * C.o.w, sy * C.o.w, -1.0);
        return make_ray(C.o.xyz, rotate(d), 0.0, inf());
    }
    let o = rotate(vec3<f32>(sx * C.ry.w, sy * C.rz.w, 0.0));
    return make_ray(C.o.xyz + o, rotate(vec3<f32>(0.0, 0.0, -1.0)), 0.0, inf());
}

// An item's shadow ray slots: a punctual light each, then the area-light samples.
fn slots() -> u32 {
    return F.a.y + F.h.w;
}

// The shadow rays' batches: the punctual lights, then one for every area-light sample.
fn batches() -> u32 {
    return F.a.y + select(0u, 1u, F.g.w > 0u);
}

// 0.999_999_9 as f32.
fn top() -> f32 {
    return bitcast<f32>(0x3f7ffffeu);
}

// `sampling::stratified`: the i-th of n stratified pairs in [0, 1)^2 from r (cell i of
// an a x b grid, a the largest divisor of n up to its square root).
fn stratified(i: u32, n: u32, r: vec2<f32>) -> vec2<f32> {
    if n <= 1u {
        return r;
    }
    // floor(sqrt(n)), exactly.
    var a = u32(sqrt(f32(n)));
    while a * a > n {
        a = a - 1u;
    }
    while (a + 1u) * (a + 1u) <= n {
        a = a + 1u;
    }
    while a > 1u && n % a != 0u {
        a = a - 1u;
    }
    let b = n / max(a, 1u);
    let j = i % n;
    return vec2<f32>(
        min(div_rn(f32(j % a) + r.x, f32(a)), top()),
        min(div_rn(f32(j / a) + r.y, f32(b)), top()),
    );
}

fn grid_index(gid: vec3<u32>) -> u32 {
    return gid.y * F.b.y + gid.x;
}

// The sample item `i` adds to: at the camera rays' level item i is sample i, but for a
// blurred frame's step (F.a.z 2), whose first items the host wrote with their samples.
fn sample_of(i: u32) -> u32 {
    if F.a.z == 1u {
        return i;
    }
    return items[i].m.x;
}

fn tri_vec(t: u32, k: u32) -> vec4<f32> {
    if t < F.b.x {
        return surf_s[t * 8u + k];
    }
    return surf_m[(t - F.b.x) * 8u + k];
}

struct Surf {
    point: vec3<f32>,
    ng: vec3<f32>,
    ns: vec3<f32>,
    dir: vec3<f32>,
    entering: bool,
    mat: u32,
    uv: vec2<f32>,
    // texture level of detail for a unit texture (`Surface::lod`)
    lod: f32,
}

// `ShadeContext::surface`; `width`: the ray cone's width at the hit.
fn surface(r: Ray, h: vec4<u32>, width: f32) -> Surf {
    let t = h.y;
    let u = bitcast<f32>(h.z);
    let v = bitcast<f32>(h.w);
    let w = 1.0 - u - v;
    let a0 = tri_vec(t, 0u);
    let a1 = tri_vec(t, 1u);
    let a2 = tri_vec(t, 2u);
    let p0 = a0.xyz;
    let p1 = a1.xyz;
    let p2 = a2.xyz;
    var s: Surf;
    s.point = p0 * w + p1 * u + p2 * v;
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    var ng = nz(cross(e1, e2));
    s.dir = nz(r.d.xyz);
    if is_zero3(ng) {
        ng = -s.dir;
    }
    let front = ng;
    s.entering = dot(ng, s.dir) < 0.0;
    if !s.entering {
        ng = -ng;
    }
    var ns = vec3<f32>(0.0);
    if bitcast<u32>(a1.w) != 0u {
        let n0 = tri_vec(t, 3u).xyz;
        let n1 = tri_vec(t, 4u).xyz;
        let n2 = tri_vec(t, 5u).xyz;
        ns = nz(n0 * w + n1 * u + n2 * v);
    }
    if is_zero3(ns) || !finite3(ns) {
        ns = front;
    }
    // Texture coordinates, level of detail and the normal map (the textures' part below).
    let mi = bitcast<u32>(a0.w);
    let a7 = tri_vec(t, 7u);
    let has_uvs = bitcast<u32>(a7.w) != 0u;
    var t0 = vec2<f32>(0.0);
    var t1 = vec2<f32>(0.0);
    var t2 = vec2<f32>(0.0);
    s.uv = vec2<f32>(0.0);
    if has_uvs {
        let a6 = tri_vec(t, 6u);
        t0 = a6.xy;
        t1 = a6.zw;
        t2 = a7.xy;
        s.uv = t0 * w + t1 * u + t2 * v;
    }
    s.lod = -inf();
    let tx = mats[mi].tex;
    let textured = any(tx != vec4<u32>(NONE));
    if has_uvs && textured && width > 0.0 {
        let d1 = t1 - t0;
        let d2 = t2 - t0;
        let uv_area = abs(d1.x * d2.y - d1.y * d2.x);
        let world_area = length(cross(e1, e2));
        let cos_v = max(abs(dot(ng, s.dir)), 1e-4);
        if uv_area > 0.0 && world_area > 0.0 {
            s.lod = log2(width / cos_v) + 0.5 * log2(uv_area / world_area);
        }
    }
    if has_uvs && tx.w != NONE {
        ns = normal_mapped(mi, ns, e1, e2, t0, t1, t2, s.uv, s.lod);
    }
    if dot(ns, ng) < 0.0 {
        ns = -ns;
    }
    s.ng = ng;
    s.ns = ns;
    s.mat = mi;
    return s;
}

// ---- Textures: `ShadeContext::texture` and `TextureMips::lookup` (render/mips.rs),
// filtered by hand from the texels (no samplers), in the CPU's arithmetic: texel
// coordinates in f64 (exact: a uv times a side), the fractions rounded to f32 as the CPU
// rounds them, the bytes decoded by the CPU's own tables (in `tex_meta`), glam's lerps.

// Where the views begin in `tex_meta` (after the sRGB and the linear tables).
const VIEWS: u32 = 512u;

// `mips::wrap` of the whole number `i` on a side of `n` texels (0 repeat, 1 clamp to
// edge, 2 mirrored repeat).
fn tex_wrap(i: f64, n: f64, mode: u32) -> u32 {
    var m: f64;
    if mode == 1u {
        m = i;
    } else {
        var p = n;
        if mode == 2u {
            p = 2.0lf * n;
        }
        m = i - p * floor(i / p);
        if m >= p {
            m = m - p;
        }
        if m < 0.0lf {
            m = m + p;
        }
        if mode == 2u && m >= n {
            m = p - 1.0lf - m;
        }
    }
    return u32(clamp(m, 0.0lf, n - 1.0lf));
}

// The texel at (x, y) of the level whose record is at word `lv`, decoded: RGB by the
// table at word `table` (0 sRGB, 256 linear), alpha by the linear one.
fn texel(lv: u32, x: f64, y: f64, wrap_s: u32, wrap_t: u32, table: u32) -> vec4<f32> {
    let w = tex_meta[lv + 1u];
    let h = tex_meta[lv + 2u];
    let p = texels[tex_meta[lv] + tex_wrap(y, f64(h), wrap_t) * w + tex_wrap(x, f64(w), wrap_s)];
    return vec4<f32>(
        bitcast<f32>(tex_meta[table + (p & 255u)]),
        bitcast<f32>(tex_meta[table + ((p >> 8u) & 255u)]),
        bitcast<f32>(tex_meta[table + ((p >> 16u) & 255u)]),
        bitcast<f32>(tex_meta[256u + (p >> 24u)]),
    );
}

// glam's `lerp`.
fn lerp4(a: vec4<f32>, b: vec4<f32>, f: f32) -> vec4<f32> {
    return a * (1.0 - f) + b * f;
}

// `TextureMips::bilinear` of view `vw` (its word) on the level at word `lv`.
fn bilinear(vw: u32, lv: u32, uv: vec2<f32>, nearest: bool) -> vec4<f32> {
    let ws = tex_meta[vw + 1u];
    let wt = tex_meta[vw + 2u];
    let table = select(256u, 0u, tex_meta[vw + 6u] != 0u);
    var x = f64(uv.x) * f64(tex_meta[lv + 1u]);
    var y = f64(uv.y) * f64(tex_meta[lv + 2u]);
    if nearest {
        return texel(lv, floor(x), floor(y), ws, wt, table);
    }
    x = x - 0.5lf;
    y = y - 0.5lf;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = f32(x - x0);
    let fy = f32(y - y0);
    let x1 = x0 + 1.0lf;
    let y1 = y0 + 1.0lf;
    let top = lerp4(texel(lv, x0, y0, ws, wt, table), texel(lv, x1, y0, ws, wt, table), fx);
    let bottom = lerp4(texel(lv, x0, y1, ws, wt, table), texel(lv, x1, y1, ws, wt, table), fx);
    return lerp4(top, bottom, fy);
}

// `ShadeContext::texture` of slot `k` (0 base colour, 1 metallic-roughness, 2 emissive,
// 3 normal) of material `mi`, which has a texture there, at `uv_in`, for a footprint of
// level `lod_in` (a unit texture's).
fn tex_at(mi: u32, k: u32, uv_in: vec2<f32>, lod_in: f32) -> vec4<f32> {
    let vw = VIEWS + mats[mi].tex[k] * 8u;
    var uv = uv_in;
    let xa = mats[mi].xf[2u * k];
    let xb = mats[mi].xf[2u * k + 1u];
    if xb.z != 0.0 {
        // `UvTransform::apply`.
        let sc = uv * xa.xy;
        uv = vec2<f32>(xa.w * sc.x + xa.z * sc.y, xa.w * sc.y - xa.z * sc.x) + xb.xy;
    }
    if !finite(uv.x) || !finite(uv.y) {
        uv = vec2<f32>(0.0);
    }
    var lod = lod_in + bitcast<f32>(tex_meta[vw + 5u]);
    let top = tex_meta[vw];
    let lw = tex_meta[vw + 4u];
    if !finite(lod) {
        lod = 0.0;
    }
    if lod <= 0.0 || top == 0u {
        return bilinear(vw, lw, uv, tex_meta[vw + 3u] != 0u && lod <= 0.0);
    }
    lod = min(lod, f32(top));
    let l0 = floor(lod);
    let f = lod - l0;
    let li = u32(l0);
    let a = bilinear(vw, lw + 4u * li, uv, false);
    if f <= 0.0 || li >= top {
        return a;
    }
    return lerp4(a, bilinear(vw, lw + 4u * (li + 1u), uv, false), f);
}

// glam's `try_normalize`: w = 0 for none.
fn try_nz(v: vec3<f32>) -> vec4<f32> {
    let r = 1.0 / sqrt(dot(v, v));
    if finite(r) && r > 0.0 {
        return vec4<f32>(v * r, 1.0);
    }
    return vec4<f32>(0.0);
}

// `ShadeContext::normal_mapped`, `n` where the CPU's gives `None`. `e1`, `e2`: the
// triangle's edges; `t0..t2` its uvs.
fn normal_mapped(mi: u32, n: vec3<f32>, e1: vec3<f32>, e2: vec3<f32>, t0: vec2<f32>, t1: vec2<f32>, t2: vec2<f32>, uv: vec2<f32>, lod: f32) -> vec3<f32> {
    let c = tex_at(mi, 3u, uv, lod);
    let d1 = t1 - t0;
    let d2 = t2 - t0;
    let det = d1.x * d2.y - d1.y * d2.x;
    if abs(det) < 1e-12 {
        return n;
    }
    let dpdu = (e1 * d2.y - e2 * d1.y) / det;
    let dpdv = (e2 * d1.x - e1 * d2.x) / det;
    let tg = try_nz(dpdu - n * dot(n, dpdu));
    if tg.w == 0.0 {
        return n;
    }
    var bt = cross(n, tg.xyz);
    if dot(bt, dpdv) > 0.0 {
        bt = -bt;
    }
    let sc = mats[mi].factors.w;
    let l = vec3<f32>((2.0 * c.x - 1.0) * sc, (2.0 * c.y - 1.0) * sc, 2.0 * c.z - 1.0);
    let bent = try_nz(tg.xyz * l.x + bt * l.y + n * l.z);
    if bent.w == 0.0 || dot(bent.xyz, n) <= 0.0 {
        return n;
    }
    return bent.xyz;
}

// `ShadeContext::shininess`.
fn shininess(r: f32) -> f32 {
    if r < 0.9 {
        let r2 = r * r;
        return min(2.0 / max(r2 * r2, 1e-4) - 2.0, MAX_SHININESS);
    }
    return 0.0;
}

// Material `mi` at `s` with what its textures change there, as the CPU computes it
// (`base_color`; `lobes`' metallic and roughness and what follows from them; `emission`;
// the glint's exponent and factors): the table's entry for a material without textures.
fn textured(mi: u32, s: Surf) -> Mat {
    var m = mats[mi];
    if all(m.tex == vec4<u32>(NONE)) {
        return m;
    }
    if m.tex.x != NONE {
        // `base_color`: factor × texture, alpha too.
        let t = tex_at(mi, 0u, s.uv, s.lod);
        m.albedo = m.albedo * t.xyz;
        m.alpha.x = m.alpha.x * t.w;
    }
    if m.tex.y != NONE {
        let t = tex_at(mi, 1u, s.uv, s.lod);
        m.metallic = clamp(m.factors.x * t.z, 0.0, 1.0);
        m.roughness = clamp(m.factors.y * t.y, 0.0, 1.0);
        m.transmission = m.factors.z * (1.0 - m.metallic);
        m.gloss = (1.0 - m.roughness) * (1.0 - m.roughness);
        // `lobes`: no reflection ray from GLOSSY_LIMIT on, a mirror's under MIRROR_ALPHA,
        // else one drawn from the GGX lobe.
        m.reflects = 0u;
        if m.roughness < GLOSSY_LIMIT {
            m.reflects = select(2u, 1u, m.roughness * m.roughness < MIRROR_ALPHA);
        }
        m.shininess = shininess(m.roughness);
        m.glint_norm = (m.shininess + 8.0) / (8.0 * PI);
        m.glint_scale = 1.0 - m.gloss * 0.5;
    }
    m.f0 = vec3<f32>(0.04) * (1.0 - m.metallic) + m.albedo * m.metallic;
    if m.tex.z != NONE && !is_zero3(m.emission) {
        m.emission = m.emission * tex_at(mi, 2u, s.uv, s.lod).xyz;
    }
    return m;
}

// `alpha_of`: the coverage of material `m` (as `textured` made it) at the hit.
fn alpha_of(m: Mat) -> f32 {
    if m.alpha.z == 1.0 {
        return select(0.0, 1.0, m.alpha.x >= m.alpha.y);
    }
    if m.alpha.z == 2.0 {
        return clamp(m.alpha.x, 0.0, 1.0);
    }
    return 1.0;
}

// `ShadeContext::emission` at barycentrics `b` of emitter `e`'s triangle (`uv_at`; the
// finest texture level, as the CPU reads it for a light sample).
fn emitted_at(e: Emitter, b: vec2<f32>) -> vec3<f32> {
    var em = mats[e.material].emission;
    if mats[e.material].tex.z != NONE && !is_zero3(em) {
        var uv = vec2<f32>(0.0);
        if bitcast<u32>(tri_vec(e.tri, 7u).w) != 0u {
            let a6 = tri_vec(e.tri, 6u);
            let a7 = tri_vec(e.tri, 7u);
            uv = a6.xy * (1.0 - b.x - b.y) + a6.zw * b.x + a7.xy * b.y;
        }
        em = em * tex_at(e.material, 2u, uv, -inf()).xyz;
    }
    return em;
}

fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let sin_t2 = eta * eta * (1.0 - cos_i * cos_i);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin_t2);
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return clamp(0.5 * (rs * rs + rp * rp), 0.0, 1.0);
}

fn reflect_(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return d - 2.0 * dot(d, n) * n;
}

// `refract`: w = 0 on total internal reflection.
fn refract_(d: vec3<f32>, n: vec3<f32>, eta: f32) -> vec4<f32> {
    let cos_i = -dot(d, n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(nz(eta * d + (eta * cos_i - sqrt(k)) * n), 1.0);
}

// `sampling::basis`: an orthonormal basis (t, b) around unit n (Duff et al. 2017).
fn basis_t(n: vec3<f32>, sign: f32) -> vec3<f32> {
    let a = -1.0 / (sign + n.z);
    return vec3<f32>(1.0 + sign * n.x * n.x * a, sign * (n.x * n.y * a), -sign * n.x);
}

fn basis_b(n: vec3<f32>, sign: f32) -> vec3<f32> {
    let a = -1.0 / (sign + n.z);
    return vec3<f32>(n.x * n.y * a, sign + n.y * n.y * a, -n.y);
}

// `1.0f32.copysign(x)`.
fn sign_of(x: f32) -> f32 {
    return select(1.0, -1.0, (bitcast<u32>(x) & 0x80000000u) != 0u);
}

// `sampling::sample_cosine`: a direction around unit n with density cos / pi.
fn sample_cosine(n: vec3<f32>, r: vec2<f32>) -> vec3<f32> {
    let sign = sign_of(n.z);
    let t = basis_t(n, sign);
    let b = basis_b(n, sign);
    let radius = sqrt(r.y);
    let phi = 2.0 * 3.14159265358979323846 * r.x;
    return nz(t * (radius * cos(phi)) + b * (radius * sin(phi)) + n * sqrt(max(1.0 - r.y, 0.0)));
}

fn env_texel(x: u32, y: u32) -> vec3<f32> {
    let k = 8u + 3u * (y * bitcast<u32>(env[0]) + x);
    return vec3<f32>(env[k], env[k + 1u], env[k + 2u]);
}

// `EnvironmentMap::radiance`: the map turned about +Y, looked up bilinearly
// (equirectangular; columns wrap, rows clamp).
fn env_radiance(dir: vec3<f32>) -> vec3<f32> {
    let w = bitcast<u32>(env[0]);
    let hh = bitcast<u32>(env[1]);
    let c = env[2];
    let sn = env[3];
    let d = vec3<f32>(c * dir.x - sn * dir.z, dir.y, sn * dir.x + c * dir.z);
    let u = 0.5 + atan2(d.z, d.x) / 6.283185307179586;
    let v = 0.5 + atan2(d.y, sqrt(d.x * d.x + d.z * d.z)) / 3.14159265358979323846;
    if !(finite(u) && finite(v)) {
        return vec3<f32>(0.0);
    }
    let x = u * f32(w) - 0.5;
    let y = (1.0 - v) * f32(hh) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let wi = i32(w);
    let xi = i32(x0);
    let yi = i32(y0);
    let xa = u32(((xi % wi) + wi) % wi);
    let xb = u32((((xi + 1) % wi) + wi) % wi);
    let ya = u32(clamp(yi, 0, i32(hh) - 1));
    let yb = u32(clamp(yi + 1, 0, i32(hh) - 1));
    let top = env_texel(xa, ya) * (1.0 - fx) + env_texel(xb, ya) * fx;
    let bottom = env_texel(xa, yb) * (1.0 - fx) + env_texel(xb, yb) * fx;
    return (top * (1.0 - fy) + bottom * fy) * env[4];
}

// `sampling::smith_g1`: GGX Smith masking for a direction at cosine `c`, width `alpha`.
fn smith_g1(c: f32, alpha: f32) -> f32 {
    let c2 = max(c * c, 1e-8);
    let t2 = (1.0 - c2) / c2;
    return 2.0 / (1.0 + sqrt(1.0 + alpha * alpha * t2));
}

// `sampling::sample_ggx_vndf`: a GGX normal drawn from those visible from `v` (Heitz
// 2018) around unit n, width `alpha`, from the uniform pair `r`.
fn sample_ggx_vndf(v: vec3<f32>, n: vec3<f32>, alpha: f32, r: vec2<f32>) -> vec3<f32> {
    let sign = sign_of(n.z);
    let t = basis_t(n, sign);
    let b = basis_b(n, sign);
    let vl = vec3<f32>(dot(v, t), dot(v, b), max(dot(v, n), 1e-6));
    let vh = normalize(vec3<f32>(alpha * vl.x, alpha * vl.y, vl.z));
    let len2 = vh.x * vh.x + vh.y * vh.y;
    var t1 = vec3<f32>(1.0, 0.0, 0.0);
    if len2 > 0.0 {
        t1 = vec3<f32>(-vh.y, vh.x, 0.0) / sqrt(len2);
    }
    let t2 = cross(vh, t1);
    let rad = sqrt(r.x);
    let phi = 2.0 * 3.14159265358979323846 * r.y;
    let p1 = rad * cos(phi);
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * rad * sin(phi);
    let p3 = sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0));
    let nh = t1 * p1 + t2 * p2 + vh * p3;
    let m = normalize(vec3<f32>(alpha * nh.x, alpha * nh.y, max(nh.z, 1e-6)));
    return nz(t * m.x + b * m.y + n * m.z);
}

struct Lobes {
    v: vec3<f32>,
    kr: vec3<f32>,
    kt: vec3<f32>,
    kd: vec3<f32>,
    eta: f32,
}

// `ShadeContext::lobes` of a constant material.
fn lobes(m: Mat, s: Surf) -> Lobes {
    var l: Lobes;
    l.v = -s.dir;
    let cos_o = clamp(dot(s.ns, l.v), 0.0, 1.0);
    l.eta = m.eta_leaving;
    if s.entering {
        l.eta = m.eta_entering;
    }
    var fresnel: vec3<f32>;
    if m.transmission > 0.0 {
        fresnel = vec3<f32>(fresnel_dielectric(cos_o, l.eta));
    } else {
        let x = 1.0 - cos_o;
        let x2 = x * x;
        let x4 = x2 * x2;
        fresnel = m.f0 + (vec3<f32>(1.0) - m.f0) * (x4 * x);
    }
    l.kt = (vec3<f32>(1.0) - fresnel) * m.transmission * m.albedo;
    if m.reflects != 0u {
        l.kr = fresnel;
        l.kd = m.albedo * ((1.0 - m.metallic) * (1.0 - m.transmission) * (1.0 - max3(fresnel)));
    } else {
        l.kr = vec3<f32>(0.0);
        l.kd = m.albedo * ((1.0 - m.metallic) * (1.0 - m.transmission) * (1.0 - max3(fresnel) * m.gloss) + m.metallic * (1.0 - m.gloss));
    }
    return l;
}

// `ShadeContext::brdf` with the highlight: diffuse plus the capped Blinn-Phong glint.
fn brdf(m: Mat, l: Lobes, s: Surf, to: vec3<f32>) -> vec3<f32> {
    var b = l.kd * FRAC_1_PI;
    if m.shininess > 0.0 {
        b = b + glint(m, l, s, to);
    }
    return b;
}

// `ShadeContext::glint`: the capped Blinn-Phong highlight (0 without one).
fn glint(m: Mat, l: Lobes, s: Surf, to: vec3<f32>) -> vec3<f32> {
    if m.shininess <= 0.0 {
        return vec3<f32>(0.0);
    }
    let h = nz(to + l.v);
    let nh = max(dot(s.ns, h), 0.0);
    var p = 0.0;
    if nh > 0.0 {
        p = pow(nh, m.shininess);
    }
    return m.f0 * m.glint_scale * min(m.glint_norm * p, 1e3);
}

// The light-path passes (`--aov diffuse,specular,transmission,emission`): each item's
// own terms split over the four (`BlockOut::add_split`) after the items' beauty terms
// in `local` (from word F.g.y on, `split_stride()` a item: its four, then two a shadow
// ray slot), each shadow ray's (`split_light`: the diffuse lobe's part and the
// glint's, and the pass they go to) after the shadow rays' beauty in `sh_add` (from
// F.g.z on, two a ray), each sample's four after the samples' beauty in `radiance`
// (from F.b.z × F.b.w on), and each pixel's four after the pixels in `rgba`.
fn light_paths() -> bool {
    return C.d.z != 0.0;
}

fn split_stride() -> u32 {
    return 4u + 2u * slots();
}

// Where item i's pass k goes in `local`, and its shadow ray slot j's two words.
fn split_at(i: u32, k: u32) -> u32 {
    return F.g.y + i * split_stride() + k;
}

// A pass's index from an item's path code at a term that goes to `fallback` at a camera
// ray's hit (`item.path.unwrap_or(fallback)`).
fn pass_of(path: u32, fallback: u32) -> u32 {
    if path == 0u {
        return fallback;
    }
    return path - 1u;
}

@compute @workgroup_size(64)
fn shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = grid_index(gid);
    let n = F.a.x;
    // The scans run over the items and one more; the sums up to [n] read only counts
    // written here.
    if i >= n {
        return;
    }
    let nl = F.a.y;
    let first = F.a.z != 0u;
    let r = rays[i];
    var it: Item;
    let random = F.e.y != 0.0;
    let smp = sample_of(i);
    if first {
        it.w = vec4<f32>(1.0, 1.0, 1.0, 0.0);
        it.m = vec4<u32>(smp, 0u, 0u, 0u);
        if random {
            it.m = vec4<u32>(smp, 0u, seed_camera(camera_sample(smp)));
        }
        // The camera ray's cone (`wavefront::primary_cone`).
        it.c = vec4<f32>(C.d.x, C.d.y, 1.0, 0.0);
    } else {
        it = items[i];
    }
    let h = hits[i];
    var weight = it.w.xyz;
    var add = vec3<f32>(0.0);
    var nsh = 0u;
    var nnx = 0u;
    var cover = 0.0;
    // `Item::bounces`, `Item::diffuse` and `Item::path` (the code in `w.w`).
    let code = u32(it.w.w);
    let bounces = code & 255u;
    let diffuse = (code & 256u) != 0u;
    let path = code >> 9u;
    // The item's own terms split over the passes (emission, ambient, background).
    var split: array<vec3<f32>, 4>;
    if h.y == NONE {
        if F.e.w != 0.0 {
            add = weight * env_radiance(r.d.xyz);
        } else {
            add = weight * F.d.xyz;
        }
        split[pass_of(path, 3u)] = add;
    } else if h.y < F.g.x {
        // The cone's width at the hit: width + spread × distance.
        let width = it.c.x + it.c.y * (bitcast<f32>(h.x) * length(r.d.xyz));
        let s = surface(r, h, width);
        let m = textured(s.mat, s);
        let alpha = alpha_of(m);
        let ap = abs(s.point);
        let eps = 1e-4 * max(max3(ap), 1e-3 * F.c.w);
        // `pass_through`: on through the surface, same direction, same depth, the cone
        // at the hit, weight and coverage × (1 - alpha).
        if alpha < 1.0 && it.c.w < MAX_PASSES {
            let wp = weight * (1.0 - alpha);
            if max3(wp) > F.e.x || it.c.z > 0.0 {
                var p: Item;
                p.w = vec4<f32>(wp, it.w.w);
                p.m = it.m;
                if random {
                    p.m = vec4<u32>(it.m.x, it.m.y, seed_child(it.m.zw, 2u));
                }
                p.c = vec4<f32>(width, it.c.y, it.c.z * (1.0 - alpha), it.c.w + 1.0);
                nx_cand_r[i * NEXT_SLOTS + nnx] = make_ray(s.point - s.ng * eps, s.dir, 0.0, inf());
                nx_cand_i[i * NEXT_SLOTS + nnx] = p;
                nnx = nnx + 1u;
            }
        }
        if alpha <= 0.0 {
            finish(i, first, smp, vec3<f32>(0.0), split, 0.0, 0u, nnx);
            return;
        }
        // `BlockOut::cover` keeps positive terms only.
        let c = it.c.z * alpha;
        cover = select(0.0, c, c > 0.0);
        weight = weight * alpha;
        let lb = lobes(m, s);
        var emitted = vec3<f32>(0.0);
        // A diffuse bounce's ray adds no emission (next-event estimation lit it).
        if (s.entering || m.double_sided != 0u) && !diffuse {
            emitted = m.emission;
        }
        // The ambient light is reflected with the diffuse colour, or with the material's
        // own ambient colour (AFF) times its base colour texture.
        var ambient = lb.kd;
        if m.aff.w != 0.0 {
            ambient = m.aff.xyz;
            if m.tex.x != NONE {
                ambient = ambient * tex_at(s.mat, 0u, s.uv, s.lod).xyz;
            }
        }
        add = weight * (emitted + ambient * F.c.xyz);
        split[pass_of(path, 3u)] = weight * emitted;
        split[pass_of(path, 0u)] = split[pass_of(path, 0u)] + weight * (ambient * F.c.xyz);
        let origin = s.point + s.ng * eps;
        // Direct light: a shadow ray a light that lights the point, in table order.
        for (var li = 0u; li < nl; li = li + 1u) {
            let lt = lights[li];
            var to: vec3<f32>;
            var dist = inf();
            var irr: vec3<f32>;
            if lt.kind == 0u {
                to = -lt.direction;
                irr = lt.power;
            } else {
                let d = lt.position - origin;
                let d2 = dot(d, d);
                if d2 <= 0.0 || !finite(d2) {
                    continue;
                }
                dist = sqrt(d2);
                var att = 1.0;
                if lt.no_falloff == 0u {
                    att = 1.0 / d2;
                }
                if lt.has_range != 0u {
                    let q = dist / lt.range;
                    let q2 = q * q;
                    let x = clamp(1.0 - q2 * q2, 0.0, 1.0);
                    att = att * (x * x);
                }
                to = d / dist;
                if lt.kind == 2u {
                    let cd = dot(lt.direction, -to);
                    let y = clamp((cd - lt.cos_outer) * lt.cone_scale, 0.0, 1.0);
                    att = att * (y * y);
                }
                irr = lt.power * att;
            }
            let cos_i = dot(s.ns, to);
            if cos_i <= 0.0 || dot(s.ng, to) <= 0.0 {
                continue;
            }
            let c = weight * brdf(m, lb, s, to) * irr * cos_i;
            if max3(c) <= F.e.x * 1e-2 || !finite3(c) {
                continue;
            }
            var sr: Ray;
            if finite(dist) {
                sr = make_ray(origin, to, 0.0, dist * (1.0 - 1e-4));
            } else {
                sr = make_ray(origin, to, 0.0, inf());
            }
            var sh: Shadow;
            sh.r = sr;
            sh.c = vec4<f32>(c, f32(li));
            sh_cand[i * slots() + nsh] = sh;
            if light_paths() {
                // `split_light` with the highlight: the diffuse lobe's part and the glint's.
                let e = weight * irr * cos_i;
                let at = split_at(i, 4u + 2u * nsh);
                local[at] = vec4<f32>(e * (lb.kd * FRAC_1_PI), f32(path));
                local[at + 1u] = vec4<f32>(e * glint(m, lb, s, to), 0.0);
            }
            nsh = nsh + 1u;
        }
        // `area_light`: shadow rays to points on the emissive triangles (one batch after
        // the punctual lights'), each emitter drawn by power, the point stratified; at a
        // camera ray's hit the pixel's samples share one stratification (cell j * spp + k
        // for light sample j of pixel sample k), the emitter choice over the cells in a
        // scrambled order.
        let ne = F.g.w;
        if ne > 0u {
            let spp = max(F.b.w, 1u);
            var n = 1u;
            var k = 0u;
            var cells = 1u;
            if it.m.y == 0u {
                n = F.h.w;
                k = it.m.x % spp;
                cells = n * spp;
            }
            let seed = it.m.zw;
            for (var j = 0u; j < n; j = j + 1u) {
                let cell = j * (cells / n) + k;
                // Purpose::AreaLight is 2.
                let rp = seed_get(seed, 2u, 2u * j);
                var scrambled = f32(cell);
                if cells % 7919u != 0u {
                    scrambled = f32((cell * 7919u) % cells);
                }
                let pick = min(div_rn(scrambled + rp.x, f32(cells)), top());
                let rs = stratified(cell, cells, seed_get(seed, 2u, 2u * j + 1u));
                // `AreaLights::pick`: the first emitter whose cdf is above `pick`.
                var lo = 0u;
                var hi = ne;
                while lo < hi {
                    let mid = (lo + hi) / 2u;
                    if emitters[mid].cdf <= pick {
                        lo = mid + 1u;
                    } else {
                        hi = mid;
                    }
                }
                let e = emitters[min(lo, ne - 1u)];
                let pe = e.cdf - e.cdf_below;
                if !(pe > 0.0) || e.tri == h.y {
                    continue;
                }
                let su = sqrt(rs.x);
                let lp = e.p0 + e.e1 * (su * (1.0 - rs.y)) + e.e2 * (su * rs.y);
                let pdf_area = pe / e.area;
                let d = lp - origin;
                let d2 = dot(d, d);
                if !(d2 > 0.0 && finite(d2)) {
                    continue;
                }
                let dist = sqrt(d2);
                let to = d / dist;
                let cos_i = dot(s.ns, to);
                if cos_i <= 0.0 || dot(s.ng, to) <= 0.0 {
                    continue;
                }
                var cos_l = -dot(e.normal, to);
                if e.two_sided != 0u {
                    cos_l = abs(cos_l);
                }
                if cos_l <= 0.0 {
                    continue;
                }
                let le = emitted_at(e, vec2<f32>(su * (1.0 - rs.y), su * rs.y));
                // The glint only on a surface without a reflection ray.
                var b = lb.kd * FRAC_1_PI;
                if m.reflects == 0u {
                    b = brdf(m, lb, s, to);
                }
                let c = weight * b * le * (cos_i * cos_l / (d2 * pdf_area * f32(n)));
                if max3(c) <= F.e.x * 1e-2 || !finite3(c) {
                    continue;
                }
                var sh: Shadow;
                sh.r = make_ray(origin, to, 0.0, dist * (1.0 - 1e-3));
                sh.c = vec4<f32>(c, f32(nl));
                sh_cand[i * slots() + nsh] = sh;
                if light_paths() {
                    let e = weight * le * (cos_i * cos_l / (d2 * pdf_area * f32(n)));
                    var g = vec3<f32>(0.0);
                    if m.reflects == 0u {
                        g = e * glint(m, lb, s, to);
                    }
                    let at = split_at(i, 4u + 2u * nsh);
                    local[at] = vec4<f32>(e * (lb.kd * FRAC_1_PI), f32(path));
                    local[at + 1u] = vec4<f32>(g, 0.0);
                }
                nsh = nsh + 1u;
            }
        }
        // `diffuse_bounce`: one cosine-weighted direction (Purpose::Diffuse is 3), made
        // whatever the depth, before the secondary rays.
        if bounces < u32(F.e.z) {
            let wb = weight * lb.kd;
            if max3(wb) > F.e.x {
                let dir = sample_cosine(s.ns, seed_get(it.m.zw, 3u, 0u));
                if dot(dir, s.ng) > 0.0 {
                    var b: Item;
                    b.w = vec4<f32>(wb, f32(bounces + 1u + 256u + 512u * select(path, 1u, path == 0u)));
                    b.m = vec4<u32>(it.m.x, it.m.y + 1u, seed_child(it.m.zw, 3u));
                    // A diffuse lobe spreads over the hemisphere: the coarsest level.
                    b.c = vec4<f32>(width, 1.0, 0.0, it.c.w);
                    nx_cand_r[i * NEXT_SLOTS + nnx] = make_ray(origin, dir, 0.0, inf());
                    nx_cand_i[i * NEXT_SLOTS + nnx] = b;
                    nnx = nnx + 1u;
                }
            }
        }
        // `secondary`: refraction, then the mirror or GGX reflection.
        if it.m.y < F.a.w {
            var kr = lb.kr;
            let kt_w = weight * lb.kt;
            var next: Item;
            let seed = it.m.zw;
            next.m = vec4<u32>(it.m.x, it.m.y + 1u, 0u, 0u);
            // The cone goes on from its width at the hit, with its spread.
            next.c = vec4<f32>(width, it.c.y, 0.0, it.c.w);
            if max3(kt_w) > F.e.x {
                if random {
                    next.m = vec4<u32>(it.m.x, it.m.y + 1u, seed_child(seed, 1u));
                }
                var t = refract_(s.dir, s.ns, lb.eta);
                if t.w == 0.0 {
                    t = refract_(s.dir, s.ng, lb.eta);
                }
                if t.w != 0.0 && dot(t.xyz, s.ng) < 0.0 {
                    // At the camera ray's hit the event names the pass (transmission).
                    next.w = vec4<f32>(kt_w, f32(bounces + 512u * select(path, 3u, path == 0u)));
                    nx_cand_r[i * NEXT_SLOTS + nnx] = make_ray(s.point - s.ng * eps, t.xyz, 0.0, inf());
                    nx_cand_i[i * NEXT_SLOTS + nnx] = next;
                    nnx = nnx + 1u;
                } else {
                    kr = kr + lb.kt;
                }
            }
            let kr_w = weight * kr;
            if random {
                next.m = vec4<u32>(it.m.x, it.m.y + 1u, seed_child(seed, 0u));
            }
            if max3(kr_w) > F.e.x && m.reflects == 1u {
                var rd = reflect_(s.dir, s.ns);
                if dot(rd, s.ng) <= 0.0 {
                    rd = reflect_(s.dir, s.ng);
                }
                next.w = vec4<f32>(kr_w, f32(bounces + 512u * select(path, 2u, path == 0u)));
                nx_cand_r[i * NEXT_SLOTS + nnx] = make_ray(origin, rd, 0.0, inf());
                nx_cand_i[i * NEXT_SLOTS + nnx] = next;
                nnx = nnx + 1u;
            } else if max3(kr_w) > F.e.x && m.reflects == 2u {
                // One direction from the visible normals: the weight is F · G1(l)
                // (Purpose::Glossy is 1).
                let alpha = m.roughness * m.roughness;
                let mh = sample_ggx_vndf(lb.v, s.ns, alpha, seed_get(seed, 1u, 0u));
                let rd = reflect_(s.dir, mh);
                let cos_l = dot(rd, s.ns);
                if cos_l > 0.0 && dot(rd, s.ng) > 0.0 {
                    let w = kr_w * smith_g1(cos_l, alpha);
                    if max3(w) > F.e.x {
                        next.w = vec4<f32>(w, f32(bounces + 512u * select(path, 2u, path == 0u)));
                        // The lobe's width widens the cone.
                        next.c = vec4<f32>(width, it.c.y + alpha, 0.0, it.c.w);
                        nx_cand_r[i * NEXT_SLOTS + nnx] = make_ray(origin, rd, 0.0, inf());
                        nx_cand_i[i * NEXT_SLOTS + nnx] = next;
                        nnx = nnx + 1u;
                    }
                }
            }
        }
    }
    finish(i, first, smp, add, split, cover, nsh, nnx);
}

// What item `i` hands on: its own light and coverage (`accum` adds them), its counts.
// `smp`: its sample; `split_in`: its own light split over the light-path passes.
fn finish(
    i: u32,
    first: bool,
    smp: u32,
    add_in: vec3<f32>,
    split_in: array<vec3<f32>, 4>,
    cover: f32,
    nsh: u32,
    nnx: u32,
) {
    var add = add_in;
    var split = split_in;
    // `BlockOut::add_split` keeps only nonzero, finite terms.
    if is_zero3(add) || !finite3(add) {
        add = vec3<f32>(0.0);
        split = array<vec3<f32>, 4>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    }
    local[i] = vec4<f32>(add, cover);
    if light_paths() {
        for (var k = 0u; k < 4u; k = k + 1u) {
            local[split_at(i, k)] = vec4<f32>(split[k], 0.0);
        }
    }
    if first {
        // Each sample's sums start at 0 (its coverage too: `accum` adds the items'
        // coverage terms).
        radiance[smp] = vec4<f32>(0.0);
        if light_paths() {
            let base = F.b.z * F.b.w + smp * 4u;
            for (var k = 0u; k < 4u; k = k + 1u) {
                radiance[base + k] = vec4<f32>(0.0);
            }
        }
    }
    sh_count[i] = nsh;
    nx_count[i] = nnx;
}

// The candidates moved to their places: the prefix sums of the counts.
@compute @workgroup_size(64)
fn compact(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = grid_index(gid);
    if i >= F.a.x {
        return;
    }
    let nl = slots();
    // Past the capacities nothing is written: `next_level` flags the overflow and the
    // host traces the chunk again with more room.
    let a = sh_start[i];
    for (var k = 0u; k < sh_count[i]; k = k + 1u) {
        if a + k < F.g.z {
            let c = sh_cand[i * nl + k];
            sh_rays[a + k] = c.r;
            sh_add[a + k] = c.c;
            if light_paths() {
                let at = split_at(i, 4u + 2u * k);
                sh_add[F.g.z + 2u * (a + k)] = local[at];
                sh_add[F.g.z + 2u * (a + k) + 1u] = local[at + 1u];
            }
        }
    }
    let b = nx_start[i];
    for (var k = 0u; k < nx_count[i]; k = k + 1u) {
        if b + k < F.g.y {
            nx_rays[b + k] = nx_cand_r[i * NEXT_SLOTS + k];
            nx_items[b + k] = nx_cand_i[i * NEXT_SLOTS + k];
        }
    }
}

// One invocation: the level's totals (the scans' last sums), the uniforms of the
// shadow rays' any hits and of the next level (its items and their closest hits), made
// from the templates with the counts, clamped to the capacities (an overflow is
// flagged), and the frame's totals.
// Workgroups (x, y, 1) of 64 for `n` invocations on a grid `x_cap` wide (the width
// the row stride in the uniform was made for).
fn groups(at: u32, n: u32, x_cap: u32) {
    let g = (n + 63u) / 64u;
    made[at] = min(g, x_cap);
    made[at + 1u] = (g + x_cap - 1u) / x_cap;
    made[at + 2u] = 1u;
}

@compute @workgroup_size(1)
fn next_level() {
    let cap = F.g.y;
    let ns = sh_start[F.a.x];
    let nn = nx_start[F.a.x];
    var over = 0u;
    var ns2 = ns;
    if ns > F.g.z {
        ns2 = F.g.z;
        over = 1u;
    }
    var nn2 = nn;
    if nn > cap {
        nn2 = cap;
        over = 1u;
    }
    totals[0] = totals[0] | over;
    totals[1] = totals[1] + ns2;
    totals[2] = totals[2] + nn2;
    for (var w = 0u; w < 108u; w = w + 1u) {
        made[w] = templates[w];
    }
    made[0] = nn2;
    // Not the camera rays' level.
    made[2] = 0u;
    made[28] = nn2;
    made[68] = ns2;
    groups(108u, nn2, F.h.x);
    groups(111u, nn2, F.h.y);
    groups(114u, ns2, F.h.z);
}

// A run of items of one sample, added to it in the CPU's order: the items' own terms,
// then light by light the unblocked shadow rays, in item order.
@compute @workgroup_size(64)
fn accum(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = grid_index(gid);
    let n = F.a.x;
    if i >= n {
        return;
    }
    let s = sample_of(i);
    if i > 0u && sample_of(i - 1u) == s {
        return;
    }
    var e = i + 1u;
    while e < n && sample_of(e) == s {
        e = e + 1u;
    }
    let old = radiance[s];
    var acc = old.xyz;
    // The coverage terms in item order, as `coverage[sample]` sums `BlockOut::cover`'s
    // (a zero term adds nothing: the CPU pushes none).
    var cov = old.w;
    // The passes: each a sum of its own terms in the same order (`paths[sample]`).
    let lp = light_paths();
    let pbase = F.b.z * F.b.w + s * 4u;
    var pacc: array<vec3<f32>, 4>;
    if lp {
        for (var q = 0u; q < 4u; q = q + 1u) {
            pacc[q] = radiance[pbase + q].xyz;
        }
    }
    for (var j = i; j < e; j = j + 1u) {
        acc = acc + local[j].xyz;
        cov = cov + local[j].w;
        if lp {
            for (var q = 0u; q < 4u; q = q + 1u) {
                pacc[q] = pacc[q] + local[split_at(j, q)].xyz;
            }
        }
    }
    for (var l = 0u; l < batches(); l = l + 1u) {
        for (var j = i; j < e; j = j + 1u) {
            for (var k = sh_start[j]; k < sh_start[j + 1u]; k = k + 1u) {
                let a = sh_add[k];
                if u32(a.w) == l && sh_hits[k].y == NONE {
                    acc = acc + a.xyz;
                    if lp {
                        // `split_light`: at a camera ray's hit the diffuse lobe's part
                        // is diffuse and the glint's specular (the other two add 0);
                        // deeper, both go to the path's pass.
                        let d = sh_add[F.g.z + 2u * k];
                        let g = sh_add[F.g.z + 2u * k + 1u].xyz;
                        let path = u32(d.w);
                        if path == 0u {
                            pacc[0] = pacc[0] + d.xyz;
                            pacc[1] = pacc[1] + g;
                        } else {
                            pacc[path - 1u] = pacc[path - 1u] + (d.xyz + g);
                        }
                    }
                }
            }
        }
    }
    radiance[s] = vec4<f32>(acc, cov);
    if lp {
        for (var q = 0u; q < 4u; q = q + 1u) {
            radiance[pbase + q] = vec4<f32>(pacc[q], 0.0);
        }
    }
}

// Each pixel's samples summed in order and averaged, as `trace_pass` does.
@compute @workgroup_size(64)
fn pixels(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = grid_index(gid);
    if p >= F.b.z {
        return;
    }
    let spp = F.b.w;
    var c = vec3<f32>(0.0);
    var a = 0.0;
    for (var s = p * spp; s < (p + 1u) * spp; s = s + 1u) {
        let r = radiance[s];
        c = c + r.xyz;
        a = a + r.w;
    }
    let inv = F.d.w;
    if F.a.z != 0u {
        // A blurred frame's step: the sums (1 / spp applied later, and the clamp).
        rgba[p] = vec4<f32>(c * inv, a * inv);
    } else {
        rgba[p] = vec4<f32>(c * inv, min(a * inv, 1.0));
    }
    // The light-path passes (F.a.w 1), each averaged (or summed) as the beauty is.
    if F.a.w != 0u {
        let base = F.b.z * spp;
        for (var q = 0u; q < 4u; q = q + 1u) {
            var pc = vec3<f32>(0.0);
            for (var s = p * spp; s < (p + 1u) * spp; s = s + 1u) {
                pc = pc + radiance[base + s * 4u + q].xyz;
            }
            rgba[F.b.z + p * 4u + q] = vec4<f32>(pc * inv, 0.0);
        }
    }
}

// Sample s of the chunk: its camera pixel (x, y, wrapping in the overscan border as the
// seeds take it) and its number k in the pixel. Sample s is sample s % spp of the
// chunk's pixel s / spp (the samples of a pixel, the pixels of a row, the rows), as
// `trace_pass` walks them.
fn camera_sample(s: u32) -> vec3<u32> {
    let spp = max(C.a.w, 1u);
    let p = C.c.x + s / spp;
    let w = C.b.w;
    return vec3<u32>((p % w) - C.b.z, (p / w) - C.b.z, s % spp);
}

// The chunk's camera rays: sample s is sample s % spp of the chunk's pixel s / spp (the
// samples of a pixel, the pixels of a row, the rows), as `trace_pass` makes them.
@compute @workgroup_size(64)
fn camera(@builtin(global_invocation_id) gid: vec3<u32>) {
    let s = grid_index(gid);
    if s >= F.a.x {
        return;
    }
    let p = camera_sample(sample_of(s));
    let off = sample_offset(p.x, p.y, p.z);
    rays[s] = camera_ray(f32(bitcast<i32>(p.x)) + off.x, f32(bitcast<i32>(p.y)) + off.y);
}

// For the tests: each ray's origin, direction and span remade here, with its shear.
@compute @workgroup_size(64)
fn shear_test(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = grid_index(gid);
    if i >= F.a.x {
        return;
    }
    let r = rays[i];
    rays[i] = make_ray(r.o.xyz, r.d.xyz, r.o.w, r.d.w);
}
