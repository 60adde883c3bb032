// An exclusive prefix sum of u32, 256 values a workgroup: `scan` writes each block's
// exclusive sums and the block's total; the host scans the totals the same way (one level
// up) and `add` adds each block's offset back. Hillis-Steele within a workgroup.

struct ScanParams {
    // elements, row stride in invocations
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
