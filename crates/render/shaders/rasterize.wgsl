// rasterize: one workgroup per 16x16 tile, one invocation per pixel, blending the
// tile's depth-sorted Gaussians front to back with early termination. No workgroup
// barriers: on software rasterisers they cost more than the shared loads save.

@group(0) @binding(0) var<uniform> camera: Camera;
@group(0) @binding(1) var<storage, read> projected: array<vec4<f32>>;
// Per tile: start and end in `tile_list`.
@group(0) @binding(2) var<storage, read> tile_ranges: array<vec2<u32>>;
// Gaussian indices, each tile's run in front-to-back order.
@group(0) @binding(3) var<storage, read> tile_list: array<u32>;
// RGBA8 per pixel, row-major.
@group(0) @binding(4) var<storage, read_write> image: array<u32>;
// Pixels whose walk ended before their list did without saturating: a driver
// cut the loop short (llvmpipe allows an invocation 65,535 loop iterations).
@group(0) @binding(5) var<storage, read_write> cut_short: atomic<u32>;

fn pack(c: vec3<f32>) -> u32 {
    let q = vec3<u32>(clamp(c, vec3<f32>(0.0), vec3<f32>(1.0)) * 255.0 + vec3<f32>(0.5));
    return q.x | (q.y << 8u) | (q.z << 16u) | (255u << 24u);
}

@compute @workgroup_size(TILE, TILE)
fn main(@builtin(workgroup_id) tile: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>) {
    let x = tile.x * TILE + local.x;
    let y = tile.y * TILE + local.y;
    if (x >= camera.size.x || y >= camera.size.y) {
        return;
    }
    let range = tile_ranges[tile.y * camera.size.z + tile.x];
    let px = f32(x) + 0.5;
    let py = f32(y) + 0.5;
    var colour = vec3<f32>(0.0);
    var transmittance = 1.0;
    var saturated = false;
    var k = range.x;
    for (; k < range.y; k++) {
        let i = tile_list[k];
        let p0 = projected[3u * i];
        let d = vec2<f32>(px - p0.x, py - p0.y);
        if (abs(d.x) > p0.w || abs(d.y) > p0.w) {
            continue;
        }
        let p1 = projected[3u * i + 1u];
        let power = -0.5 * (p1.x * d.x * d.x + p1.z * d.y * d.y) - p1.y * d.x * d.y;
        if (power > 0.0) {
            continue;
        }
        let alpha = min(MAX_ALPHA, p1.w * exp(power));
        if (alpha < MIN_ALPHA) {
            continue;
        }
        let next = transmittance * (1.0 - alpha);
        if (next < camera.tuning.x) {
            saturated = true;
            break;
        }
        colour += projected[3u * i + 2u].xyz * (alpha * transmittance);
        transmittance = next;
    }
    if (!saturated && k < range.y) {
        atomicAdd(&cut_short, 1u);
    }
    image[y * camera.size.x + x] = pack(colour + transmittance * camera.extra.yzw);
}
