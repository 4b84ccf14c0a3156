// pack_rgb: the RGBA8 image → tightly packed RGB8 bytes (four per word), so the
// read-back moves a quarter fewer bytes and the host copies it as it is.

@group(0) @binding(0) var<uniform> camera: Camera;
@group(0) @binding(1) var<storage, read> image: array<u32>;
@group(0) @binding(2) var<storage, read_write> packed: array<u32>;

@compute @workgroup_size(GROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let word = element_index(id, groups);
    let bytes = camera.size.x * camera.size.y * 3u;
    if (4u * word >= bytes) {
        return;
    }
    var out = 0u;
    for (var b = 0u; b < 4u; b++) {
        let at = 4u * word + b;
        if (at < bytes) {
            let channel = (image[at / 3u] >> (8u * (at % 3u))) & 255u;
            out |= channel << (8u * b);
        }
    }
    packed[word] = out;
}
