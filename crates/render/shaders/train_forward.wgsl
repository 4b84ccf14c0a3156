// train_forward: the training rasteriser's forward pass (src/train/raster.rs in
// f32). One workgroup per 16x16 tile, one invocation per pixel, front to back
// with the transmittance stop. Besides the colour it keeps what the backward
// pass needs: the final transmittance and how many of the tile's entries the
// pixel walked.

@group(0) @binding(0) var<uniform> params: RasterParams;
@group(0) @binding(1) var<storage, read> splats: array<vec4<f32>>;
// Per tile: start and end in `tile_list`.
@group(0) @binding(2) var<storage, read> tile_ranges: array<vec2<u32>>;
// Splat indices, each tile's run in front-to-back order.
@group(0) @binding(3) var<storage, read> tile_list: array<u32>;
// Per pixel: the backdrop's colour (rgb) and the depth beyond which it hides
// splats (w; +inf hides none).
@group(0) @binding(4) var<storage, read> backdrop: array<vec4<f32>>;
// Per pixel: colour over the backdrop (rgb) and the final transmittance (w).
@group(0) @binding(5) var<storage, read_write> pixels: array<vec4<f32>>;
// Per pixel: entries of its tile's run walked (the last contributing one + 1).
@group(0) @binding(6) var<storage, read_write> walked: array<u32>;

@compute @workgroup_size(TILE, TILE)
fn main(@builtin(workgroup_id) tile: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>) {
    let x = tile.x * TILE + local.x;
    let y = tile.y * TILE + local.y;
    if (x >= params.size.x || y >= params.size.y) {
        return;
    }
    let range = tile_ranges[tile.y * params.size.z + tile.x];
    let pixel = vec2<f32>(f32(x) + 0.5, f32(y) + 0.5);
    let p = y * params.size.x + x;
    let behind = backdrop[p];
    var colour = vec3<f32>(0.0);
    var transmittance = 1.0;
    var last = 0u;
    for (var k = range.x; k < range.y; k++) {
        let i = tile_list[k];
        if (splats[3u * i].z > behind.w) {
            break;
        }
        let a = splat_alpha(splats[3u * i], splats[3u * i + 1u], pixel);
        if (a.x <= 0.0) {
            continue;
        }
        let next = transmittance * (1.0 - a.x);
        if (next < params.tuning.x) {
            break;
        }
        colour += splats[3u * i + 2u].xyz * (a.x * transmittance);
        transmittance = next;
        last = k - range.x + 1u;
    }
    pixels[p] = vec4<f32>(colour + transmittance * behind.xyz, transmittance);
    walked[p] = last;
}
