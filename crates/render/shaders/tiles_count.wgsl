// tiles_count: how many tiles each Gaussian touches, in depth order (0 when
// culled, and past the first `live` of the room the dispatch covers). Its
// exclusive prefix sum is where each one's tile entries start.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> order: array<u32>;
@group(0) @binding(3) var<storage, read_write> entries: array<u32>;
@group(0) @binding(4) var<storage, read> live: array<u32>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let s = element_index(id, groups);
    if (s >= params.count) {
        return;
    }
    if (s >= live[0]) {
        entries[s] = 0u;
        return;
    }
    let k = keys[order[s]];
    var n = 0u;
    if (k.w != 0u) {
        let r = key_tiles(k, params.tiles);
        n = (r.z - r.x + 1u) * (r.w - r.y + 1u);
    }
    entries[s] = n;
}
