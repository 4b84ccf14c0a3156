//! Numbers for what the thesis showed only in pictures (Table 6.2): how much
//! the far side of a trained head shows through its face (*leak*), and how
//! opaque each face region's own Gaussians are over that region (*coverage*).

use glam::{DMat3, DVec3, Vec3};

use super::capture::visible_triangles;
use super::holes::Obscurer;
use super::model::{Render, Trainable, SH_STRIDE};
use super::project::TrainCamera;
use super::raster::Rasterizer;
use crate::avatar::binding::triangle_frames;
use crate::model::head::HeadModel;
use crate::model::regions::Group;
use crate::render::sh::C0;

/// The groups a composite swaps behind the face: recoloured to measure leak.
pub const FAR_SIDE: [Group; 3] = [Group::Hair, Group::Neck, Group::Ears];

/// The groups whose coverage is reported.
pub const COVERED: [Group; 4] = [Group::Face, Group::Nose, Group::Eyes, Group::Mouth];

/// The colour the far side is repainted with (a saturated green no skin has).
pub const LEAK_COLOUR: [f64; 3] = [0.0, 1.0, 0.0];

/// Pixels next to the face's outline left out of the leak: there the far
/// side's Gaussians lie in front of the face (hair over the forehead), which
/// is no show-through.
pub const BORDER_PX: u32 = 2;

/// Degrees the coverage views are turned beyond the training views.
pub const BEYOND_DEG: f64 = 30.0;

/// Longest image side the hole metrics render at.
pub const METRIC_SIDE: u32 = 128;

/// Leak and coverage of one avatar.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HoleMetrics {
    /// Mean CIELAB ΔE (CIE76) over the face's pixels (those at least
    /// [`BORDER_PX`] inside its outline) between the avatar as trained and
    /// with its far side repainted.
    pub leak_delta_e: f64,
    /// PSNR between the same two renders over the same pixels (100 at most).
    pub leak_psnr_db: f64,
    /// Per covered group: mean accumulated opacity of its own Gaussians over
    /// the pixels its triangles show, from the training views.
    pub coverage: Vec<(Group, f64)>,
    /// The same from the training views turned ±[`BEYOND_DEG`] about the
    /// vertical axis through the head.
    pub coverage_beyond: Vec<(Group, f64)>,
}

/// Hole metrics as reported: leak, and coverage on average and per group.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HoleSummary {
    /// [`HoleMetrics::leak_delta_e`].
    pub leak_delta_e: f64,
    /// [`HoleMetrics::leak_psnr_db`].
    pub leak_psnr_db: f64,
    /// Mean coverage over the covered groups, training views.
    pub coverage: f64,
    /// The same from the turned views.
    pub coverage_beyond: f64,
    /// Coverage per group name, training views.
    pub coverage_by_group: std::collections::BTreeMap<&'static str, f64>,
    /// Coverage per group name, turned views.
    pub coverage_beyond_by_group: std::collections::BTreeMap<&'static str, f64>,
}

impl HoleMetrics {
    /// The figures as reported.
    pub fn summary(&self) -> HoleSummary {
        let by_group = |c: &[(Group, f64)]| c.iter().map(|(g, v)| (g.name(), *v)).collect();
        let (coverage, coverage_beyond) = self.mean_coverage();
        HoleSummary {
            leak_delta_e: self.leak_delta_e,
            leak_psnr_db: self.leak_psnr_db,
            coverage,
            coverage_beyond,
            coverage_by_group: by_group(&self.coverage),
            coverage_beyond_by_group: by_group(&self.coverage_beyond),
        }
    }

    /// Mean coverage over the covered groups (training views, turned views).
    pub fn mean_coverage(&self) -> (f64, f64) {
        let mean =
            |c: &[(Group, f64)]| c.iter().map(|(_, v)| v).sum::<f64>() / c.len().max(1) as f64;
        (mean(&self.coverage), mean(&self.coverage_beyond))
    }
}

/// Measures `model` (bound to the full topology of `head`) posed as
/// `posed`, seen from `cameras`.
pub fn measure(
    model: &Trainable,
    head: &HeadModel,
    posed: &[Vec3],
    cameras: &[TrainCamera],
) -> HoleMetrics {
    let group_of = |t: u32| head.triangle_regions[t as usize].group();
    let frames = triangle_frames(posed, &head.triangles);
    let draw = |m: &Trainable, camera: &TrainCamera| {
        Render::new(
            m,
            &frames,
            camera,
            [0.0; 3],
            &Obscurer::None,
            &mut Rasterizer::Cpu,
        )
        .expect("the CPU rasteriser does not fail")
    };
    let repainted = repaint(model, |t| FAR_SIDE.contains(&group_of(t)), LEAK_COLOUR);
    let (mut delta_e, mut squared, mut pixels) = (0.0, 0.0, 0usize);
    for camera in cameras {
        let shown = visible_triangles(posed, &head.triangles, camera);
        let face: Vec<bool> = shown
            .iter()
            .map(|t| t.is_some_and(|t| !FAR_SIDE.contains(&group_of(t))))
            .collect();
        let inside = erode(&face, camera.size, BORDER_PX);
        let (a, b) = (draw(model, camera), draw(&repainted, camera));
        for p in (0..inside.len()).filter(|&p| inside[p]) {
            let (x, y) = (pixel(a.image(), p), pixel(b.image(), p));
            delta_e += (lab(x) - lab(y)).length();
            squared += (x - y).length_squared();
            pixels += 1;
        }
    }
    let mse = squared / (3 * pixels.max(1)) as f64;
    let leak_psnr_db = if mse > 0.0 {
        (10.0 * (1.0 / mse).log10()).min(100.0)
    } else {
        100.0
    };
    let pivot = head_centre(posed);
    let turned: Vec<TrainCamera> = cameras
        .iter()
        .flat_map(|c| [turn(c, pivot, BEYOND_DEG), turn(c, pivot, -BEYOND_DEG)])
        .collect();
    let coverage_from = |views: &[TrainCamera]| -> Vec<(Group, f64)> {
        // Which surface each pixel shows, per view: the same for every group.
        let shown_by_view: Vec<Vec<Option<u32>>> = views
            .iter()
            .map(|camera| visible_triangles(posed, &head.triangles, camera))
            .collect();
        COVERED
            .iter()
            .map(|&g| {
                let own = keep_bound(model, |t| group_of(t) == g);
                let (mut sum, mut count) = (0.0, 0usize);
                for (camera, shown) in views.iter().zip(&shown_by_view) {
                    let opacity = draw(&own, camera).opacity();
                    for (p, t) in shown.iter().enumerate() {
                        if t.is_some_and(|t| group_of(t) == g) {
                            sum += opacity[p];
                            count += 1;
                        }
                    }
                }
                (g, if count == 0 { 0.0 } else { sum / count as f64 })
            })
            .collect()
    };
    HoleMetrics {
        leak_delta_e: delta_e / pixels.max(1) as f64,
        leak_psnr_db,
        coverage: coverage_from(cameras),
        coverage_beyond: coverage_from(&turned),
    }
}

/// The pixels of `mask` whose whole (2r + 1)² neighbourhood is in it.
fn erode(mask: &[bool], size: [u32; 2], r: u32) -> Vec<bool> {
    let [w, h] = size.map(|s| s as i64);
    let r = r as i64;
    (0..mask.len())
        .map(|p| {
            let (x, y) = (p as i64 % w, p as i64 / w);
            (-r..=r).all(|dy| {
                (-r..=r).all(|dx| {
                    let (nx, ny) = (x + dx, y + dy);
                    (0..w).contains(&nx) && (0..h).contains(&ny) && mask[(ny * w + nx) as usize]
                })
            })
        })
        .collect()
}

/// A pixel of a row-major RGB image, clamped to [0, 1].
fn pixel(image: &[f64], p: usize) -> DVec3 {
    DVec3::new(image[p * 3], image[p * 3 + 1], image[p * 3 + 2]).clamp(DVec3::ZERO, DVec3::ONE)
}

/// CIELAB (D65) of an sRGB colour in [0, 1].
pub fn lab(srgb: DVec3) -> DVec3 {
    let linear = |c: f64| {
        if c <= 0.040_45 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let rgb = DVec3::new(linear(srgb.x), linear(srgb.y), linear(srgb.z));
    let to_xyz = DMat3::from_cols(
        DVec3::new(0.412_456_4, 0.212_672_9, 0.019_333_9),
        DVec3::new(0.357_576_1, 0.715_152_2, 0.119_192),
        DVec3::new(0.180_437_5, 0.072_175, 0.950_304_1),
    );
    let xyz = to_xyz * rgb / DVec3::new(0.950_47, 1.0, 1.088_83);
    let f = |t: f64| {
        if t > (6.0f64 / 29.0).powi(3) {
            t.cbrt()
        } else {
            t / (3.0 * (6.0f64 / 29.0).powi(2)) + 4.0 / 29.0
        }
    };
    let (fx, fy, fz) = (f(xyz.x), f(xyz.y), f(xyz.z));
    DVec3::new(116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz))
}

/// The model with the Gaussians on triangles `chosen` picks painted a flat
/// `colour` (SH DC only).
pub fn repaint(model: &Trainable, chosen: impl Fn(u32) -> bool, colour: [f64; 3]) -> Trainable {
    let mut out = model.clone();
    for (i, &b) in model.binding.iter().enumerate() {
        if chosen(b) {
            let sh = &mut out.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
            sh.fill(0.0);
            for ch in 0..3 {
                sh[ch] = (colour[ch] - 0.5) / C0;
            }
        }
    }
    out
}

/// The model with only the Gaussians on triangles `chosen` picks.
fn keep_bound(model: &Trainable, chosen: impl Fn(u32) -> bool) -> Trainable {
    let mut out = Trainable {
        sh_degree: model.sh_degree,
        ..Trainable::default()
    };
    for (i, &b) in model.binding.iter().enumerate() {
        if chosen(b) {
            out.binding.push(b);
            out.geometry.push(model.geometry[i]);
            out.opacity_logit.push(model.opacity_logit[i]);
            out.sh
                .extend_from_slice(&model.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE]);
        }
    }
    out
}

/// The centre of the posed head's bounding box.
pub fn head_centre(posed: &[Vec3]) -> DVec3 {
    let (low, high) = posed.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(l, h), v| (l.min(v.as_dvec3()), h.max(v.as_dvec3())),
    );
    0.5 * (low + high)
}

/// A camera turned by `degrees` about the vertical (+y) axis through `pivot`.
pub fn turn(camera: &TrainCamera, pivot: DVec3, degrees: f64) -> TrainCamera {
    let rotation = DMat3::from_rotation_y(degrees.to_radians());
    let c2w = camera.c2w();
    let column = |k: usize| DVec3::new(c2w[0][k], c2w[1][k], c2w[2][k]);
    let axes = [0, 1, 2].map(|k| rotation * column(k));
    let eye = pivot + rotation * (column(3) - pivot);
    let turned = [
        [axes[0].x, axes[1].x, axes[2].x, eye.x],
        [axes[0].y, axes[1].y, axes[2].y, eye.y],
        [axes[0].z, axes[1].z, axes[2].z, eye.z],
        [0.0, 0.0, 0.0, 1.0],
    ];
    TrainCamera::from_c2w(turned, camera.focal, camera.principal, camera.size)
}

/// The camera with its image scaled to at most `side` pixels on its longer
/// edge (intrinsics scaled with it).
pub fn at_most(camera: &TrainCamera, side: u32) -> TrainCamera {
    let longest = camera.size[0].max(camera.size[1]);
    if longest <= side {
        return *camera;
    }
    let k = side as f64 / longest as f64;
    let size = camera.size.map(|s| ((s as f64 * k).round() as u32).max(1));
    TrainCamera::from_c2w(
        camera.c2w(),
        camera.focal.map(|f| f * k),
        camera.principal.map(|c| c * k),
        size,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CIELAB of known colours (white, black, sRGB red and mid grey).
    #[test]
    fn lab_of_known_colours() {
        let close = |a: DVec3, b: DVec3| (a - b).length() < 0.05;
        assert!(
            close(lab(DVec3::ONE), DVec3::new(100.0, 0.0, 0.0)),
            "{}",
            lab(DVec3::ONE)
        );
        assert!(close(lab(DVec3::ZERO), DVec3::ZERO));
        assert!(
            close(
                lab(DVec3::new(1.0, 0.0, 0.0)),
                DVec3::new(53.24, 80.09, 67.20)
            ),
            "{}",
            lab(DVec3::new(1.0, 0.0, 0.0))
        );
        assert!(close(lab(DVec3::splat(0.5)), DVec3::new(53.39, 0.0, 0.0)));
        // Near-black stays finite and ordered.
        assert!(lab(DVec3::splat(1e-6)).x > 0.0 && lab(DVec3::splat(1e-6)).x < 0.01);
    }

    /// The metrics move the way a user expects: a built-in avatar with its
    /// face Gaussians made faint leaks more of its repainted far side and
    /// covers its face less than the avatar as built.
    #[test]
    fn a_fainter_face_leaks_more_and_covers_less() {
        let db = crate::avatar::synthetic::builtin_database(
            crate::model::builtin::build_head(),
            crate::avatar::synthetic::SyntheticOptions {
                seed: 1,
                sources: 1,
                gaussians_per_avatar: 4000,
            },
        )
        .unwrap();
        let (head, source) = (&db.model, &db.sources[0]);
        let posed = source.neutral(head);
        let (cameras, _) = crate::train::capture::rig(4, false, [48, 48]);
        let solid = Trainable::from_set(&source.gaussians);
        let mut faint = solid.clone();
        for (i, &b) in solid.binding.iter().enumerate() {
            if !FAR_SIDE.contains(&head.triangle_regions[b as usize].group()) {
                faint.opacity_logit[i] = -1.5;
            }
        }
        let (a, b) = (
            measure(&solid, head, &posed, &cameras),
            measure(&faint, head, &posed, &cameras),
        );
        assert!(b.leak_delta_e > a.leak_delta_e + 1.0, "{a:?}\n{b:?}");
        assert!(b.leak_psnr_db < a.leak_psnr_db, "{a:?}\n{b:?}");
        assert!(
            b.mean_coverage().0 < a.mean_coverage().0 - 0.02,
            "{a:?}\n{b:?}"
        );
        for m in [&a, &b] {
            assert!(m
                .coverage
                .iter()
                .chain(&m.coverage_beyond)
                .all(|(_, c)| (0.0..=1.0).contains(c)));
        }
    }

    /// A camera turned a full circle is where it was; turned 90° about a
    /// pivot in front of it, it looks at the pivot from the side.
    #[test]
    fn turned_cameras_circle_the_pivot() {
        let (cameras, _) = crate::train::capture::rig(2, false, [32, 32]);
        let c = cameras[0];
        let back = turn(&c, DVec3::new(0.0, 0.0, 0.1), 360.0);
        for (a, b) in c.eye.iter().zip(back.eye) {
            assert!((a - b).abs() < 1e-9);
        }
        let pivot = DVec3::new(0.0, 0.0, 0.1);
        let side = turn(&c, pivot, 90.0);
        let distance = |e: [f64; 3]| (DVec3::from(e) - pivot).length();
        assert!((distance(side.eye) - distance(c.eye)).abs() < 1e-9);
        let small = at_most(&c, 16);
        assert_eq!(small.size, [16, 16]);
        assert!((small.focal[0] - c.focal[0] / 2.0).abs() < 1e-9);
    }
}
