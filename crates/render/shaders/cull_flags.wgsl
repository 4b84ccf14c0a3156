// cull_flags: 1 for each Gaussian `project` kept, 0 for a culled one; their
// exclusive prefix sum is where `compact_keys` puts each kept one.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> flags: array<u32>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = element_index(id, groups);
    if (i >= params.count) {
        return;
    }
    flags[i] = select(0u, 1u, keys[i].w != 0u);
}
