//! Region membership by place (docs/method.md §5.1): the region a Gaussian of
//! a trained source counts for is the region of the surface it sits on, not
//! only the region of its parent triangle. Training moves Gaussians: densified
//! children keep their parent's triangle wherever they drift. Swapping regions
//! by parent triangle then carries another person's Gaussians into a region
//! (thesis §7.2, Figure 6.8) — part of the composite's leak. The same
//! nearest triangles say which triangle's reshaping such a Gaussian follows
//! (`anchor = "nearest"`, method §6.8).

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use crate::avatar::binding::{triangle_frames, TriangleFrame};
use crate::avatar::gaussians::GaussianSet;
use crate::model::head::HeadModel;
use crate::model::nearest::{barycentric, TriangleGrid};

use super::lids::triangles_over_eyeballs;

/// How much nearer (metres of template space) another region's surface must
/// be to a Gaussian's centre than its parent triangle for it to count there:
/// Gaussians on or near their own triangle keep its region, so a Gaussian on
/// a border does not flicker between two regions.
pub const PLACE_MARGIN: f32 = 1e-3;

/// How much nearer (metres of template space) another triangle must be to a
/// Gaussian's centre than its parent for the Gaussian to follow that
/// triangle's reshaping (`anchor = "nearest"`, docs/method.md §6.8): a
/// Gaussian on its own triangle, to rounding, keeps its parent.
pub const ANCHOR_MARGIN: f32 = 1e-4;

/// The triangle each Gaussian of `set` counts for by place, on the source's
/// `neutral` mesh: the triangle nearest its centre when that is another
/// region's and more than [`PLACE_MARGIN`] nearer than its parent triangle,
/// otherwise its parent — except that a Gaussian so counted for an eyeball
/// with its lid in front of it counts for the lid
/// ([`triangles_over_eyeballs`]). Gaussians with a non-finite centre (or a
/// binding past the mesh) keep their parent.
pub fn place_triangles(model: &HeadModel, set: &GaussianSet, neutral: &[Vec3]) -> Vec<u32> {
    let regions = &model.triangle_regions;
    let mut places = nearer_triangles(model, set, neutral, PLACE_MARGIN, |parent, t| {
        regions.get(parent as usize) != regions.get(t as usize)
    });
    let lids = triangles_over_eyeballs(model, set, neutral, &places);
    for (place, lid) in places.iter_mut().zip(lids) {
        if let Some(lid) = lid {
            *place = lid;
        }
    }
    places
}

/// The triangle whose reshaping each Gaussian of `set` follows under
/// `anchor = "nearest"`: the triangle of the source's `neutral` mesh nearest
/// its centre when that is more than [`ANCHOR_MARGIN`] nearer than its
/// parent, otherwise its parent. Gaussians with a non-finite centre (or a
/// binding past the mesh) keep their parent.
pub fn anchor_triangles(model: &HeadModel, set: &GaussianSet, neutral: &[Vec3]) -> Vec<u32> {
    nearer_triangles(model, set, neutral, ANCHOR_MARGIN, |_, _| true)
}

/// Per Gaussian of `set`: the triangle of `neutral` nearest its centre when
/// `accept(parent, nearest)` and it is more than `margin` nearer than the
/// parent triangle, otherwise the parent.
fn nearer_triangles(
    model: &HeadModel,
    set: &GaussianSet,
    neutral: &[Vec3],
    margin: f32,
    accept: impl Fn(u32, u32) -> bool + Sync,
) -> Vec<u32> {
    let frames = triangle_frames(neutral, &model.triangles);
    let grid = TriangleGrid::new(neutral, &model.triangles);
    (0..set.len())
        .into_par_iter()
        .map(|i| {
            let parent = set.binding[i];
            let Some(centre) = neutral_centre(&frames, set, i) else {
                return parent;
            };
            // Within the margin of its parent nothing can be a margin nearer:
            // most Gaussians of a trained source stop here.
            let to_parent = grid.distance(parent, centre);
            if to_parent.is_nan() || to_parent <= margin {
                return parent;
            }
            match grid.nearest_within(centre, to_parent - margin) {
                Some((t, d)) if accept(parent, t) && to_parent > d + margin => t,
                _ => parent,
            }
        })
        .collect()
}

/// How far out, in standard deviations, a Gaussian's footprint is looked at
/// ([`footprint_triangles`]): two hold 95 % of its weight along an axis.
pub const FOOTPRINT_SIGMAS: f32 = 2.0;

/// How many of a Gaussian's four footprint points must lie over one other
/// source's triangles for a colour seam to give it that source's colour
/// there (docs/method.md §7.8).
pub const FOOTPRINT_MAJORITY: usize = 3;

/// Where each Gaussian of `set` paints (docs/method.md §7.8): the triangles of
/// the source's `neutral` mesh nearest the four points [`FOOTPRINT_SIGMAS`]
/// standard deviations out either way along its two longest axes, at the
/// size training gave it. `u32::MAX` for a point no triangle is near, and for every
/// point of a Gaussian whose centre, scale or rotation is not finite (or
/// whose binding is past the mesh).
pub fn footprint_triangles(
    model: &HeadModel,
    set: &GaussianSet,
    neutral: &[Vec3],
) -> Vec<[u32; 4]> {
    let frames = triangle_frames(neutral, &model.triangles);
    let grid = TriangleGrid::new(neutral, &model.triangles);
    (0..set.len())
        .into_par_iter()
        .map(|i| {
            let mut points = [u32::MAX; 4];
            let (Some(frame), Some(centre)) = (
                frames.get(set.binding[i] as usize),
                neutral_centre(&frames, set, i),
            ) else {
                return points;
            };
            let deviation = frame.scale * set.log_scale[i].exp();
            let turn = frame.rotation * Mat3::from_quat(set.rotation[i].normalize());
            if !(centre.is_finite() && deviation.is_finite() && turn.is_finite()) {
                return points;
            }
            let mut axes = [
                deviation.x * turn.x_axis,
                deviation.y * turn.y_axis,
                deviation.z * turn.z_axis,
            ];
            axes.sort_by(|a, b| b.length_squared().total_cmp(&a.length_squared()));
            let outs = [axes[0], -axes[0], axes[1], -axes[1]];
            for (point, out) in points.iter_mut().zip(outs) {
                if let Some((t, _)) = grid.nearest(centre + FOOTPRINT_SIGMAS * out) {
                    *point = t;
                }
            }
            points
        })
        .collect()
}

/// Where each Gaussian of `set` sits on the triangle it counts for
/// (`counted`, one per Gaussian): barycentric coordinates of its centre's
/// projection onto that triangle of the source's `neutral` mesh, clamped into
/// it. Gaussians with a non-finite centre sit at the centroid.
pub fn placements(
    model: &HeadModel,
    set: &GaussianSet,
    neutral: &[Vec3],
    counted: &[u32],
) -> Vec<[f32; 3]> {
    let frames = triangle_frames(neutral, &model.triangles);
    (0..set.len())
        .into_par_iter()
        .map(|i| {
            let centroid = [1.0 / 3.0; 3];
            let (Some(centre), Some(tri)) = (
                neutral_centre(&frames, set, i),
                model.triangles.get(counted[i] as usize),
            ) else {
                return centroid;
            };
            if !centre.is_finite() {
                return centroid;
            }
            let [a, b, c] = tri.map(|v| neutral[v as usize]);
            barycentric(centre, a, b, c)
        })
        .collect()
}

/// Gaussian `i`'s centre on the mesh whose triangle `frames` are given
/// (`None` for a binding past the mesh).
fn neutral_centre(frames: &[TriangleFrame], set: &GaussianSet, i: usize) -> Option<Vec3> {
    Some(
        frames
            .get(set.binding[i] as usize)?
            .to_world(set.position[i]),
    )
}
