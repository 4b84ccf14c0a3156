//! Baked light under a new shape (docs/method.md §7.10). A trained avatar's
//! colours hold the light of its capture: a cheek facing the key light is
//! brighter than one turned away. A composite moves a source's Gaussians onto
//! the blended face, where many triangles face another way, but their colours
//! still say how the source's own face was lit. Each source's light is
//! estimated from its own skin — colour as a linear function of the surface
//! normal, c = a + b·n per channel (first-order irradiance; the skin's albedo
//! is taken as even) — and every Gaussian moved onto a triangle that turned
//! is relit by the ratio of that light for the new normal to the old.

use glam::{DMat4, DVec4, Vec3, Vec4};

use super::colour::{colour_weight, skin_likeness, srgb_to_lab, SkinStats};
use crate::avatar::gaussians::{dc_to_rgb, GaussianSet};
use crate::avatar::synthetic::vertex_normals;

/// Largest and smallest relighting gain: a turn that would change a colour
/// more than this is more likely a bad fit or a degenerate triangle.
pub const RELIGHT_RANGE: (f32, f32) = (0.5, 2.0);

/// A gain this close to one is a normal that moved by rounding alone.
const ROUNDING: f32 = 1e-5;

/// Fewest skin Gaussians a light is fitted to.
const MIN_SAMPLES: usize = 64;

/// The light a source's skin shows: per channel, brightness a + b·n for a
/// surface of unit normal n.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakedLight {
    /// Per channel (r, g, b): (bx, by, bz, a), in f32 for relighting many
    /// Gaussians.
    channels: [Vec4; 3],
}

impl BakedLight {
    /// The light of these per-channel (a, bx, by, bz).
    pub fn new(channels: [DVec4; 3]) -> BakedLight {
        BakedLight {
            channels: channels.map(|c| Vec4::new(c.y as f32, c.z as f32, c.w as f32, c.x as f32)),
        }
    }

    /// Fits the light to skin samples: each a colour (display RGB), the unit
    /// normal of the surface it sits on, and a weight. None when the samples
    /// are too few, do not span enough directions to tell the light's, or
    /// leave a channel dark where they face.
    pub fn fit(samples: impl IntoIterator<Item = (Vec3, Vec3, f32)>) -> Option<BakedLight> {
        let mut normal_matrix = DMat4::ZERO;
        let mut rhs = [DVec4::ZERO; 3];
        let mut count = 0usize;
        for (colour, normal, weight) in samples {
            if !(weight > 0.0 && colour.is_finite() && normal.is_finite()) {
                continue;
            }
            let x = DVec4::new(1.0, normal.x as f64, normal.y as f64, normal.z as f64);
            let w = weight as f64;
            normal_matrix += outer(x * w, x);
            for (ch, r) in rhs.iter_mut().enumerate() {
                *r += x * (w * colour[ch] as f64);
            }
            count += 1;
        }
        if count < MIN_SAMPLES {
            return None;
        }
        // Normals all alike (a flat patch) leave the light's direction unknown.
        let scale = normal_matrix.x_axis.x.max(f64::MIN_POSITIVE);
        let conditioned = normal_matrix * (1.0 / scale);
        let determinant = conditioned.determinant().abs();
        if determinant.is_nan() || determinant <= 1e-9 {
            return None;
        }
        let inverse = normal_matrix.inverse();
        let light = BakedLight::new(rhs.map(|r| inverse * r));
        let mean_normal = (normal_matrix.x_axis.truncate() / scale).as_vec3();
        let facing = light.brightness(mean_normal.normalize_or(Vec3::Z));
        (light.channels.iter().all(|c| c.is_finite()) && facing.min_element() > 0.05)
            .then_some(light)
    }

    /// Brightness per channel of a surface facing `normal` (unit).
    pub fn brightness(&self, normal: Vec3) -> Vec3 {
        let x = normal.extend(1.0);
        Vec3::new(
            self.channels[0].dot(x),
            self.channels[1].dot(x),
            self.channels[2].dot(x),
        )
    }

    /// The per-channel gain that relights a colour seen on a surface facing
    /// `from` as it would look facing `to`: exactly one when they are equal
    /// or differ by rounding (a source's mesh moved whole), one where the
    /// light is too dark to divide by, within [`RELIGHT_RANGE`].
    pub fn gain(&self, from: Vec3, to: Vec3) -> Vec3 {
        if from == to {
            return Vec3::ONE;
        }
        let (old, new) = (self.brightness(from), self.brightness(to));
        let floor = 0.05;
        let gain = Vec3::from_array(std::array::from_fn(|ch| {
            if old[ch] > floor && new[ch] > floor {
                (new[ch] / old[ch]).clamp(RELIGHT_RANGE.0, RELIGHT_RANGE.1)
            } else {
                1.0
            }
        }));
        match (gain - Vec3::ONE).abs().max_element() < ROUNDING {
            true => Vec3::ONE,
            false => gain,
        }
    }
}

/// The light baked into a source's colours, fitted to its Gaussians
/// `indices` (its skin regions'): each counts by its weight in a mean colour
/// times how skin-like its colour is (`stats`), at the smooth normal of its
/// parent triangle on the source's neutral mesh (`normals`, per triangle).
pub fn source_light(
    set: &GaussianSet,
    normals: &[Vec3],
    indices: &[u32],
    stats: Option<&SkinStats>,
) -> Option<BakedLight> {
    let stride = set.sh_stride();
    let samples = indices.iter().filter_map(|&i| {
        let i = i as usize;
        let normal = *normals.get(set.binding[i] as usize)?;
        let dc = &set.sh[i * stride..i * stride + 3];
        let colour = Vec3::new(dc_to_rgb(dc[0]), dc_to_rgb(dc[1]), dc_to_rgb(dc[2]));
        let likeness = stats.map_or(1.0, |s| skin_likeness(srgb_to_lab(colour), s));
        (normal != Vec3::ZERO).then_some((colour, normal, colour_weight(set, i) * likeness))
    });
    BakedLight::fit(samples)
}

fn outer(a: DVec4, b: DVec4) -> DMat4 {
    DMat4::from_cols(a * b.x, a * b.y, a * b.z, a * b.w)
}

/// Unit normal of the triangle with these corners (zero when degenerate).
pub fn face_normal(corners: [Vec3; 3]) -> Vec3 {
    (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .normalize_or_zero()
}

/// Each triangle's smooth normal: the mean of its corners' area-weighted
/// vertex normals (the surface's shading normal over the triangle, as a
/// renderer interpolates it), zero where they cancel.
pub fn smooth_normals(mesh: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let vertex = vertex_normals(mesh, triangles);
    triangles
        .iter()
        .map(|t| {
            t.iter()
                .map(|&v| vertex[v as usize])
                .sum::<Vec3>()
                .normalize_or_zero()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere_samples(light: Vec3, albedo: Vec3) -> Vec<(Vec3, Vec3, f32)> {
        let mut out = Vec::new();
        for i in 0..40 {
            for j in 0..20 {
                let (theta, phi) = (i as f32 * 0.157, j as f32 * 0.078);
                let n = Vec3::new(theta.sin() * phi.cos(), phi.sin(), theta.cos() * phi.cos());
                if n.z < 0.0 {
                    continue;
                }
                let shade = 0.55 + 0.5 * (n.dot(light) + 0.4) / 1.4;
                out.push((albedo * shade, n, 1.0));
            }
        }
        out
    }

    /// A wrapped key light (linear in the normal where it is not clipped)
    /// is recovered, and relighting a colour from one normal to another
    /// gives the colour the light gives there.
    #[test]
    fn recovers_a_linear_light_and_relights_by_its_ratio() {
        let key = Vec3::new(0.35, 0.55, 0.76).normalize();
        let albedo = Vec3::new(0.8, 0.6, 0.5);
        let light = BakedLight::fit(sphere_samples(key, albedo)).unwrap();
        let (from, to) = (Vec3::Z, Vec3::new(0.6, 0.0, 0.8));
        let shade = |n: Vec3| 0.55 + 0.5 * (n.dot(key) + 0.4) / 1.4;
        let relit = albedo * shade(from) * light.gain(from, to);
        assert!(
            (relit - albedo * shade(to)).abs().max_element() < 1e-4,
            "{relit}"
        );
        assert_eq!(light.gain(to, to), Vec3::ONE);
        let nudged = (to + Vec3::splat(1e-7)).normalize();
        assert_eq!(light.gain(to, nudged), Vec3::ONE);
    }

    /// Smooth normals of a mesh with a degenerate triangle, a sliver and a
    /// part on its own: unit where a triangle's corners agree, zero where a
    /// lone degenerate triangle has none, never NaN.
    #[test]
    fn smooth_normals_of_hard_meshes_are_unit_or_zero() {
        let mesh = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(1e-9, 1.0, 0.0),
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(6.0, 0.0, 0.0),
            Vec3::new(7.0, 0.0, 0.0),
        ];
        let triangles = [[0, 1, 2], [1, 3, 2], [4, 5, 6]];
        let normals = smooth_normals(&mesh, &triangles);
        assert!((normals[0] - Vec3::Z).length() < 1e-6);
        assert!(
            (normals[1] - Vec3::Z).length() < 1e-6,
            "the sliver takes its corners'"
        );
        assert_eq!(
            normals[2],
            Vec3::ZERO,
            "a lone degenerate triangle has none"
        );
        assert!(normals.iter().all(|n| n.is_finite()));
    }

    /// Near-black skin (a dark skin in deep shade) shows no light to fit.
    #[test]
    fn near_black_skin_gives_no_light() {
        let key = Vec3::new(0.35, 0.55, 0.76).normalize();
        assert!(BakedLight::fit(sphere_samples(key, Vec3::splat(0.03))).is_none());
        assert!(BakedLight::fit(sphere_samples(key, Vec3::splat(0.15))).is_some());
    }

    /// Too few samples, all one normal, or non-finite ones give no light;
    /// a degenerate triangle has no normal and a dark light no gain.
    #[test]
    fn refuses_what_tells_no_light() {
        let one_way = vec![(Vec3::splat(0.5), Vec3::Z, 1.0); 500];
        assert!(BakedLight::fit(one_way).is_none());
        let few = sphere_samples(Vec3::Z, Vec3::ONE)
            .into_iter()
            .take(10)
            .collect::<Vec<_>>();
        assert!(BakedLight::fit(few).is_none());
        let mut bad = sphere_samples(Vec3::Z, Vec3::ONE);
        for s in bad.iter_mut() {
            s.0 = Vec3::NAN;
        }
        assert!(BakedLight::fit(bad).is_none());
        assert_eq!(
            face_normal([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]),
            Vec3::ZERO
        );
        let dark = BakedLight::new([DVec4::new(0.01, 0.0, 0.0, 0.0); 3]);
        assert_eq!(dark.gain(Vec3::Z, Vec3::X), Vec3::ONE);
        let steep = BakedLight::new([DVec4::new(0.5, 0.0, 0.0, 0.45); 3]);
        let g = steep.gain(
            Vec3::Z,
            Vec3::new(0.0, 0.0, -1.0).lerp(Vec3::X, 0.5).normalize(),
        );
        assert!(g.min_element() >= RELIGHT_RANGE.0);
    }
}
