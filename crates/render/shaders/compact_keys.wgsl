// compact_keys: the depth sort's input with the culled Gaussians left out
// (sort_keys keeps them, last): (depth bits, Gaussian index) of each kept one
// at its place among the kept ones, in index order, so the stable radix sort
// orders ties as sort_keys' input does. Those past the room planned for them
// (`limit`) are dropped: the frame is then binned again with more room.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> sort_keys: array<u32>;
@group(0) @binding(4) var<storage, read_write> sort_values: array<u32>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = element_index(id, groups);
    if (i >= params.count) {
        return;
    }
    let k = keys[i];
    if (k.w != 0u) {
        let at = offsets[i];
        if (at < params.limit) {
            sort_keys[at] = k.x;
            sort_values[at] = i;
        }
    }
}
