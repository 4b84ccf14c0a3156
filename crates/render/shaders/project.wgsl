// project: world Gaussians -> screen-space ellipses (EWA, 3DGS numerics), SH colour,
// depth and the tiles each footprint touches. Culled Gaussians get key.w = 0.
// With a level-of-detail threshold (camera.tuning.z > 0) the Gaussians are the
// nodes of a hierarchy and each decides on its own whether it is in the cut
// (src/render/lod/cut.rs): the same cut the CPU's tree walk finds, because a
// parent's bounding sphere holds its children's, so its size on screen is never
// smaller and every node whose parent is opened has all its ancestors opened.

@group(0) @binding(0) var<uniform> camera: Camera;
@group(0) @binding(1) var<storage, read> world: array<vec4<f32>>;
// SH coefficients, `counts.z` floats a Gaussian, in two bindings so a scene
// may hold twice what one binding can: Gaussians below bitcast<u32>(tuning.y)
// in `sh`, the rest in `sh_rest`.
@group(0) @binding(2) var<storage, read> sh: array<f32>;
@group(0) @binding(3) var<storage, read> sh_rest: array<f32>;
// Per node of a hierarchy (unread without a threshold): parent index (NO_PARENT for
// the root) with LEAF_BIT set for the scene's own Gaussians; the bits of its
// bounding sphere's radius, of its leaves' mass and of their summed opacity.
@group(0) @binding(4) var<storage, read> lod: array<vec4<u32>>;
// Per Gaussian, 3 x vec4: (centre x, y, depth, radius), (conic a, b, c, opacity), (rgb, 0).
@group(0) @binding(5) var<storage, read_write> projected: array<vec4<f32>>;
// Per Gaussian: (depth bits, first tile x | y << 16, last tile x | y << 16, visible).
@group(0) @binding(6) var<storage, read_write> keys: array<vec4<u32>>;
// Gaussians drawn this frame (not culled), and of them the scene's own (all of
// them without a hierarchy); the renderer clears it before the dispatch.
@group(0) @binding(7) var<storage, read_write> drawn: array<atomic<u32>, 2>;

const LEAF_BIT: u32 = 0x80000000u;
const NO_PARENT: u32 = 0x7fffffffu;
const FAR_AWAY: f32 = 3.0e38;

var<workgroup> drawn_here: array<atomic<u32>, 2>;

const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;

// Coefficient k of Gaussian i.
fn coef(i: u32, k: u32) -> vec3<f32> {
    let split = bitcast<u32>(camera.tuning.y);
    if (i < split) {
        let o = i * camera.counts.z + 3u * k;
        return vec3<f32>(sh[o], sh[o + 1u], sh[o + 2u]);
    }
    let o = (i - split) * camera.counts.z + 3u * k;
    return vec3<f32>(sh_rest[o], sh_rest[o + 1u], sh_rest[o + 2u]);
}

fn sh_colour(i: u32, dir: vec3<f32>) -> vec3<f32> {
    let degree = camera.counts.y;
    var c = SH_C0 * coef(i, 0u);
    if (degree >= 1u) {
        let x = dir.x; let y = dir.y; let z = dir.z;
        c += SH_C1 * (-y * coef(i, 1u) + z * coef(i, 2u) - x * coef(i, 3u));
        if (degree >= 2u) {
            let xx = x * x; let yy = y * y; let zz = z * z;
            c += 1.0925484305920792 * x * y * coef(i, 4u)
               - 1.0925484305920792 * y * z * coef(i, 5u)
               + 0.31539156525252005 * (2.0 * zz - xx - yy) * coef(i, 6u)
               - 1.0925484305920792 * x * z * coef(i, 7u)
               + 0.5462742152960396 * (xx - yy) * coef(i, 8u);
            if (degree >= 3u) {
                c += -0.5900435899266435 * y * (3.0 * xx - yy) * coef(i, 9u)
                   + 2.890611442640554 * x * y * z * coef(i, 10u)
                   - 0.4570457994644658 * y * (4.0 * zz - xx - yy) * coef(i, 11u)
                   + 0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * coef(i, 12u)
                   - 0.4570457994644658 * x * (4.0 * zz - xx - yy) * coef(i, 13u)
                   + 1.445305721320277 * z * (xx - yy) * coef(i, 14u)
                   - 0.5900435899266435 * x * (xx - 3.0 * yy) * coef(i, 15u);
            }
        }
    }
    return max(c + vec3<f32>(0.5), vec3<f32>(0.0));
}

fn cull(i: u32) {
    keys[i] = vec4<u32>(0u, 0u, 0u, 0u);
}

// The on-screen diameter in pixels of a sphere of radius r about view-space p
// (cut.rs View::judge): unbounded once it reaches the near plane.
fn sphere_pixels(p: vec3<f32>, r: f32) -> f32 {
    let nearest = -p.z - r;
    if (nearest <= camera.limits.z) {
        return FAR_AWAY;
    }
    return 2.0 * max(camera.intrinsics.x, camera.intrinsics.y) * r / nearest;
}

// Whether a sphere lies wholly outside the guarded view or before the near plane.
fn sphere_outside(p: vec3<f32>, r: f32) -> bool {
    let depth = -p.z;
    let tan = camera.limits.xy;
    let norm = sqrt(vec2<f32>(1.0) + tan * tan);
    return depth + r < camera.limits.z
        || (abs(p.x) - tan.x * depth) / norm.x > r
        || (abs(p.y) - tan.y * depth) / norm.y > r;
}

// Whether node i is in the cut of threshold `pixels` (cut.rs): in view, small
// enough to stand for its subtree (or a leaf), and its parent too large.
fn in_cut(i: u32, p: vec3<f32>, link: vec4<u32>, pixels: f32) -> bool {
    let extent = bitcast<f32>(link.y);
    if (sphere_outside(p, extent)) {
        return false;
    }
    if ((link.x & LEAF_BIT) == 0u && sphere_pixels(p, extent) > pixels) {
        return false;
    }
    let parent = link.x & NO_PARENT;
    if (parent == NO_PARENT) {
        return true;
    }
    let centre = (camera.view * vec4<f32>(world[3u * parent].xyz, 1.0)).xyz;
    return sphere_pixels(centre, bitcast<f32>(lod[parent].y)) > pixels;
}

// A merged node's opacity where it is drawn (lod/mod.rs DrawnOpacity): its
// leaves' mass, dilated as the renderer dilates each of them, over its own
// dilated mean area.
fn drawn_opacity(link: vec4<u32>, depth: f32, scale: vec3<f32>) -> f32 {
    let pixel = max(depth, camera.limits.z) / camera.intrinsics.y;
    let dilation = DILATION * pixel * pixel;
    let grown = sqrt(scale * scale + vec3<f32>(dilation));
    let mass = bitcast<f32>(link.z) + 3.0 * dilation * bitcast<f32>(link.w);
    let area = max(grown.x * grown.y + grown.y * grown.z + grown.z * grown.x, 1e-37);
    return clamp(mass / area, 0.0, MAX_OPACITY);
}

// Projects Gaussian i: 0 when culled, 1 for a drawn merged node, 2 for a drawn
// Gaussian of the scene.
fn project_one(i: u32) -> u32 {
    let w0 = world[3u * i];
    let q = world[3u * i + 1u];
    let s = world[3u * i + 2u].xyz * camera.extra.x;
    var opacity = min(w0.w, MAX_OPACITY);
    let p = (camera.view * vec4<f32>(w0.xyz, 1.0)).xyz;
    let depth = -p.z;
    var kind = 2u;
    let pixels = camera.tuning.z;
    if (pixels > 0.0) {
        let link = lod[i];
        if (!in_cut(i, p, link, pixels)) {
            cull(i);
            return 0u;
        }
        if ((link.x & LEAF_BIT) == 0u) {
            kind = 1u;
            opacity = drawn_opacity(link, depth, world[3u * i + 2u].xyz);
        }
    }
    if (!finite3(w0.xyz) || !finite3(s) || !(opacity > 0.0)) {
        cull(i);
        return 0u;
    }
    if (!(depth >= camera.limits.z && depth <= camera.limits.w)) {
        cull(i);
        return 0u;
    }
    let r = quat_to_mat(quat_normalize(q));
    let m = mat3x3<f32>(r[0] * s.x, r[1] * s.y, r[2] * s.z);
    let w = mat3x3<f32>(camera.view[0].xyz, camera.view[1].xyz, camera.view[2].xyz);
    let cov = w * (m * transpose(m)) * transpose(w);
    let fx = camera.intrinsics.x;
    let fy = camera.intrinsics.y;
    let tx = clamp(p.x / depth, -camera.limits.x, camera.limits.x);
    let ty = clamp(p.y / depth, -camera.limits.y, camera.limits.y);
    let j0 = vec3<f32>(fx / depth, 0.0, fx * tx / depth);
    let j1 = vec3<f32>(0.0, -fy / depth, -fy * ty / depth);
    let a = dot(j0, cov * j0) + DILATION;
    let b = dot(j0, cov * j1);
    let c = dot(j1, cov * j1) + DILATION;
    let det = a * c - b * b;
    if (!(det > 0.0) || !finite(det)) {
        cull(i);
        return 0u;
    }
    let mid = 0.5 * (a + c);
    let lambda = mid + sqrt(max(mid * mid - det, 0.1));
    // projection.rs footprint_radius: 3σ, or less where α drops below 1/255 sooner.
    let visible = sqrt(max(2.0 * lambda * log(opacity / MIN_ALPHA), 0.0));
    let radius = min(ceil(RADIUS_SIGMAS * sqrt(lambda)), visible * (1.0 + 1e-4) + 1e-3);
    let centre = vec2<f32>(camera.intrinsics.z + fx * p.x / depth, camera.intrinsics.w - fy * p.y / depth);
    let width = f32(camera.size.x);
    let height = f32(camera.size.y);
    // Pixels whose centres lie within the square footprint (see projection.rs).
    let x0 = max(ceil(centre.x - radius - 0.5), 0.0);
    let x1 = min(floor(centre.x + radius - 0.5), width - 1.0);
    let y0 = max(ceil(centre.y - radius - 0.5), 0.0);
    let y1 = min(floor(centre.y + radius - 0.5), height - 1.0);
    // The square's part the ellipse where α reaches 1/255 can reach,
    // ±sqrt(2 ln(o / MIN_ALPHA) Σ_xx) across and Σ_yy down, widened a little
    // for rounding (cpu/project.rs, the same box): only its tiles list the
    // Gaussian, since the square's other pixels are never blended.
    let reach = 2.0 * max(log(opacity / MIN_ALPHA), 0.0);
    let reach_x = min(radius, sqrt(reach * a) * (1.0 + 1e-3) + 1e-2);
    let reach_y = min(radius, sqrt(reach * c) * (1.0 + 1e-3) + 1e-2);
    let bx0 = max(ceil(centre.x - reach_x - 0.5), 0.0);
    let bx1 = min(floor(centre.x + reach_x - 0.5), width - 1.0);
    let by0 = max(ceil(centre.y - reach_y - 0.5), 0.0);
    let by1 = min(floor(centre.y + reach_y - 0.5), height - 1.0);
    if (!finite(radius) || !(x0 <= x1) || !(y0 <= y1) || !(bx0 <= bx1) || !(by0 <= by1)) {
        cull(i);
        return 0u;
    }
    let dir = normalize(w0.xyz - camera.position.xyz);
    let rgb = sh_colour(i, dir);
    projected[3u * i] = vec4<f32>(centre, depth, radius);
    projected[3u * i + 1u] = vec4<f32>(c / det, -b / det, a / det, opacity);
    projected[3u * i + 2u] = vec4<f32>(rgb, 0.0);
    let t0 = vec2<u32>(u32(bx0) / TILE, u32(by0) / TILE);
    let t1 = vec2<u32>(u32(bx1) / TILE, u32(by1) / TILE);
    keys[i] = vec4<u32>(bitcast<u32>(depth), t0.x | (t0.y << 16u), t1.x | (t1.y << 16u), 1u);
    return kind;
}

@compute @workgroup_size(GROUP)
fn main(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let i = element_index(id, groups);
    var kind = 0u;
    if (i < camera.counts.x) {
        kind = project_one(i);
    }
    // Counted per workgroup first: one global atomic a workgroup, not one a Gaussian.
    if (kind != 0u) {
        atomicAdd(&drawn_here[0], 1u);
    }
    if (kind == 2u) {
        atomicAdd(&drawn_here[1], 1u);
    }
    workgroupBarrier();
    if (local < 2u) {
        let n = atomicLoad(&drawn_here[local]);
        if (n > 0u) {
            atomicAdd(&drawn[local], n);
        }
    }
}
