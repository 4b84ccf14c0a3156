// scan_apply: last step of the prefix sum: each block scans its elements in
// place (exclusive) and adds the block's offset.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read> sums: array<u32>;

var<workgroup> partial: array<u32, GROUP>;

@compute @workgroup_size(GROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let base = group.x * SORT_BLOCK + t * SORT_ITEMS;
    var values: array<u32, 4>;
    var s = 0u;
    for (var k = 0u; k < SORT_ITEMS; k++) {
        var v = 0u;
        if (base + k < params.count) {
            v = data[base + k];
        }
        values[k] = v;
        s += v;
    }
    partial[t] = s;
    workgroupBarrier();
    // Hillis-Steele inclusive scan of the per-invocation sums.
    for (var stride = 1u; stride < GROUP; stride <<= 1u) {
        var add = 0u;
        if (t >= stride) {
            add = partial[t - stride];
        }
        workgroupBarrier();
        partial[t] += add;
        workgroupBarrier();
    }
    var running = sums[group.x] + partial[t] - s;
    for (var k = 0u; k < SORT_ITEMS; k++) {
        if (base + k < params.count) {
            data[base + k] = running;
        }
        running += values[k];
    }
}
