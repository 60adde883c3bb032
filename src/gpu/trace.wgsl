// Closest hit and any hit of a batch of rays over the static subfields and the moving
// grid together: one invocation a ray. The CPU's query (src/psf/traverse.rs and
// src/psf/dynamic/layered.rs), step for step, so the hits are the CPU's to the bit; see
// docs/GPU.md for why each number below is exact or, where it only steers the walk,
// safely conservative.
//
// Exactness rules of this file:
// * The triangle test runs in f32 with the CPU's operations in the CPU's order. Vulkan
//   rounds f32 +, -, * correctly, but a compiler may fuse a product into the add after it
//   (SPIR-V allows contraction unless an op is marked NoContraction, which naga does not
//   emit). Every product that feeds an add therefore passes `nc`, an xor with a zero the
//   compiler cannot see (a uniform): the add then reads an integer op's result, and
//   nothing can be fused.
// * The one division of the test (1 / det) is done in f64 and rounded to f32: f64 has
//   more than 2·24 + 2 bits, so rounding twice gives the correctly rounded f32 quotient
//   (Figueroa), and even a quotient off by a few f64 ulps rounds to it (1/det lies at
//   least 2^-48 relative from any f32 midpoint). Vulkan's f32 division is only 2.5 ulp.
// * The ray's shear divisions come from the CPU with the ray (geometry::Shear).
// * The walk (clipping, the 2D DDA, the 3D DDA, depth windows) runs in f64 as on the
//   CPU; it only chooses which triangles are tested, and every window it computes is
//   wider than the rounding it could differ by (the margin is ~80 f32 ulps of the scene).

struct Params {
    // n_rays, subfields, table res, the zero of `nc`
    a: vec4<u32>,
    // 1 for any hit, moving triangles, static triangles, row stride (invocations)
    b: vec4<u32>,
    // the static clip box; clip_lo.w = the static margin
    clip_lo: vec4<f32>,
    clip_hi: vec4<f32>,
    // moving grid: origin (xyz), cell side (w)
    g_lo: vec4<f32>,
    // moving grid cells along x, y, z
    g_dims: vec4<u32>,
    // the moving clip box; m_lo.w = the moving margin
    m_lo: vec4<f32>,
    m_hi: vec4<f32>,
    // log2 of the elements a binding of each split array holds (static_part.rs):
    // triangles' vec4s, tile headers, slab starts, entries; then blocks
    k: vec4<u32>,
    k2: vec4<u32>,
}

struct Ray {
    // origin, t_min
    o: vec4<f32>,
    // direction, t_max
    d: vec4<f32>,
    // shear sx, sy, sz; w: bits of kx | ky << 2 | kz << 4 | valid << 8
    s: vec4<f32>,
}

struct SubMeta {
    // direction (xyz), u0
    d: vec4<f32>,
    // u axis, v0
    u: vec4<f32>,
    // v axis, inv_tile
    v: vec4<f32>,
    // nu, nv, first tile, first slab start
    n: vec4<u32>,
    // first entry, first block
    m: vec4<u32>,
}

struct Entry {
    tri: u32,
    zmin: f32,
    zmax: f32,
}

struct Block {
    zmin: array<f32, 8>,
    zmax: array<f32, 8>,
    tri: array<u32, 8>,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> rays: array<Ray>;
@group(0) @binding(2) var<storage, read_write> hits: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> stris: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> subs: array<SubMeta>;
@group(0) @binding(5) var<storage, read> tiles: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> starts: array<u32>;
@group(0) @binding(7) var<storage, read> entries: array<Entry>;
@group(0) @binding(8) var<storage, read> blocks: array<Block>;
@group(0) @binding(9) var<storage, read> table: array<u32>;
@group(0) @binding(10) var<storage, read> mtris: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read> cell_start: array<u32>;
@group(0) @binding(12) var<storage, read> cell_tris: array<u32>;
// The rest of the split arrays (static_part.rs, CHUNKS = 4): element i of an array is
// element i & (2^k - 1) of its binding i >> k.
@group(0) @binding(13) var<storage, read> stris1: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read> stris2: array<vec4<f32>>;
@group(0) @binding(15) var<storage, read> stris3: array<vec4<f32>>;
@group(0) @binding(16) var<storage, read> tiles1: array<vec4<u32>>;
@group(0) @binding(17) var<storage, read> tiles2: array<vec4<u32>>;
@group(0) @binding(18) var<storage, read> tiles3: array<vec4<u32>>;
@group(0) @binding(19) var<storage, read> starts1: array<u32>;
@group(0) @binding(20) var<storage, read> starts2: array<u32>;
@group(0) @binding(21) var<storage, read> starts3: array<u32>;
@group(0) @binding(22) var<storage, read> entries1: array<Entry>;
@group(0) @binding(23) var<storage, read> entries2: array<Entry>;
@group(0) @binding(24) var<storage, read> entries3: array<Entry>;
@group(0) @binding(25) var<storage, read> blocks1: array<Block>;
@group(0) @binding(26) var<storage, read> blocks2: array<Block>;
@group(0) @binding(27) var<storage, read> blocks3: array<Block>;

fn low(i: u32, k: u32) -> u32 {
    return i & ((1u << k) - 1u);
}

fn stri(i: u32) -> vec4<f32> {
    let j = low(i, P.k.x);
    switch i >> P.k.x {
        case 0u: { return stris[j]; }
        case 1u: { return stris1[j]; }
        case 2u: { return stris2[j]; }
        default: { return stris3[j]; }
    }
}

fn tile_at(i: u32) -> vec4<u32> {
    let j = low(i, P.k.y);
    switch i >> P.k.y {
        case 0u: { return tiles[j]; }
        case 1u: { return tiles1[j]; }
        case 2u: { return tiles2[j]; }
        default: { return tiles3[j]; }
    }
}

fn start_at(i: u32) -> u32 {
    let j = low(i, P.k.z);
    switch i >> P.k.z {
        case 0u: { return starts[j]; }
        case 1u: { return starts1[j]; }
        case 2u: { return starts2[j]; }
        default: { return starts3[j]; }
    }
}

fn entry_at(i: u32) -> Entry {
    let j = low(i, P.k.w);
    switch i >> P.k.w {
        case 0u: { return entries[j]; }
        case 1u: { return entries1[j]; }
        case 2u: { return entries2[j]; }
        default: { return entries3[j]; }
    }
}

// Slot s of block i: its depth range, then its triangle.
fn block_z(i: u32, s: u32) -> vec2<f32> {
    let j = low(i, P.k2.x);
    switch i >> P.k2.x {
        case 0u: { return vec2<f32>(blocks[j].zmin[s], blocks[j].zmax[s]); }
        case 1u: { return vec2<f32>(blocks1[j].zmin[s], blocks1[j].zmax[s]); }
        case 2u: { return vec2<f32>(blocks2[j].zmin[s], blocks2[j].zmax[s]); }
        default: { return vec2<f32>(blocks3[j].zmin[s], blocks3[j].zmax[s]); }
    }
}

fn block_tri(i: u32, s: u32) -> u32 {
    let j = low(i, P.k2.x);
    switch i >> P.k2.x {
        case 0u: { return blocks[j].tri[s]; }
        case 1u: { return blocks1[j].tri[s]; }
        case 2u: { return blocks2[j].tri[s]; }
        default: { return blocks3[j].tri[s]; }
    }
}

const NONE: u32 = 0xffffffffu;
const FLAT: u32 = 0x80000000u;
// "Never" for a DDA axis the ray does not cross; every walk ends at a finite t1.
const NEVER: f64 = 1e300lf;

// A product that must not be fused into the add that follows (see the top).
fn nc(x: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(x) ^ P.a.w);
}

fn nc3(x: vec3<f32>) -> vec3<f32> {
    return bitcast<vec3<f32>>(bitcast<vec3<u32>>(x) ^ vec3<u32>(P.a.w));
}

fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn is_nan(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u;
}

struct Best {
    t: f32,
    tri: u32,
    u: f32,
    v: f32,
}

struct Pre {
    org: vec3<f32>,
    c0: vec3<f32>,
    c1: vec3<f32>,
    c2: vec3<f32>,
}

// The shear matrix by columns, as RayPre::new builds it: column kx (1,0,0), ky (0,1,0),
// kz (-sx, -sy, sz).
fn make_pre(r: Ray) -> Pre {
    let k = bitcast<u32>(r.s.w);
    let kx = k & 3u;
    let ky = (k >> 2u) & 3u;
    let kz = (k >> 4u) & 3u;
    var cols: array<vec3<f32>, 3>;
    cols[kx] = vec3<f32>(1.0, 0.0, 0.0);
    cols[ky] = vec3<f32>(0.0, 1.0, 0.0);
    cols[kz] = vec3<f32>(-r.s.x, -r.s.y, r.s.z);
    return Pre(r.o.xyz, cols[0], cols[1], cols[2]);
}

// glam's Mat3A * Vec3A: ((c0 x + c1 y) + c2 z), lane by lane.
fn shear(pre: Pre, p: vec3<f32>) -> vec3<f32> {
    let q = p - pre.org;
    var r = nc3(pre.c0 * q.x);
    r = r + nc3(pre.c1 * q.y);
    r = r + nc3(pre.c2 * q.z);
    return r;
}

// geometry::intersect_triangle: the watertight test, (t, u, v) in `best` form with tri
// NONE on a miss. `degenerate` is the CPU's is_degenerate, computed on the CPU.
fn test_tri(pre: Pre, base: u32, tris_static: bool, t_min: f32, t_max: f32) -> Best {
    let miss = Best(0.0, NONE, 0.0, 0.0);
    var v0: vec4<f32>;
    var v1: vec4<f32>;
    var v2: vec4<f32>;
    if tris_static {
        v0 = stri(base);
        v1 = stri(base + 1u);
        v2 = stri(base + 2u);
    } else {
        v0 = mtris[base];
        v1 = mtris[base + 1u];
        v2 = mtris[base + 2u];
    }
    if v0.w != 0.0 {
        return miss;
    }
    let a = shear(pre, v0.xyz);
    let b = shear(pre, v1.xyz);
    let c = shear(pre, v2.xyz);
    var u = nc(c.x * b.y) - nc(c.y * b.x);
    var v = nc(a.x * c.y) - nc(a.y * c.x);
    var w = nc(b.x * a.y) - nc(b.y * a.x);
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // The CPU recomputes all three in f64 (products of f32 are exact there).
        let ax = f64(a.x);
        let ay = f64(a.y);
        let bx = f64(b.x);
        let by = f64(b.y);
        let cx = f64(c.x);
        let cy = f64(c.y);
        u = f32(cx * by - cy * bx);
        v = f32(ax * cy - ay * cx);
        w = f32(bx * ay - by * ax);
    }
    let neg = u < 0.0 || v < 0.0 || w < 0.0;
    let pos = u > 0.0 || v > 0.0 || w > 0.0;
    if neg && pos {
        return miss;
    }
    let det = u + v + w;
    if det == 0.0 || !finite(det) {
        return miss;
    }
    let ts = nc(u * a.z) + nc(v * b.z) + nc(w * c.z);
    let inv = f32(1.0lf / f64(det));
    let t = ts * inv;
    if is_nan(t) || !(t >= t_min && t <= t_max) {
        return miss;
    }
    return Best(t, 0u, v * inv, w * inv);
}

fn closer(h: Best, b: Best) -> bool {
    return b.tri == NONE || h.t < b.t || (h.t == b.t && h.tri < b.tri);
}

// DirectionTable::lookup.
fn lookup(dir: vec3<f32>) -> u32 {
    let a = abs(dir);
    var face = 2u;
    if a.x >= a.y && a.x >= a.z {
        face = 0u;
    } else if a.y >= a.z {
        face = 1u;
    }
    let m = a[face];
    var sgn = 1.0;
    if dir[face] < 0.0 {
        sgn = -1.0;
    }
    let s = dir[(face + 1u) % 3u] * sgn / m;
    let t = dir[(face + 2u) % 3u] * sgn / m;
    let res = P.a.z;
    let r = f32(res);
    let top = f32(res - 1u);
    let i = u32(clamp((s + 1.0) * 0.5 * r, 0.0, top));
    let j = u32(clamp((t + 1.0) * 0.5 * r, 0.0, top));
    return table[(face * res + j) * res + i];
}

struct Span {
    o: vec3<f64>,
    d: vec3<f64>,
    t0: f64,
    t1: f64,
    ok: bool,
}

// clipped_span: the f64 line and the part of [t_min, t_max] inside the box. An axis the
// ray runs parallel to clips nothing (or everything, from outside the slab), which visits
// at least what the CPU visits.
fn clip(r: Ray, lo: vec3<f32>, hi: vec3<f32>, t_max: f32) -> Span {
    let o = vec3<f64>(r.o.xyz);
    let d = vec3<f64>(r.d.xyz);
    var t0 = f64(r.o.w);
    var t1 = f64(t_max);
    var out = Span(o, d, 0.0lf, 0.0lf, false);
    // Infinite bounds (the CPU's f64 infinities): an empty span when they face the wrong
    // way, else "no bound" (every span below is cut to the box's finite one).
    if !finite(t_max) {
        if t_max < 0.0 {
            return out;
        }
        t1 = NEVER;
    }
    if !finite(r.o.w) {
        if r.o.w > 0.0 {
            return out;
        }
        t0 = -NEVER;
    }
    for (var k = 0u; k < 3u; k++) {
        let l = f64(lo[k]);
        let h = f64(hi[k]);
        if d[k] == 0.0lf {
            if o[k] < l || o[k] > h {
                return out;
            }
            continue;
        }
        let inv = 1.0lf / d[k];
        let a = (l - o[k]) * inv;
        let b = (h - o[k]) * inv;
        t0 = max(t0, min(a, b));
        t1 = min(t1, max(a, b));
    }
    if !(t0 <= t1) {
        return out;
    }
    out.t0 = t0;
    out.t1 = t1;
    out.ok = true;
    return out;
}

fn step_of(b: f64) -> i32 {
    if b > 0.0lf {
        return 1;
    }
    if b < 0.0lf {
        return -1;
    }
    return 0;
}

// TileHeader::slab_of.
fn slab_of(h: vec4<u32>, z: f32) -> u32 {
    let x = (z - bitcast<f32>(h.z)) * bitcast<f32>(h.w);
    let s = u32(clamp(x, 0.0, 4294967040.0));
    return min(s, h.y - 1u);
}

// Psf::trace_pre: the static subfields.
fn trace_static(r: Ray, pre: Pre, any: bool) -> Best {
    var best = Best(0.0, NONE, 0.0, 0.0);
    if P.a.y == 0u {
        return best;
    }
    let sp = clip(r, P.clip_lo.xyz, P.clip_hi.xyz, r.d.w);
    if !sp.ok {
        return best;
    }
    let sf = subs[lookup(r.d.xyz)];
    let margin = P.clip_lo.w;
    // Psf's slack, from f32 lengths nudged the safe way (a larger slack only waits longer).
    let olen = f64(length(r.o.xyz)) * 1.000001lf;
    let dlen = f64(length(r.d.xyz)) * 0.999999lf;
    let slack = (f64(margin) + 1e-6lf * olen) / dlen;
    let fd = vec3<f64>(sf.d.xyz);
    let oz = dot(sp.o, fd);
    let dz = dot(sp.d, fd);
    let ascending = dz >= 0.0lf;

    // walk_tiles (Amanatides-Woo), in f64.
    let inv = f64(sf.v.w);
    let fu = vec3<f64>(sf.u.xyz);
    let fv = vec3<f64>(sf.v.xyz);
    let ax = (dot(sp.o, fu) - f64(sf.d.w)) * inv;
    let bx = dot(sp.d, fu) * inv;
    let ay = (dot(sp.o, fv) - f64(sf.u.w)) * inv;
    let by = dot(sp.d, fv) * inv;
    let nu = i32(sf.n.x);
    let nv = i32(sf.n.y);
    var ix = i32(clamp(ax + sp.t0 * bx, 0.0lf, f64(nu - 1)));
    var iy = i32(clamp(ay + sp.t0 * by, 0.0lf, f64(nv - 1)));
    let sx = step_of(bx);
    let sy = step_of(by);
    var tx = NEVER;
    var ty = NEVER;
    var dtx = 0.0lf;
    var dty = 0.0lf;
    if sx != 0 {
        tx = (f64(ix + select(0, 1, sx > 0)) - ax) / bx;
        dtx = abs(1.0lf / bx);
    }
    if sy != 0 {
        ty = (f64(iy + select(0, 1, sy > 0)) - ay) / by;
        dty = abs(1.0lf / by);
    }
    var t = sp.t0;
    let t1 = sp.t1;
    // A DDA crosses at most nu + nv tiles; the bound only guards the loop.
    for (var guard = 0; guard <= nu + nv + 2; guard++) {
        let t_exit = max(min(min(tx, ty), t1), t);
        let h = tile_at(sf.n.z + u32(iy * nu + ix));
        if h.y != 0u {
            if (h.y & FLAT) != 0u {
                // block_window: the depth window over the tile, cut at the best hit.
                var t_far = t_exit;
                if best.tri != NONE {
                    t_far = min(t_exit, f64(best.t) + slack);
                }
                let za = oz + t * dz;
                let zb = oz + t_far * dz;
                let lo = f32(min(za, zb)) - margin;
                let hi = f32(max(za, zb)) + margin;
                let first = sf.m.y + h.x;
                let count = h.y & ~FLAT;
                for (var bi = 0u; bi < count; bi++) {
                    for (var j = 0u; j < 8u; j++) {
                        let z = block_z(first + bi, j);
                        if !(z.y >= lo && z.x <= hi) {
                            continue;
                        }
                        let tri = block_tri(first + bi, j);
                        var tm = r.d.w;
                        if best.tri != NONE {
                            tm = best.t;
                        }
                        var hit = test_tri(pre, 3u * tri, true, r.o.w, tm);
                        if hit.tri == NONE {
                            continue;
                        }
                        hit.tri = tri;
                        if any {
                            return hit;
                        }
                        if closer(hit, best) {
                            best = hit;
                        }
                    }
                }
            } else {
                let za = oz + t * dz;
                let zb = oz + t_exit * dz;
                var lo = f32(min(za, zb)) - margin;
                var hi = f32(max(za, zb)) + margin;
                if best.tri != NONE {
                    let cut = f32(oz + (f64(best.t) + slack) * dz);
                    if ascending {
                        hi = min(hi, cut + margin);
                    } else {
                        lo = max(lo, cut - margin);
                    }
                }
                if lo <= hi {
                    let s_lo = i32(slab_of(h, lo));
                    let s_hi = i32(slab_of(h, hi));
                    var s = s_lo;
                    var s_end = s_hi;
                    var dir = 1;
                    if !ascending {
                        s = s_hi;
                        s_end = s_lo;
                        dir = -1;
                    }
                    let s_first = s;
                    while (s - s_end) * dir <= 0 {
                        let base = sf.n.w + h.x + u32(s);
                        let e0 = sf.m.x + start_at(base);
                        let e1 = sf.m.x + start_at(base + 1u);
                        for (var ei = e0; ei < e1; ei++) {
                            let e = entry_at(ei);
                            if e.zmax < lo || e.zmin > hi {
                                continue;
                            }
                            // Tested already in an earlier slab of this walk?
                            if s != s_first {
                                var z = e.zmax;
                                if ascending {
                                    z = e.zmin;
                                }
                                if i32(slab_of(h, z)) != s {
                                    continue;
                                }
                            }
                            var tm = r.d.w;
                            if best.tri != NONE {
                                tm = best.t;
                            }
                            var hit = test_tri(pre, 3u * e.tri, true, r.o.w, tm);
                            if hit.tri == NONE {
                                continue;
                            }
                            hit.tri = e.tri;
                            if any {
                                return hit;
                            }
                            if closer(hit, best) {
                                best = hit;
                                let cut = f32(oz + (f64(hit.t) + slack) * dz);
                                if ascending {
                                    hi = min(hi, cut + margin);
                                    s_end = i32(slab_of(h, hi));
                                } else {
                                    lo = max(lo, cut - margin);
                                    s_end = i32(slab_of(h, lo));
                                }
                            }
                        }
                        s += dir;
                    }
                }
            }
            // Every triangle hit before the tile's exit is listed in a tile walked so far.
            if best.tri != NONE && f64(best.t) + slack <= t_exit {
                return best;
            }
        }
        if t_exit >= t1 {
            return best;
        }
        t = t_exit;
        if tx <= ty {
            ix += sx;
            if ix < 0 || ix >= nu {
                return best;
            }
            tx += dtx;
        } else {
            iy += sy;
            if iy < 0 || iy >= nv {
                return best;
            }
            ty += dty;
        }
    }
    return best;
}

// The moving grid (src/gpu/moving.rs): cells visited near to far by a 3D DDA in f64,
// every triangle of a cell tested. A triangle is listed in every cell its box, grown by
// the moving margin, overlaps; the point at a reported hit's t lies within the rounding
// of the test (far below the margin) of its triangle, so the cell holding it is walked
// before the exit below.
fn trace_moving(r: Ray, pre: Pre, t_max: f32, any: bool) -> Best {
    var best = Best(0.0, NONE, 0.0, 0.0);
    if P.b.y == 0u {
        return best;
    }
    let sp = clip(r, P.m_lo.xyz, P.m_hi.xyz, t_max);
    if !sp.ok {
        return best;
    }
    let margin = P.m_lo.w;
    let olen = f64(length(r.o.xyz)) * 1.000001lf;
    let dlen = f64(length(r.d.xyz)) * 0.999999lf;
    let slack = (f64(margin) + 1e-6lf * olen) / dlen;
    let g = vec3<f64>(P.g_lo.xyz);
    let inv = 1.0lf / f64(P.g_lo.w);
    let a = (sp.o - g) * inv;
    let b = sp.d * inv;
    let n = vec3<i32>(P.g_dims.xyz);
    var cell: vec3<i32>;
    var st: vec3<i32>;
    var tn: vec3<f64>;
    var dt: vec3<f64>;
    for (var k = 0u; k < 3u; k++) {
        cell[k] = i32(clamp(a[k] + sp.t0 * b[k], 0.0lf, f64(n[k] - 1)));
        st[k] = step_of(b[k]);
        tn[k] = NEVER;
        dt[k] = 0.0lf;
        if st[k] != 0 {
            tn[k] = (f64(cell[k] + select(0, 1, st[k] > 0)) - a[k]) / b[k];
            dt[k] = abs(1.0lf / b[k]);
        }
    }
    var t = sp.t0;
    let t1 = sp.t1;
    for (var guard = 0; guard <= n.x + n.y + n.z + 3; guard++) {
        let t_exit = max(min(min(tn.x, tn.y), min(tn.z, t1)), t);
        let c = u32((cell.z * n.y + cell.y) * n.x + cell.x);
        let j1 = cell_start[c + 1u];
        for (var j = cell_start[c]; j < j1; j++) {
            let tri = cell_tris[j];
            var tm = t_max;
            if best.tri != NONE {
                tm = best.t;
            }
            var hit = test_tri(pre, 3u * tri, false, r.o.w, tm);
            if hit.tri == NONE {
                continue;
            }
            hit.tri = tri;
            if any {
                return hit;
            }
            if closer(hit, best) {
                best = hit;
            }
        }
        if best.tri != NONE && f64(best.t) + slack <= t_exit {
            return best;
        }
        if t_exit >= t1 {
            return best;
        }
        t = t_exit;
        var k = 2u;
        if tn.x <= tn.y && tn.x <= tn.z {
            k = 0u;
        } else if tn.y <= tn.z {
            k = 1u;
        }
        cell[k] += st[k];
        if cell[k] < 0 || cell[k] >= n[k] {
            return best;
        }
        tn[k] += dt[k];
    }
    return best;
}

@compute @workgroup_size(64)
fn trace(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * P.b.w + gid.x;
    if i >= P.a.x {
        return;
    }
    let r = rays[i];
    let any = P.b.x != 0u;
    var out = vec4<u32>(0u, NONE, 0u, 0u);
    if ((bitcast<u32>(r.s.w) >> 8u) & 1u) != 0u {
        let pre = make_pre(r);
        let s = trace_static(r, pre, any);
        var best = s;
        if !(any && s.tri != NONE) {
            // The moving walk stops at the static hit: a moving triangle at the same t
            // loses the tie (its number is larger).
            var tm = r.d.w;
            if s.tri != NONE {
                tm = s.t;
            }
            var m = trace_moving(r, pre, tm, any);
            if m.tri != NONE {
                m.tri = m.tri + P.b.z;
                if closer(m, best) {
                    best = m;
                }
            }
        }
        if best.tri != NONE {
            out = vec4<u32>(bitcast<u32>(best.t), best.tri, bitcast<u32>(best.u), bitcast<u32>(best.v));
        }
    }
    hits[i] = out;
}
