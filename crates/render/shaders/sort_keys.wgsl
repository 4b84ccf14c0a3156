// sort_keys: the depth sort's input. Value = Gaussian index in index order (so the
// stable radix sort keeps ties in index order, as the CPU renderer does); key = the
// depth's f32 bits (positive floats order like their bits), culled Gaussians last.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> sort_keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> sort_values: array<u32>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = element_index(id, groups);
    if (i >= params.count) {
        return;
    }
    let k = keys[i];
    sort_keys[i] = select(0xffffffffu, k.x, k.w != 0u);
    sort_values[i] = i;
}
