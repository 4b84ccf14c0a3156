// Definitions shared by the splat kernels; prepended to each kernel at load time.
// Conventions match src/render/projection.rs (the f64 reference): camera looks down
// -z, pixel (i, j) has its centre at (i + 0.5, j + 0.5), 3DGS numerics.

struct Camera {
    view: mat4x4<f32>,        // world -> view
    position: vec4<f32>,      // camera position (xyz)
    intrinsics: vec4<f32>,    // fx, fy, cx, cy
    limits: vec4<f32>,        // guarded tan(fov/2) x, y; near; far
    size: vec4<u32>,          // width, height, tiles_x, tiles_y
    counts: vec4<u32>,        // gaussians, sh degree used, sh stride (floats), triangles
    extra: vec4<f32>,         // scale modifier, background r, g, b
    tuning: vec4<f32>,        // transmittance at which a pixel stops, unused x3
}

const TILE: u32 = 16u;
const DILATION: f32 = 0.3;
const RADIUS_SIGMAS: f32 = 3.0;
const MAX_ALPHA: f32 = 0.99;
const MIN_ALPHA: f32 = 0.0039215686;  // 1/255

// Finite test on the bit pattern: compilers may fold `x != x` away.
fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn finite3(v: vec3<f32>) -> bool {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

// Hamilton product, quaternions stored (w, x, y, z).
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        a.x * b.x - a.y * b.y - a.z * b.z - a.w * b.w,
        a.x * b.y + a.y * b.x + a.z * b.w - a.w * b.z,
        a.x * b.z - a.y * b.w + a.z * b.x + a.w * b.y,
        a.x * b.w + a.y * b.z - a.z * b.y + a.w * b.x,
    );
}

// Unit quaternion, identity for zero, tiny or non-finite input.
fn quat_normalize(q: vec4<f32>) -> vec4<f32> {
    let len2 = dot(q, q);
    if (!finite(len2) || len2 <= 1e-30) {
        return vec4<f32>(1.0, 0.0, 0.0, 0.0);
    }
    return q * inverseSqrt(len2);
}

// Rotation matrix (columns) of a unit quaternion (w, x, y, z).
fn quat_to_mat(q: vec4<f32>) -> mat3x3<f32> {
    let w = q.x; let x = q.y; let y = q.z; let z = q.w;
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

// Parameters of the sort and binning kernels (one uniform slot per dispatch).
struct SortParams {
    count: u32,   // elements in this dispatch
    shift: u32,   // radix pass: bit offset of the digit
    blocks: u32,  // radix pass: workgroup blocks of SORT_BLOCK elements
    pad: u32,     // unused: aligns `tiles`
    tiles: vec4<u32>,  // tiles x, tiles y, unused x2
}

// Elements per workgroup of the radix and scan kernels (256 invocations x 4).
const SORT_BLOCK: u32 = 1024u;
const SORT_ITEMS: u32 = 4u;

// The tile rectangle (x0, y0, x1, y1) of a projection key, clamped to the grid;
// the CPU's TileBins clamps the same way.
fn key_tiles(k: vec4<u32>, grid: vec4<u32>) -> vec4<u32> {
    return vec4<u32>(
        k.y & 0xffffu,
        k.y >> 16u,
        min(k.z & 0xffffu, grid.x - 1u),
        min(k.z >> 16u, grid.y - 1u),
    );
}
