//! Eyeball Gaussians under the lids (docs/method.md §5.1, "Under the lids").
//! By place a Gaussian counts for the surface nearest its centre; on an
//! eyeball that surface runs on under the lids, and a trained source's
//! Gaussians there — on the covered part of the eyeball, millimetres behind
//! the lid's margin — were fitted to what the cameras saw in front of them:
//! lid skin, not the eye's white. They count for the lid instead, so its
//! colour rules judge them (a light source's lid skin in shade is as light
//! and nearly as grey as its white: no rule by colour alone on the eyeball
//! told the two apart) and the base's lid skin takes over from them where
//! it takes over the lid.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::avatar::binding::triangle_frames;
use crate::avatar::gaussians::GaussianSet;
use crate::model::head::HeadModel;
use crate::model::regions::Region;

/// Per Gaussian of `set`, counted for the triangles `counted` of the
/// source's `neutral` mesh: where it counts for an eyeball and a triangle of
/// that eye's lid or socket (its eye region or eye socket) lies in front of
/// it — along the head frame's +z, out of the face (method §1.1), and
/// [`COVER_YAW_DEG`] to either side, within the eyeball's radius — the
/// nearest such triangle along +z; `None` for every other
/// Gaussian, and for one whose centre is not finite or whose triangle
/// (bound or counted) is past the mesh.
pub fn triangles_over_eyeballs(
    model: &HeadModel,
    set: &GaussianSet,
    neutral: &[Vec3],
    counted: &[u32],
) -> Vec<Option<u32>> {
    let eyes: Vec<Eyeball> = [Region::LeftEyeball, Region::RightEyeball]
        .into_iter()
        .filter_map(|region| Eyeball::of(model, neutral, region))
        .collect();
    if eyes.is_empty() {
        return vec![None; set.len()];
    }
    let frames = triangle_frames(neutral, &model.triangles);
    (0..set.len())
        .into_par_iter()
        .map(|i| {
            let region = model.triangle_regions.get(*counted.get(i)? as usize)?;
            let eye = eyes.iter().find(|e| e.region == *region)?;
            let centre = frames
                .get(set.binding[i] as usize)?
                .to_world(set.position[i]);
            if !centre.is_finite() {
                return None;
            }
            eye.cover(model, neutral, centre)
        })
        .collect()
}

/// How far from +z (degrees of yaw, either way) the lid must cover an
/// eyeball Gaussian as well: the frontal pair of a NeRSemble-like rig
/// (cameras at ±20°, as `visage capture`'s) sees round the corners of the
/// eye, where the white shows past a lid that covers it straight ahead.
pub const COVER_YAW_DEG: f64 = 20.0;

/// An eyeball of a neutral mesh and the triangles of its lid and socket
/// that may lie in front of it.
struct Eyeball {
    region: Region,
    radius: f64,
    /// Triangles of the eyeball's lid and socket on the same side
    /// (`Region::anchor_regions`) that come within two radii of the centre
    /// (by the ball round their centroid through their farthest corner).
    near: Vec<usize>,
}

impl Eyeball {
    /// The eyeball of `region` on `neutral`: the mean of its triangles'
    /// corners and their mean distance from it; `None` where the region has
    /// no triangles or no size, or is no eyeball.
    fn of(model: &HeadModel, neutral: &[Vec3], region: Region) -> Option<Eyeball> {
        let mut corners: Vec<u32> = model
            .triangles
            .iter()
            .zip(&model.triangle_regions)
            .filter(|(_, r)| **r == region)
            .flat_map(|(t, _)| *t)
            .collect();
        corners.sort_unstable();
        corners.dedup();
        let points: Vec<DVec3> = corners
            .iter()
            .map(|&v| neutral[v as usize].as_dvec3())
            .collect();
        if points.is_empty() {
            return None;
        }
        let centre = points.iter().sum::<DVec3>() / points.len() as f64;
        let radius = points.iter().map(|p| p.distance(centre)).sum::<f64>() / points.len() as f64;
        if !(radius.is_finite() && radius > 0.0) {
            return None;
        }
        let lids = region.anchor_regions()?;
        let near = (0..model.triangles.len())
            .zip(&model.triangle_regions)
            .filter(|(_, other)| lids.contains(other))
            .filter(|&(t, _)| {
                let corners = model.triangles[t].map(|v| neutral[v as usize].as_dvec3());
                let middle = corners.iter().sum::<DVec3>() / 3.0;
                let reach = corners
                    .iter()
                    .map(|c| c.distance(middle))
                    .fold(0.0, f64::max);
                middle.distance(centre) - reach < 2.0 * radius
            })
            .map(|(t, _)| t)
            .collect();
        Some(Eyeball {
            region,
            radius,
            near,
        })
    }

    /// The nearest triangle in front of `point` along +z (out of the face),
    /// within one radius of the eyeball, where one also lies in front of it
    /// along each of the directions turned [`COVER_YAW_DEG`] either way.
    fn cover(&self, model: &HeadModel, neutral: &[Vec3], point: Vec3) -> Option<u32> {
        let origin = point.as_dvec3();
        let hits = |direction: DVec3| {
            self.near.iter().filter_map(move |&t| {
                let [a, b, c] = model.triangles[t].map(|v| neutral[v as usize].as_dvec3());
                ray_hit(origin, direction, [a, b, c])
                    .filter(|&d| d <= self.radius)
                    .map(|d| (d, t))
            })
        };
        let yaw = COVER_YAW_DEG.to_radians();
        let turned = [-yaw, yaw].map(|a| DVec3::new(a.sin(), 0.0, a.cos()));
        if turned.iter().any(|&d| hits(d).next().is_none()) {
            return None;
        }
        hits(DVec3::Z)
            .min_by(|x, y| x.0.total_cmp(&y.0))
            .map(|(_, t)| t as u32)
    }
}

/// The distance along the unit `direction` from `origin` at which the ray
/// meets triangle `[a, b, c]` (Möller–Trumbore), if it does at or past the
/// origin; `None` for a ray in the triangle's plane and a degenerate
/// triangle.
fn ray_hit(origin: DVec3, direction: DVec3, [a, b, c]: [DVec3; 3]) -> Option<f64> {
    let (e1, e2) = (b - a, c - a);
    let p = direction.cross(e2);
    let det = e1.dot(p);
    let scale = e1.length() * e2.length();
    // False for a NaN determinant or scale too.
    let meets_plane = det.abs() > 1e-12 * scale;
    if !meets_plane {
        return None;
    }
    let to_origin = origin - a;
    let u = to_origin.dot(p) / det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = to_origin.cross(e1);
    let v = direction.dot(q) / det;
    let inside = v >= 0.0 && u + v <= 1.0;
    if !inside {
        return None;
    }
    let d = e2.dot(q) / det;
    (d >= 0.0).then_some(d)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRIANGLE: [DVec3; 3] = [
        DVec3::new(-1.0, -1.0, 1.0),
        DVec3::new(1.0, -1.0, 1.0),
        DVec3::new(0.0, 1.0, 1.0),
    ];

    #[test]
    fn a_ray_meets_a_triangle_in_front_and_not_one_behind_or_beside() {
        let hit = ray_hit(DVec3::ZERO, DVec3::Z, TRIANGLE).unwrap();
        assert!((hit - 1.0).abs() < 1e-12, "{hit}");
        assert_eq!(ray_hit(DVec3::new(0.0, 0.0, 2.0), DVec3::Z, TRIANGLE), None);
        assert_eq!(ray_hit(DVec3::new(3.0, 0.0, 0.0), DVec3::Z, TRIANGLE), None);
        // On an edge and at a corner the triangle counts.
        assert!(ray_hit(DVec3::new(0.0, -1.0, 0.0), DVec3::Z, TRIANGLE).is_some());
        assert!(ray_hit(DVec3::new(1.0, -1.0, 0.0), DVec3::Z, TRIANGLE).is_some());
    }

    #[test]
    fn a_ray_along_a_triangle_or_through_a_degenerate_one_meets_nothing() {
        assert_eq!(
            ray_hit(DVec3::new(0.0, -2.0, 1.0), DVec3::Y, TRIANGLE),
            None
        );
        let sliver = [DVec3::ZERO, DVec3::X, DVec3::new(2.0, 0.0, 1e-20)];
        assert_eq!(ray_hit(DVec3::new(0.5, 0.0, -1.0), DVec3::Z, sliver), None);
        let point = [DVec3::Z; 3];
        assert_eq!(ray_hit(DVec3::ZERO, DVec3::Z, point), None);
        let huge = TRIANGLE.map(|p| p * 1e30);
        let hit = ray_hit(DVec3::ZERO, DVec3::Z, huge).unwrap();
        assert!((hit / 1e30 - 1.0).abs() < 1e-9, "{hit}");
        assert_eq!(ray_hit(DVec3::NAN, DVec3::Z, TRIANGLE), None);
    }
}
