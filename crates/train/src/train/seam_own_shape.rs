//! A seam fit's targets drawn where each person's Gaussians were trained
//! (method §7.12, "Drawn on their own face").
//!
//! A whole head's Gaussians sit on the composite's shape, which may not be
//! their person's: there their detail lands a little off the surface point
//! it belongs to (trained Gaussians lie inside the surface, so a reshaped
//! triangle carries them along a path the surface does not take), and the
//! fit would learn that misplacement back. So each person's part of a
//! whole is drawn a second time on that person's own face, posed alike, and
//! each pixel of the composite's view takes what the own-face drawing shows
//! at the same surface point (triangle and barycentric point), where that
//! point is visible there; elsewhere it keeps the drawing on the
//! composite's shape.

use glam::{DVec3, Vec3};

use crate::avatar::binding::triangle_frames_into;
use crate::compose::engine::{Composite, Engine, PosedMesh};
use crate::compose::recipe::{Anchor, Deform, ResolvedRecipe, Shading};
use crate::model::head::{HeadModel, Pose};
use crate::model::regions::Region;

use super::capture::pixel_of;
use super::project::TrainCamera;

/// How far (metres, along the view) a point may lie from the surface its
/// own-face drawing shows at a pixel and still count as that surface: a few
/// millimetres, far under what a nose or a lid in front of it puts there,
/// plus [`SAME_SURFACE_PX`] pixels' width at its depth (a slanted surface
/// changes depth across the pixels read round the point).
const SAME_SURFACE_M: f64 = 0.004;
/// See [`SAME_SURFACE_M`].
const SAME_SURFACE_PX: f64 = 3.0;

/// The recipe a whole is drawn with on its people's own faces: the light
/// as trained, each Gaussian on its parent triangle as trained (on its own
/// face a person's Gaussians need no reshaping).
pub(super) fn own_face_recipe(recipe: &ResolvedRecipe) -> ResolvedRecipe {
    let mut out = recipe.clone();
    out.post.shading = Shading::Kept;
    out.post.deform = Deform::Similarity;
    out.post.anchor = Anchor::Parent;
    out
}

/// Person `source`'s own neutral posed at `pose` (no expression), as the
/// rig poses the composite.
pub(super) fn posed_own_face(engine: &Engine, source: usize, pose: &Pose) -> PosedMesh {
    let model = &engine.database().model;
    let mut out = PosedMesh::default();
    let expression = vec![0.0; model.expression_basis.len()];
    model.pose_offset(
        engine.source_neutral(source),
        &expression,
        pose,
        None,
        &mut out.vertices,
    );
    triangle_frames_into(&out.vertices, &model.triangles, &mut out.frames);
    out
}

/// Whether the composite's shape differs from `source`'s own neutral
/// anywhere (by more than a micrometre) once moved as a whole — a blend
/// of one person's shape alone is that shape moved to the base's pinned
/// vertex: where it does not, the drawing on the composite's shape is
/// already the own-face one.
pub(super) fn reshaped(engine: &Engine, composite: &Composite, source: usize) -> bool {
    let own = engine.source_neutral(source);
    let (Some(a), Some(b)) = (own.first(), composite.neutral.first()) else {
        return own.len() != composite.neutral.len();
    };
    let shift = *b - *a;
    own.len() != composite.neutral.len()
        || own.iter().zip(&composite.neutral).any(|(a, b)| {
            let d = (*a + shift - *b).length_squared();
            // A non-finite vertex counts as changed.
            d > 1e-12 || d.is_nan()
        })
}

/// What a pixel of the composite's view shows: triangle, barycentric point
/// and view depth (`capture::rasterize`).
pub(super) type Hit = Option<(u32, [f32; 3], f64)>;

/// One person's part of a whole drawn in a view.
pub(super) struct Drawing {
    /// Its colour, RGB per pixel (`KeptWhole::part`).
    pub(super) colour: Vec<f64>,
    /// How much of each pixel its Gaussians show, RGB per pixel
    /// (`KeptWhole::coverage`).
    pub(super) coverage: Vec<f64>,
}

/// Below this coverage a part's drawing (on its person's own face, or on
/// the composite's shape) shows too little of its person at a point to
/// take a colour per unit of coverage from.
const MIN_COVERAGE: f64 = 0.05;

/// `here`'s colour (a part drawn on the composite's shape, per pixel of
/// `hits`) with each pixel that shows a surface point given the colour that
/// `there` (the same part drawn on its person's own face `own`, whose
/// surface the camera sees as `own_hits`) shows at that point per unit of
/// its coverage, times `here`'s coverage: the share of the pixel the part
/// has on the composite stays, and its colour comes from where its
/// Gaussians were trained. The point's own-face pixels are read with
/// Catmull-Rom's cubic, where every pixel the cubic weighs round it
/// shows the own face within [`SAME_SURFACE_M`] of the point's depth and
/// the nearest one
/// shows the point's triangle or one touching it (the point is in view and
/// not at a silhouette or behind a fold there), and the part covers at
/// least [`MIN_COVERAGE`] of it.
pub(super) fn reprojected(
    model: &HeadModel,
    camera: &TrainCamera,
    hits: &[Hit],
    own: &[Vec3],
    own_hits: &[Hit],
    there: &Drawing,
    here: &Drawing,
) -> Vec<f64> {
    let mut out = here.colour.clone();
    let [w, h] = camera.size.map(|v| v as usize);
    for (p, hit) in hits.iter().enumerate() {
        let Some((t, bary, _)) = hit else { continue };
        let corners = model.triangles[*t as usize];
        let point: DVec3 = corners
            .iter()
            .zip(bary)
            .map(|(&v, &b)| own[v as usize].as_dvec3() * f64::from(b))
            .sum();
        let Some([x, y, depth]) = pixel_of(camera, point) else {
            continue;
        };
        // Pixel centres lie at half-integers.
        let (fx, fy) = (x - 0.5, y - 0.5);
        let Some(taps) = taps(fx, fy, w, h) else {
            continue;
        };
        let tolerance = SAME_SURFACE_M + SAME_SURFACE_PX * depth / camera.focal[0];
        let seen = taps
            .iter()
            .all(|&(k, _)| own_hits[k].is_some_and(|(_, _, d)| (d - depth).abs() <= tolerance));
        // The nearest pixel shows the point's own triangle or one touching
        // it: a fold of an ear within a few millimetres is another surface.
        let nearest = (fy.round().max(0.0) as usize).min(h - 1) * w
            + (fx.round().max(0.0) as usize).min(w - 1);
        let touching = own_hits[nearest].is_some_and(|(u, _, _)| {
            let other = model.triangles[u as usize];
            u == *t || other.iter().any(|v| corners.contains(v))
        });
        if !seen || !touching {
            continue;
        }
        // Unclamped: the cubic's overshoot at an edge is the sharpness a
        // render there has (held within the values it reads, the bench lost
        // 0.004 dB).
        let read = |image: &[f64], c: usize| -> f64 {
            taps.iter().map(|&(k, a)| a * image[3 * k + c]).sum()
        };
        for c in 0..3 {
            let coverage = read(&there.coverage, c);
            if coverage >= MIN_COVERAGE {
                out[3 * p + c] = here.coverage[3 * p + c] * read(&there.colour, c) / coverage;
            }
        }
    }
    out
}

/// One person's part of a whole drawn in a view, as a target takes it.
pub(super) struct Part {
    /// The person (database index of the source).
    pub(super) person: usize,
    /// Its colour, RGB per pixel: read from the person's own face where
    /// [`reprojected`] could.
    pub(super) colour: Vec<f64>,
    /// How much of each pixel the part covers on the composite's shape,
    /// RGB per pixel; `None` where the part was not drawn on its person's
    /// own face (the composite leaves that face as it is), and its
    /// coverage was not drawn either.
    pub(super) coverage: Option<Vec<f64>>,
}

/// `parts` of a whole from `source`, with each pixel of `hits` that shows
/// an eyeball drawn by `source`'s part alone, at its colour per unit of its
/// coverage there: the other parts there — the base's lid skin under
/// `skin = "base"`, trained round the base's own eyes — hang over an
/// eyeball of another shape, which the person shows where the lids' own
/// surface does not cover it (dark-base-light-eyes, ada's eyes on nuru's
/// face: its targets' eyeballs 0.05 too dark). A whole of one person
/// shows its eyeballs at full coverage too, as the truth does. Only where
/// `source`'s part was drawn on its own face (its coverage known) and
/// covers at least [`MIN_COVERAGE`] of the pixel.
pub(super) fn eyeballs_by_their_source(
    model: &HeadModel,
    hits: &[Hit],
    source: usize,
    parts: &mut [Part],
) {
    let Some(own) = parts.iter().position(|p| p.person == source) else {
        return;
    };
    let Some(coverage) = parts[own].coverage.take() else {
        return;
    };
    for (p, hit) in hits.iter().enumerate() {
        let Some((t, _, _)) = hit else { continue };
        let region = model.triangle_regions[*t as usize];
        if !matches!(region, Region::LeftEyeball | Region::RightEyeball) {
            continue;
        }
        let share: [f64; 3] = std::array::from_fn(|c| coverage[3 * p + c]);
        if share.iter().any(|&c| c.is_nan() || c < MIN_COVERAGE) {
            continue;
        }
        for (k, part) in parts.iter_mut().enumerate() {
            let pixel = &mut part.colour[3 * p..3 * p + 3];
            for (value, share) in pixel.iter_mut().zip(share) {
                *value = if k == own { *value / share } else { 0.0 };
            }
        }
    }
    parts[own].coverage = Some(coverage);
}

/// The pixels and weights that read an image at continuous pixel position
/// (`fx`, `fy`) (pixel centres at integers): Catmull-Rom's cubic, which
/// keeps detail a bilinear read blurs, each pixel with a weight other
/// than zero; `None` where its 4×4 pixels leave the image (or a coordinate
/// is not a number).
fn taps(fx: f64, fy: f64, w: usize, h: usize) -> Option<Vec<(usize, f64)>> {
    let (x0, y0) = (fx.floor(), fy.floor());
    let inside = x0 >= 1.0 && y0 >= 1.0 && x0 + 2.0 < w as f64 && y0 + 2.0 < h as f64;
    if !inside {
        return None;
    }
    let (wx, wy) = (catmull_rom(fx - x0), catmull_rom(fy - y0));
    let (x0, y0) = (x0 as usize - 1, y0 as usize - 1);
    let mut out = Vec::with_capacity(16);
    for (j, &b) in wy.iter().enumerate() {
        for (i, &a) in wx.iter().enumerate() {
            if a * b != 0.0 {
                out.push(((y0 + j) * w + x0 + i, a * b));
            }
        }
    }
    Some(out)
}

/// Catmull-Rom's weights of the four samples at −1, 0, 1, 2 for a point
/// `t` ∈ [0, 1) past the second; they sum to one.
fn catmull_rom(t: f64) -> [f64; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin::build_head;
    use crate::train::capture::{rasterize, rig};

    /// A source's Gaussians composed for its own face from a recipe that
    /// puts them on another's are exactly those of the recipe that keeps
    /// its shape: on its own face nothing is reshaped or relit.
    #[test]
    fn on_its_own_face_a_source_s_whole_is_as_trained() {
        use crate::train::seam_test_people::{base_on_the_others_face, name_of, ours, two_people};

        let engine = two_people(3_000);
        let resolve =
            |recipe: crate::compose::recipe::Recipe| recipe.resolve(engine.database()).unwrap();
        let elsewhere = resolve(base_on_the_others_face(&engine));
        let mut own = resolve(ours(&format!("base = \"{}\"\n", name_of(&engine, 0))));
        own.post.shading = Shading::Kept;
        let composite = engine.compose(&elsewhere);
        assert!(reshaped(&engine, &composite, 0) && !reshaped(&engine, &engine.compose(&own), 0));
        let as_trained = engine.compose(&own).gaussians;
        let drawn = engine.compose(&own_face_recipe(&elsewhere)).gaussians;
        assert_eq!(drawn.len(), as_trained.len());
        assert_eq!(drawn.binding, as_trained.binding);
        assert_eq!(drawn.position, as_trained.position);
        assert_eq!(drawn.rotation, as_trained.rotation);
        assert_eq!(drawn.log_scale, as_trained.log_scale);
        assert_eq!(drawn.opacity_logit, as_trained.opacity_logit);
        assert_eq!(drawn.sh, as_trained.sh);
        // The recipe's own composite moved them: there is something to undo.
        assert_ne!(composite.gaussians.position, as_trained.position);
    }

    #[test]
    fn catmull_rom_passes_through_its_samples_and_keeps_a_ramp() {
        assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
        for k in 0..=10 {
            let t = f64::from(k) / 10.0;
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            // Samples of x at −1, 0, 1, 2 read back x = t.
            let ramp: f64 = w
                .iter()
                .zip([-1.0, 0.0, 1.0, 2.0])
                .map(|(a, x)| a * x)
                .sum();
            assert!((ramp - t).abs() < 1e-12, "{t}: {ramp}");
        }
    }

    /// The head's template seen by one camera of a 128×96 rig (not square,
    /// so rows and columns cannot be swapped unseen), with its hits.
    fn scene() -> (HeadModel, TrainCamera, Vec<Hit>) {
        let model = build_head();
        let (cameras, _) = rig(3, false, [128, 96]);
        let camera = cameras[1];
        let hits = rasterize(&model.template, &model.triangles, &camera);
        (model, camera, hits)
    }

    /// Each pixel's red is its centre's x and its green its centre's y:
    /// what a read at a point gives back is where the point lies.
    fn ramp(camera: &TrainCamera, coverage: f64) -> Drawing {
        let [w, h] = camera.size.map(|v| v as usize);
        let colour = (0..w * h)
            .flat_map(|k| [(k % w) as f64 + 0.5, (k / w) as f64 + 0.5, 0.0])
            .collect();
        Drawing {
            colour,
            coverage: vec![coverage; 3 * w * h],
        }
    }

    /// A drawing that no read gives: −1 everywhere, wholly covered.
    fn blank(camera: &TrainCamera) -> Drawing {
        let n = 3 * (camera.size[0] * camera.size[1]) as usize;
        Drawing {
            colour: vec![-1.0; n],
            coverage: vec![1.0; n],
        }
    }

    /// The pixels `out` read (not left at −1), each with the position it
    /// read (red, green).
    fn read(out: &[f64]) -> Vec<(usize, [f64; 2])> {
        (0..out.len() / 3)
            .filter(|&p| out[3 * p] != -1.0)
            .map(|p| (p, [out[3 * p], out[3 * p + 1]]))
            .collect()
    }

    #[test]
    fn an_eyeball_shows_its_own_person_alone() {
        let (model, _, hits) = scene();
        let region = |p: usize| hits[p].map(|(t, _, _)| model.triangle_regions[t as usize]);
        let eyeball = (0..hits.len())
            .find(|&p| matches!(region(p), Some(Region::LeftEyeball | Region::RightEyeball)))
            .expect("an eyeball in view");
        let skin = (0..hits.len())
            .find(|&p| region(p) == Some(Region::Skin))
            .expect("skin in view");
        let n = 3 * hits.len();
        // Person 1 (the eyes' source) covers 0.6 of each pixel at colour
        // 0.3, the base (0) the rest at 0.2.
        let parts = |coverage: f64| {
            vec![
                Part {
                    person: 0,
                    colour: vec![0.2; n],
                    coverage: Some(vec![0.4; n]),
                },
                Part {
                    person: 1,
                    colour: vec![0.3; n],
                    coverage: Some(vec![coverage; n]),
                },
            ]
        };
        let mut out = parts(0.6);
        eyeballs_by_their_source(&model, &hits, 1, &mut out);
        for c in 0..3 {
            assert!((out[1].colour[3 * eyeball + c] - 0.5).abs() < 1e-12);
            assert_eq!(out[0].colour[3 * eyeball + c], 0.0);
            // Elsewhere both show as drawn.
            assert_eq!(out[1].colour[3 * skin + c], 0.3);
            assert_eq!(out[0].colour[3 * skin + c], 0.2);
        }
        // Where the eyes' person barely covers the pixel, or its coverage
        // is unknown, or it is not in the whole, nothing changes.
        for coverage in [0.01, f64::NAN] {
            let mut bare = parts(coverage);
            eyeballs_by_their_source(&model, &hits, 1, &mut bare);
            assert_eq!(bare[0].colour, vec![0.2; n]);
            assert_eq!(bare[1].colour, vec![0.3; n]);
        }
        let mut unknown = parts(0.6);
        unknown[1].coverage = None;
        eyeballs_by_their_source(&model, &hits, 1, &mut unknown);
        assert_eq!(unknown[0].colour, vec![0.2; n]);
        assert_eq!(unknown[1].colour, vec![0.3; n]);
        let mut absent = parts(0.6);
        eyeballs_by_their_source(&model, &hits, 7, &mut absent);
        assert_eq!(absent[0].colour, vec![0.2; n]);
        assert_eq!(absent[1].colour, vec![0.3; n]);
    }

    #[test]
    fn a_face_on_its_own_shape_reads_back_its_own_pixels() {
        let (model, camera, hits) = scene();
        let out = reprojected(
            &model,
            &camera,
            &hits,
            &model.template,
            &hits,
            &ramp(&camera, 1.0),
            &blank(&camera),
        );
        let w = camera.size[0] as usize;
        let read = read(&out);
        for &(p, [x, y]) in &read {
            assert!(hits[p].is_some());
            let centre = [(p % w) as f64 + 0.5, (p / w) as f64 + 0.5];
            assert!(
                (x - centre[0]).abs() < 1e-3 && (y - centre[1]).abs() < 1e-3,
                "pixel {p}: read {x}, {y}"
            );
        }
        let head = hits.iter().filter(|h| h.is_some()).count();
        assert!(
            read.len() * 2 > head,
            "{} of {head} pixels read",
            read.len()
        );
    }

    #[test]
    fn a_moved_face_is_read_where_the_point_lies_on_it() {
        let (model, camera, hits) = scene();
        // Moved a pixel and a half along the camera's right and up axes.
        let distance = DVec3::from_array(camera.eye).length();
        let shift = (1.5 * distance / camera.focal[0]) as f32;
        let right = DVec3::from_array(camera.rotation[0]).as_vec3();
        let up = DVec3::from_array(camera.rotation[1]).as_vec3();
        let own: Vec<Vec3> = model
            .template
            .iter()
            .map(|&v| v + shift * (right + up))
            .collect();
        let own_hits = rasterize(&own, &model.triangles, &camera);
        let out = reprojected(
            &model,
            &camera,
            &hits,
            &own,
            &own_hits,
            &ramp(&camera, 1.0),
            &blank(&camera),
        );
        let w = camera.size[0] as usize;
        let read = read(&out);
        for &(p, [x, y]) in &read {
            let (t, bary, _) = hits[p].unwrap();
            let point: DVec3 = model.triangles[t as usize]
                .iter()
                .zip(bary)
                .map(|(&v, b)| own[v as usize].as_dvec3() * f64::from(b))
                .sum();
            let [px, py, _] = pixel_of(&camera, point).unwrap();
            let centre = [(p % w) as f64 + 0.5, (p / w) as f64 + 0.5];
            assert!(
                px - centre[0] > 1.2 && centre[1] - py > 1.2,
                "pixel {p} moved too little"
            );
            assert!(
                (x - px).abs() < 1e-3 && (y - py).abs() < 1e-3,
                "pixel {p}: read {x}, {y} against {px}, {py}"
            );
        }
        assert!(read.len() > 100, "{} pixels read", read.len());
    }

    #[test]
    fn the_composite_keeps_its_share_and_hidden_or_bare_points_their_drawing() {
        let (model, camera, hits) = scene();
        let n = 3 * (camera.size[0] * camera.size[1]) as usize;
        let here = Drawing {
            colour: vec![-1.0; n],
            coverage: vec![0.25; n],
        };
        // Half covered there, a quarter here: a quarter of the colour there
        // per unit of cover.
        let out = reprojected(
            &model,
            &camera,
            &hits,
            &model.template,
            &hits,
            &ramp(&camera, 0.5),
            &here,
        );
        let p = (0..hits.len()).find(|&p| out[3 * p] != -1.0).unwrap();
        let x = (p % camera.size[0] as usize) as f64 + 0.5;
        assert!((out[3 * p] - 0.25 * x / 0.5).abs() < 1e-3);

        // Something 5 cm in front of every point of the own face, another
        // surface at the same depth (a fold: no triangle touching the
        // point's), or a part covering almost nothing there: the
        // composite's drawing stays.
        let hidden: Vec<Hit> = hits
            .iter()
            .map(|h| h.map(|(t, b, d)| (t, b, d - 0.05)))
            .collect();
        let far = model.triangles.len() as u32 / 2;
        let folded: Vec<Hit> = hits
            .iter()
            .map(|h| h.map(|(t, b, d)| ((t + far) % (2 * far), b, d)))
            .collect();
        let bare = ramp(&camera, 0.01);
        let whole = ramp(&camera, 1.0);
        for (own_hits, there) in [(&hidden, &whole), (&hits, &bare)] {
            let out = reprojected(
                &model,
                &camera,
                &hits,
                &model.template,
                own_hits,
                there,
                &here,
            );
            assert_eq!(out, here.colour);
        }
        let out = reprojected(
            &model,
            &camera,
            &hits,
            &model.template,
            &folded,
            &whole,
            &here,
        );
        let head = hits.iter().filter(|h| h.is_some()).count();
        assert!(read(&out).len() * 100 < head, "{} read", read(&out).len());
    }
}
