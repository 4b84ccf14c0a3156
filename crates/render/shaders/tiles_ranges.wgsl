// tiles_ranges: where each tile's run starts and ends in the tile-sorted entries
// (tiles without entries keep the [0, 0] the buffer was cleared to). The entries
// are the first `live` of the room the dispatch covers.

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> tile_keys: array<u32>;
@group(0) @binding(2) var<storage, read_write> ranges: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read> live: array<u32>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let p = element_index(id, groups);
    let count = min(params.count, live[0]);
    if (p >= count) {
        return;
    }
    let t = tile_keys[p];
    if (p == 0u || tile_keys[p - 1u] != t) {
        ranges[t].x = p;
    }
    if (p + 1u == count || tile_keys[p + 1u] != t) {
        ranges[t].y = p + 1u;
    }
}
