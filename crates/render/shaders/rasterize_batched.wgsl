// rasterize_batched: `rasterize` for hardware GPUs. One workgroup per 16x16 tile,
// one invocation per pixel; the tile's depth-sorted Gaussians are read in batches
// of TILE*TILE, one per invocation, into workgroup memory, so a batch's loads are
// in flight together instead of every invocation waiting on each entry's two
// dependent reads in turn; the tile stops once all its pixels are saturated.
// Each pixel blends exactly as in `rasterize` (same operations, same order), so
// the two kernels' images are the same bit for bit.

@group(0) @binding(0) var<uniform> camera: Camera;
@group(0) @binding(1) var<storage, read> projected: array<vec4<f32>>;
// Per tile: start and end in `tile_list`.
@group(0) @binding(2) var<storage, read> tile_ranges: array<vec2<u32>>;
// Gaussian indices, each tile's run in front-to-back order.
@group(0) @binding(3) var<storage, read> tile_list: array<u32>;
// RGBA8 per pixel, row-major.
@group(0) @binding(4) var<storage, read_write> image: array<u32>;
// Pixels whose walk ended before their list did without saturating (as in
// `rasterize`; a driver that cuts loops short would show here).
@group(0) @binding(5) var<storage, read_write> cut_short: atomic<u32>;

const BATCH: u32 = TILE * TILE;

var<workgroup> batch_centre: array<vec4<f32>, BATCH>;
var<workgroup> batch_conic: array<vec4<f32>, BATCH>;
var<workgroup> batch_rgb: array<vec3<f32>, BATCH>;
var<workgroup> tile_range: vec2<u32>;
// Pixels of the tile that are finished (saturated or outside the image),
// counted once each as they finish, so a batch costs no atomics of its own.
var<workgroup> pixels_done: atomic<u32>;
var<workgroup> all_done: u32;

fn pack(c: vec3<f32>) -> u32 {
    let q = vec3<u32>(clamp(c, vec3<f32>(0.0), vec3<f32>(1.0)) * 255.0 + vec3<f32>(0.5));
    return q.x | (q.y << 8u) | (q.z << 16u) | (255u << 24u);
}

@compute @workgroup_size(TILE, TILE)
fn main(
    @builtin(workgroup_id) tile: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let x = tile.x * TILE + local.x;
    let y = tile.y * TILE + local.y;
    let inside = x < camera.size.x && y < camera.size.y;
    if (lane == 0u) {
        tile_range = tile_ranges[tile.y * camera.size.z + tile.x];
        // The pixels past the image's edge are finished from the start.
        let wide = min(TILE, camera.size.x - tile.x * TILE);
        let high = min(TILE, camera.size.y - tile.y * TILE);
        atomicStore(&pixels_done, BATCH - wide * high);
    }
    // The range is the same for the whole tile: loaded once, read uniformly
    // so the batch loop's barriers are in uniform control flow.
    let range = workgroupUniformLoad(&tile_range);
    let px = f32(x) + 0.5;
    let py = f32(y) + 0.5;
    var colour = vec3<f32>(0.0);
    var transmittance = 1.0;
    var done = !inside;
    // Where an unsaturated pixel's walk got to.
    var walked = range.x;
    // The loads run ahead of the blending: a batch's Gaussians are read
    // while the batch before it blends, and their list entries one batch
    // earlier still, so neither of the two dependent loads is waited on.
    var next_centre = vec4<f32>(0.0);
    var next_conic = vec4<f32>(0.0);
    var next_rgb = vec3<f32>(0.0);
    var next_index = 0u;
    if (range.x + lane < range.y) {
        let i = tile_list[range.x + lane];
        next_centre = projected[3u * i];
        next_conic = projected[3u * i + 1u];
        next_rgb = projected[3u * i + 2u].xyz;
    }
    if (range.x + BATCH + lane < range.y) {
        next_index = tile_list[range.x + BATCH + lane];
    }
    for (var start = range.x; start < range.y; start += BATCH) {
        // Every pixel finished in the last batch counted itself before
        // that batch's closing barrier, so the count is complete here and
        // a saturated tile loads no more Gaussians.
        if (lane == 0u) {
            all_done = atomicLoad(&pixels_done);
        }
        if (workgroupUniformLoad(&all_done) == BATCH) {
            break;
        }
        // Past the list's end these are stale and never read.
        batch_centre[lane] = next_centre;
        batch_conic[lane] = next_conic;
        batch_rgb[lane] = next_rgb;
        workgroupBarrier();
        if (start + BATCH + lane < range.y) {
            let i = next_index;
            next_centre = projected[3u * i];
            next_conic = projected[3u * i + 1u];
            next_rgb = projected[3u * i + 2u].xyz;
        }
        if (start + 2u * BATCH + lane < range.y) {
            next_index = tile_list[start + 2u * BATCH + lane];
        }
        if (!done) {
            let count = min(BATCH, range.y - start);
            var j = 0u;
            for (; j < count; j++) {
                // The rules `rasterize` applies inline (common.wgsl).
                let alpha = splat_alpha(batch_centre[j], batch_conic[j], vec2<f32>(px, py)).x;
                if (alpha == 0.0) {
                    continue;
                }
                let next = transmittance * (1.0 - alpha);
                if (next < camera.tuning.x) {
                    done = true;
                    atomicAdd(&pixels_done, 1u);
                    break;
                }
                colour += batch_rgb[j] * (alpha * transmittance);
                transmittance = next;
            }
            walked = start + j;
        }
        // The next batch overwrites this one only after every pixel used it.
        workgroupBarrier();
    }
    if (inside) {
        image[y * camera.size.x + x] = pack(colour + transmittance * camera.extra.yzw);
    }
    if (!done && walked < range.y) {
        atomicAdd(&cut_short, 1u);
    }
}
