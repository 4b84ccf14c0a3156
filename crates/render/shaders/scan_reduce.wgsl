// scan_reduce: first step of an exclusive prefix sum over `data`: the sum of each
// block of SORT_BLOCK elements.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> sums: array<u32>;

var<workgroup> partial: array<u32, GROUP>;

@compute @workgroup_size(GROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let base = group.x * SORT_BLOCK + t * SORT_ITEMS;
    var s = 0u;
    for (var k = 0u; k < SORT_ITEMS; k++) {
        if (base + k < params.count) {
            s += data[base + k];
        }
    }
    partial[t] = s;
    workgroupBarrier();
    for (var stride = 128u; stride > 0u; stride >>= 1u) {
        if (t < stride) {
            partial[t] += partial[t + stride];
        }
        workgroupBarrier();
    }
    if (t == 0u) {
        sums[group.x] = partial[0];
    }
}
