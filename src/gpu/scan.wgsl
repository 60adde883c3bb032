// An exclusive prefix sum of u32, 256 values a workgroup: `scan` writes each block's
// exclusive sums and the block's total; the host scans the totals the same way (one level
// up) and `add` adds each block's offset back. Hillis-Steele within a workgroup.
//
// `plan` sizes a scan whose length the GPU decides (the frame path's levels, scan.rs
// `ScanPlan`): the scan and add passes then read their lengths from uniforms and their
// workgroups from an indirect buffer that it writes.

struct ScanParams {
    // elements, row stride in invocations; for `plan`: the capacity (elements), the
    // word of `src` that holds the count, what is added to it
    n: vec4<u32>,
}

@group(0) @binding(0) var<uniform> S: ScanParams;
@group(0) @binding(1) var<storage, read> src: array<u32>;
@group(0) @binding(2) var<storage, read_write> dst: array<u32>;
@group(0) @binding(3) var<storage, read_write> sums: array<u32>;

var<workgroup> buf: array<u32, 256>;

@compute @workgroup_size(256)
fn scan(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let i = gid.y * S.n.y + gid.x;
    var x = 0u;
    if i < S.n.x {
        x = src[i];
    }
    buf[li] = x;
    workgroupBarrier();
    for (var off = 1u; off < 256u; off = off * 2u) {
        var y = 0u;
        if li >= off {
            y = buf[li - off];
        }
        workgroupBarrier();
        buf[li] = buf[li] + y;
        workgroupBarrier();
    }
    if i < S.n.x {
        dst[i] = buf[li] - x;
    }
    if li == 255u {
        sums[wid.y * nwg.x + wid.x] = buf[255];
    }
}

@compute @workgroup_size(256)
fn add(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let i = gid.y * S.n.y + gid.x;
    if i < S.n.x {
        dst[i] = dst[i] + sums[wid.y * nwg.x + wid.x];
    }
}

// One invocation: the live length `src[S.n.z] + S.n.w` (at most the capacity `S.n.x`)
// and, for each of four levels of blocks, words 4j..4j+3 of `dst`: the level's uniform
// (its length, the row stride of the grid over the level's capacity, as the host's
// `GpuDevice::grid_of` makes it), and words 16 + 6j..: the workgroups of the level's
// scan pass, then of its add pass. A level of one block adds nothing (its one offset is
// 0): it has no add pass and the levels above it scan nothing.
@compute @workgroup_size(1)
fn plan() {
    var cap = S.n.x;
    var m = min(src[S.n.z] + S.n.w, cap);
    for (var j = 0u; j < 4u; j = j + 1u) {
        let gcap = max((cap + 255u) / 256u, 1u);
        let xcap = min(gcap, 32768u);
        dst[4u * j] = m;
        dst[4u * j + 1u] = xcap * 256u;
        dst[4u * j + 2u] = 0u;
        dst[4u * j + 3u] = 0u;
        let g = (m + 255u) / 256u;
        let x = min(g, xcap);
        let y = (g + xcap - 1u) / xcap;
        let at = 16u + 6u * j;
        dst[at] = x;
        dst[at + 1u] = y;
        dst[at + 2u] = 1u;
        var more = 0u;
        if m > 256u {
            more = 1u;
        }
        dst[at + 3u] = x * more;
        dst[at + 4u] = y * more;
        dst[at + 5u] = 1u;
        m = g * more;
        cap = gcap;
    }
}
