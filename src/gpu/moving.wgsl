// The moving triangles' grid, built on the GPU each frame: a count, a prefix scan, a
// scatter (Kalojanov and Slusallek, "A parallel algorithm for construction of uniform
// grids", 2009). A triangle is listed in every cell its box, grown by the moving margin,
// overlaps. The cell range is computed here, in the count and again in the scatter, by
// the same f64 arithmetic, so both passes agree on it.

struct GridParams {
    // origin (xyz), cell side (w)
    g_lo: vec4<f32>,
    // cells along x, y, z; triangles
    dims: vec4<u32>,
    // the margin (x); row stride in invocations (bits of y); elements to scan (bits of z)
    m: vec4<f32>,
}

@group(0) @binding(0) var<uniform> G: GridParams;
@group(0) @binding(1) var<storage, read> mtris: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read> cell_start: array<u32>;
@group(0) @binding(4) var<storage, read_write> cell_tris: array<u32>;

fn index_of(gid: vec3<u32>) -> u32 {
    return gid.y * bitcast<u32>(G.m.y) + gid.x;
}

struct Range {
    lo: vec3<u32>,
    hi: vec3<u32>,
}

// The cells the triangle's grown box overlaps, clamped to the grid.
fn cells_of(i: u32) -> Range {
    let a = mtris[3u * i].xyz;
    let b = mtris[3u * i + 1u].xyz;
    let c = mtris[3u * i + 2u].xyz;
    let m = f64(G.m.x);
    let g = vec3<f64>(G.g_lo.xyz);
    let inv = 1.0lf / f64(G.g_lo.w);
    let lo = (vec3<f64>(min(min(a, b), c)) - m - g) * inv;
    let hi = (vec3<f64>(max(max(a, b), c)) + m - g) * inv;
    let top = vec3<f64>(G.dims.xyz - vec3<u32>(1u));
    let zero = vec3<f64>(0.0lf);
    return Range(vec3<u32>(clamp(lo, zero, top)), vec3<u32>(clamp(hi, zero, top)));
}

@compute @workgroup_size(64)
fn count(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = index_of(gid);
    if i >= G.dims.w {
        return;
    }
    let r = cells_of(i);
    for (var z = r.lo.z; z <= r.hi.z; z++) {
        for (var y = r.lo.y; y <= r.hi.y; y++) {
            for (var x = r.lo.x; x <= r.hi.x; x++) {
                atomicAdd(&counts[(z * G.dims.y + y) * G.dims.x + x], 1u);
            }
        }
    }
}

// `counts` is the scatter's cursor here, cleared to zero after the scan.
@compute @workgroup_size(64)
fn scatter(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = index_of(gid);
    if i >= G.dims.w {
        return;
    }
    let r = cells_of(i);
    for (var z = r.lo.z; z <= r.hi.z; z++) {
        for (var y = r.lo.y; y <= r.hi.y; y++) {
            for (var x = r.lo.x; x <= r.hi.x; x++) {
                let c = (z * G.dims.y + y) * G.dims.x + x;
                let k = atomicAdd(&counts[c], 1u);
                cell_tris[cell_start[c] + k] = i;
            }
        }
    }
}
