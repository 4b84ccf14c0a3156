// bind: triangle-local Gaussians -> world space, GaussianAvatars convention
// (docs/method.md §3): mu = k R mu_local + c, scale = exp(s) k, q = q(R) (x) normalize(q_local).
// Per animation frame only `frames` changes.

@group(0) @binding(0) var<uniform> camera: Camera;
// Per Gaussian, 3 x vec4: (local position, binding as bits), local quat (w,x,y,z),
// (log scale, opacity logit or, above OPACITY_LITERAL, literal opacity).
@group(0) @binding(1) var<storage, read> local: array<vec4<f32>>;
// Per triangle, 5 x vec4: (a0, k), (a1, 0), (a2, 0), (centre, 0), quat (w,x,y,z).
@group(0) @binding(2) var<storage, read> frames: array<vec4<f32>>;
// Per Gaussian, 3 x vec4: (position, opacity), quat (w,x,y,z), (scale, 0).
@group(0) @binding(3) var<storage, read_write> world: array<vec4<f32>>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = element_index(id, groups);
    if (i >= camera.counts.x) {
        return;
    }
    let g0 = local[3u * i];
    let g1 = local[3u * i + 1u];
    let g2 = local[3u * i + 2u];
    let t = min(bitcast<u32>(g0.w), camera.counts.w - 1u);
    let f0 = frames[5u * t];
    let f1 = frames[5u * t + 1u];
    let f2 = frames[5u * t + 2u];
    let centre = frames[5u * t + 3u].xyz;
    let frame_quat = frames[5u * t + 4u];
    let k = f0.w;
    let position = k * (f0.xyz * g0.x + f1.xyz * g0.y + f2.xyz * g0.z) + centre;
    let rotation = quat_normalize(quat_mul(frame_quat, quat_normalize(g1)));
    let scale = exp(g2.xyz) * k;
    // Codes above OPACITY_LITERAL are opacities above 1 (level-of-detail
    // nodes), written as OPACITY_LITERAL - 1 + opacity.
    let opacity = select(1.0 / (1.0 + exp(-g2.w)), g2.w - (OPACITY_LITERAL - 1.0), g2.w > OPACITY_LITERAL);
    world[3u * i] = vec4<f32>(position, opacity);
    world[3u * i + 1u] = rotation;
    world[3u * i + 2u] = vec4<f32>(scale, 0.0);
}
