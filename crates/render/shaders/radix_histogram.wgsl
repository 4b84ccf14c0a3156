// radix_histogram: per workgroup block, how many keys have each 8-bit digit at
// `shift`. Written digit-major (digit * blocks + block) so one exclusive scan
// gives every block's first output slot per digit. Only the first `live` keys
// count: a sort's length may be known only on the GPU (the tile entries).

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read_write> counts: array<u32>;
@group(0) @binding(3) var<storage, read> live: array<u32>;

var<workgroup> histogram: array<atomic<u32>, DIGITS>;

@compute @workgroup_size(GROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    atomicStore(&histogram[t], 0u);
    workgroupBarrier();
    let base = group.x * SORT_BLOCK;
    let count = min(params.count, live[0]);
    for (var k = 0u; k < SORT_ITEMS; k++) {
        let i = base + k * GROUP + t;
        if (i < count) {
            atomicAdd(&histogram[(keys[i] >> params.shift) & (DIGITS - 1u)], 1u);
        }
    }
    workgroupBarrier();
    counts[t * params.blocks + group.x] = atomicLoad(&histogram[t]);
}
