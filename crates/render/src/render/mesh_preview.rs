//! A small CPU triangle rasteriser for mesh previews: flat-shaded, z-buffered,
//! one colour per triangle. Used for the debug mesh overlay, documentation images
//! and visual checks of the built-in head; not for Gaussians.

use glam::{Mat4, Vec3, Vec4};

use super::image::RgbImage;

/// Renders triangles with per-triangle colours, lit by a light at the camera.
/// `view_proj` maps world to clip space (OpenGL-style, depth in [-1, 1]).
pub fn render_mesh(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    colours: &[[u8; 3]],
    view_proj: Mat4,
    eye: Vec3,
    width: u32,
    height: u32,
) -> RgbImage {
    let mut image = RgbImage::new(width, height, [24, 24, 28]);
    let mut depth = vec![f32::INFINITY; (width * height) as usize];
    let screen: Vec<Option<Vec3>> = positions
        .iter()
        .map(|p| {
            let c: Vec4 = view_proj * p.extend(1.0);
            (c.w > 1e-6).then(|| {
                let n = c.truncate() / c.w;
                Vec3::new(
                    (n.x * 0.5 + 0.5) * width as f32,
                    (0.5 - n.y * 0.5) * height as f32,
                    n.z,
                )
            })
        })
        .collect();
    for (tri, colour) in triangles.iter().zip(colours) {
        let [Some(a), Some(b), Some(c)] = tri.map(|i| screen[i as usize]) else {
            continue;
        };
        let [pa, pb, pc] = tri.map(|i| positions[i as usize]);
        let normal = (pb - pa).cross(pc - pa).normalize_or_zero();
        let to_eye = (eye - (pa + pb + pc) / 3.0).normalize_or_zero();
        let shade = 0.25 + 0.75 * normal.dot(to_eye).abs();
        let rgb = colour.map(|ch| (ch as f32 * shade).min(255.0) as u8);
        fill_triangle(&mut image, &mut depth, [a, b, c], rgb);
    }
    image
}

fn fill_triangle(image: &mut RgbImage, depth: &mut [f32], v: [Vec3; 3], rgb: [u8; 3]) {
    let area = edge(v[0], v[1], v[2]);
    if area.abs() < 1e-12 {
        return;
    }
    let min_x = v.iter().map(|p| p.x).fold(f32::INFINITY, f32::min).max(0.0) as u32;
    let max_x = v
        .iter()
        .map(|p| p.x)
        .fold(f32::NEG_INFINITY, f32::max)
        .min(image.width as f32 - 1.0);
    let min_y = v.iter().map(|p| p.y).fold(f32::INFINITY, f32::min).max(0.0) as u32;
    let max_y = v
        .iter()
        .map(|p| p.y)
        .fold(f32::NEG_INFINITY, f32::max)
        .min(image.height as f32 - 1.0);
    if max_x < 0.0 || max_y < 0.0 {
        return;
    }
    for y in min_y..=max_y as u32 {
        for x in min_x..=max_x as u32 {
            let p = Vec3::new(x as f32 + 0.5, y as f32 + 0.5, 0.0);
            let w0 = edge(v[1], v[2], p) / area;
            let w1 = edge(v[2], v[0], p) / area;
            let w2 = edge(v[0], v[1], p) / area;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let z = w0 * v[0].z + w1 * v[1].z + w2 * v[2].z;
            let k = (y * image.width + x) as usize;
            if z < depth[k] {
                depth[k] = z;
                image.pixels[k * 3..k * 3 + 3].copy_from_slice(&rgb);
            }
        }
    }
}

fn edge(a: Vec3, b: Vec3, p: Vec3) -> f32 {
    (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x)
}
