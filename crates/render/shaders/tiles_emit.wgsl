// tiles_emit: one (tile, Gaussian) entry per touched tile, written in depth order;
// a stable sort by tile then gives every tile its Gaussians front to back. Entries
// past the room planned for them (`limit`) are dropped: the frame is then binned
// again with more room (src/render/gpu/binning.rs).

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> order: array<u32>;
@group(0) @binding(3) var<storage, read> starts: array<u32>;
@group(0) @binding(4) var<storage, read_write> tile_keys: array<u32>;
@group(0) @binding(5) var<storage, read_write> tile_values: array<u32>;
// How many of the room's Gaussians there are (the rest of the room is unused).
@group(0) @binding(6) var<storage, read> live: array<u32>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let s = element_index(id, groups);
    if (s >= min(params.count, live[0])) {
        return;
    }
    let i = order[s];
    let k = keys[i];
    if (k.w == 0u) {
        return;
    }
    let r = key_tiles(k, params.tiles);
    var at = starts[s];
    for (var ty = r.y; ty <= r.w; ty++) {
        for (var tx = r.x; tx <= r.z; tx++) {
            if (at < params.limit) {
                tile_keys[at] = ty * params.tiles.x + tx;
                tile_values[at] = i;
            }
            at++;
        }
    }
}
