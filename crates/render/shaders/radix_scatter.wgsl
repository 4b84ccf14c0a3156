// radix_scatter: a stable scatter of one 8-bit digit. Each workgroup walks its
// block in order, 256 keys at a time; a key's rank among the equal digits before
// it comes from a 256-bit mask per digit (bit = invocation), so equal keys keep
// their order and the result is the same on every run and device. Only the first
// `live` keys move (as in radix_histogram).

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> values_in: array<u32>;
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> values_out: array<u32>;
@group(0) @binding(6) var<storage, read> live: array<u32>;

var<workgroup> masks: array<atomic<u32>, 2048>;  // DIGITS x 8 words of GROUP bits
var<workgroup> next_slot: array<u32, DIGITS>;

@compute @workgroup_size(GROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    next_slot[t] = offsets[t * params.blocks + group.x];
    let word = t / 32u;
    let below = (1u << (t % 32u)) - 1u;
    let base = group.x * SORT_BLOCK;
    let count = min(params.count, live[0]);
    for (var k = 0u; k < SORT_ITEMS; k++) {
        for (var w = 0u; w < 8u; w++) {
            atomicStore(&masks[t * 8u + w], 0u);
        }
        workgroupBarrier();
        let i = base + k * GROUP + t;
        let valid = i < count;
        var key = 0u;
        var digit = 0u;
        if (valid) {
            key = keys_in[i];
            digit = (key >> params.shift) & (DIGITS - 1u);
            atomicOr(&masks[digit * 8u + word], 1u << (t % 32u));
        }
        workgroupBarrier();
        if (valid) {
            var rank = countOneBits(atomicLoad(&masks[digit * 8u + word]) & below);
            for (var w = 0u; w < word; w++) {
                rank += countOneBits(atomicLoad(&masks[digit * 8u + w]));
            }
            let slot = next_slot[digit] + rank;
            keys_out[slot] = key;
            values_out[slot] = values_in[i];
        }
        workgroupBarrier();
        var total = 0u;
        for (var w = 0u; w < 8u; w++) {
            total += countOneBits(atomicLoad(&masks[t * 8u + w]));
        }
        next_slot[t] += total;
        workgroupBarrier();
    }
}
