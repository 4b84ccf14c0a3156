// train_backward: the training rasteriser's backward pass (src/train/raster.rs
// in f32). One workgroup per 16x16 tile, one invocation per pixel, walking the
// tile's run back to front and rebuilding each pixel's transmittance by
// division. Each entry's gradient is the sum of its pixels' contributions,
// summed in the workgroup in a fixed order (no float atomics, so a run is
// deterministic) and written to the entry's own slot; the host adds up a
// splat's slots across tiles.

@group(0) @binding(0) var<uniform> params: RasterParams;
@group(0) @binding(1) var<storage, read> splats: array<vec4<f32>>;
// Per tile: start and end in `tile_list`.
@group(0) @binding(2) var<storage, read> tile_ranges: array<vec2<u32>>;
// Splat indices, each tile's run in front-to-back order.
@group(0) @binding(3) var<storage, read> tile_list: array<u32>;
// Per pixel, two vec4s: ∂loss/∂colour (rgb) and the forward's final
// transmittance (w); the backdrop's colour (rgb).
@group(0) @binding(4) var<storage, read> pixels: array<vec4<f32>>;
// Per pixel: entries of its tile's run the forward walked.
@group(0) @binding(5) var<storage, read> walked: array<u32>;
// Per list entry, SPLAT_GRAD_FLOATS floats: ∂loss/∂ centre (x, y), conic
// (a, b, c), opacity, colour (r, g, b).
@group(0) @binding(6) var<storage, read_write> grads: array<f32>;

// The sums are pipelined over two buffers so each entry costs one barrier:
// after the barrier that publishes entry n's contributions, step 1 sums them
// in parts while step 2 finishes entry n + 1's parts (the walk goes back).
// Each pixel's contribution to an entry, component-major, two entries.
var<workgroup> contribution: array<f32, 2 * SPLAT_GRAD_FLOATS * TILE * TILE>;
// Sums of REDUCE_PARTS pixels each, component-major, two entries.
var<workgroup> partial: array<f32, 2 * SPLAT_GRAD_FLOATS * REDUCE_PARTS>;
// The most entries any pixel of the tile walked: entries behind it get no
// gradient, so the walk back starts there.
var<workgroup> most_walked: atomic<u32>;
var<workgroup> most_walked_uniform: u32;

@compute @workgroup_size(TILE, TILE)
fn main(
    @builtin(workgroup_id) tile: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let x = tile.x * TILE + local.x;
    let y = tile.y * TILE + local.y;
    // Pixels outside the image still take part in the workgroup's sums.
    var d_colour = vec3<f32>(0.0);
    var t_after = 1.0;
    var pixel_walked = 0u;
    var behind = vec3<f32>(0.0);
    if (x < params.size.x && y < params.size.y) {
        let p = y * params.size.x + x;
        d_colour = pixels[2u * p].xyz;
        t_after = pixels[2u * p].w;
        behind = pixels[2u * p + 1u].xyz;
        pixel_walked = walked[p];
    }
    let pixel = vec2<f32>(f32(x) + 0.5, f32(y) + 0.5);
    let range = tile_ranges[tile.y * params.size.z + tile.x];
    atomicMax(&most_walked, pixel_walked);
    workgroupBarrier();
    if (lane == 0u) {
        most_walked_uniform = atomicLoad(&most_walked);
    }
    let walked_by_tile = workgroupUniformLoad(&most_walked_uniform);
    // Entries past every pixel's walk get zero gradient without a walk.
    for (var k = range.x + walked_by_tile + lane; k < range.y; k += TILE * TILE) {
        for (var c = 0u; c < SPLAT_GRAD_FLOATS; c++) {
            grads[k * SPLAT_GRAD_FLOATS + c] = 0.0;
        }
    }
    for (var end = range.x + walked_by_tile; end > range.x; end--) {
        let entry = end - 1u;
        var g = array<f32, SPLAT_GRAD_FLOATS>();
        if (entry - range.x < pixel_walked) {
            let i = tile_list[entry];
            let p1 = splats[3u * i + 1u];
            let rgb = splats[3u * i + 2u].xyz;
            let a = splat_alpha(splats[3u * i], p1, pixel);
            if (a.x > 0.0) {
                let alpha = a.x;
                let d = a.zw;
                let t_before = t_after / (1.0 - alpha);
                let g_rgb = d_colour * (alpha * t_before);
                g[6] = g_rgb.x;
                g[7] = g_rgb.y;
                g[8] = g_rgb.z;
                let d_alpha = dot(d_colour, rgb - behind) * t_before;
                behind = rgb * alpha + (1.0 - alpha) * behind;
                t_after = t_before;
                // A clamped α does not move with the splat.
                if (p1.w * a.y <= MAX_ALPHA) {
                    g[5] = d_alpha * a.y;
                    let d_power = d_alpha * alpha;
                    g[2] = d_power * -0.5 * d.x * d.x;
                    g[3] = d_power * -d.x * d.y;
                    g[4] = d_power * -0.5 * d.y * d.y;
                    g[0] = d_power * (p1.x * d.x + p1.y * d.y);
                    g[1] = d_power * (p1.z * d.y + p1.y * d.x);
                }
            }
        }
        let slot = entry & 1u;
        for (var c = 0u; c < SPLAT_GRAD_FLOATS; c++) {
            contribution[(slot * SPLAT_GRAD_FLOATS + c) * TILE * TILE + lane] = g[c];
        }
        workgroupBarrier();
        sum_parts(lane, slot);
        if (end < range.x + walked_by_tile) {
            finish_entry(lane, entry + 1u);
        }
    }
    workgroupBarrier();
    if (walked_by_tile > 0u) {
        finish_entry(lane, range.x);
    }
}

// Step 1: sums of REDUCE_PARTS contributions each, for the entry in `slot`.
fn sum_parts(lane: u32, slot: u32) {
    if (lane < SPLAT_GRAD_FLOATS * REDUCE_PARTS) {
        let component = slot * SPLAT_GRAD_FLOATS + lane / REDUCE_PARTS;
        let base = component * TILE * TILE + (lane % REDUCE_PARTS) * REDUCE_PARTS;
        var sum = 0.0;
        for (var j = 0u; j < REDUCE_PARTS; j++) {
            sum += contribution[base + j];
        }
        partial[slot * SPLAT_GRAD_FLOATS * REDUCE_PARTS + lane] = sum;
    }
}

// Step 2: an entry's gradient from its parts, to its slot in `grads`.
fn finish_entry(lane: u32, entry: u32) {
    if (lane < SPLAT_GRAD_FLOATS) {
        let base = ((entry & 1u) * SPLAT_GRAD_FLOATS + lane) * REDUCE_PARTS;
        var sum = 0.0;
        for (var j = 0u; j < REDUCE_PARTS; j++) {
            sum += partial[base + j];
        }
        grads[entry * SPLAT_GRAD_FLOATS + lane] = sum;
    }
}
