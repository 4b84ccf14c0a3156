//! The floater filter: which Gaussians of a trained scene to drop because
//! they cannot belong to it — broken (NaN/Inf), transparent, huge, or
//! isolated far from the scene's mass (the stray splats trainers leave in
//! empty space). Each Gaussian is judged by the first rule it fails, in that
//! order; isolation counts only Gaussians that passed the other rules, so a
//! cloud of transparent junk does not shelter a floater.
//!
//! Isolation is radius outlier removal with a radius the scene sets itself:
//! r = `isolation` × the median distance from a Gaussian to its
//! [`NEIGHBOURS`]-th nearest neighbour (estimated on at most
//! [`DENSITY_SAMPLES`] Gaussians), and a Gaussian with fewer than
//! [`NEIGHBOURS`] others within r is isolated. Dense and sparse scenes alike
//! keep their surfaces; a splat metres from anything goes.

use std::collections::HashMap;

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use super::splats::SplatScene;

/// Neighbours a Gaussian needs within the isolation radius.
pub const NEIGHBOURS: usize = 4;
/// Gaussians sampled to measure the scene's typical spacing.
pub const DENSITY_SAMPLES: usize = 4096;
/// Rings of cells searched for a sampled Gaussian's neighbours before it
/// counts as having none (it is then a floater itself).
const MAX_RINGS: i32 = 8;

/// What the filter removes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CleanOptions {
    /// Gaussians less opaque than this go (INRIA's trainer prunes below 0.005).
    pub min_opacity: f32,
    /// Gaussians whose largest standard deviation exceeds this share of the
    /// subject's diagonal ([`SplatScene::robust_bounds`]) go.
    pub huge: f32,
    /// The isolation radius in units of the typical spacing (see the module
    /// docs); 0 turns isolation off.
    pub isolation: f32,
}

impl Default for CleanOptions {
    fn default() -> Self {
        Self {
            min_opacity: 1.0 / 255.0,
            huge: 0.1,
            isolation: 10.0,
        }
    }
}

/// Why a Gaussian was removed, or that it stays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// It stays.
    Kept,
    /// A non-finite position, scale, rotation or opacity.
    Broken,
    /// Opacity below [`CleanOptions::min_opacity`].
    Transparent,
    /// Larger than [`CleanOptions::huge`] of the subject.
    Huge,
    /// Fewer than [`NEIGHBOURS`] others within the isolation radius.
    Isolated,
}

/// How many Gaussians each rule removed.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CleanCounts {
    /// Gaussians kept.
    pub kept: usize,
    /// Removed as broken.
    pub broken: usize,
    /// Removed as transparent.
    pub transparent: usize,
    /// Removed as huge.
    pub huge: usize,
    /// Removed as isolated.
    pub isolated: usize,
    /// The isolation radius used (scene units; 0 when isolation was off or
    /// the scene too small to measure).
    pub radius: f32,
}

/// Judges every Gaussian of `scene`.
pub fn judge(scene: &SplatScene, options: &CleanOptions) -> (Vec<Verdict>, CleanCounts) {
    let diagonal = scene
        .robust_bounds()
        .map_or(0.0, |(lo, hi)| (hi - lo).length());
    let mut verdicts: Vec<Verdict> = (0..scene.len())
        .map(|i| {
            let (p, s, q, o) = (
                scene.position[i],
                scene.scale[i],
                scene.rotation[i],
                scene.opacity[i],
            );
            if !(p.is_finite() && s.is_finite() && q.is_finite() && o.is_finite()) {
                Verdict::Broken
            } else if o < options.min_opacity {
                Verdict::Transparent
            } else if diagonal > 0.0 && s.max_element() > options.huge * diagonal {
                Verdict::Huge
            } else {
                Verdict::Kept
            }
        })
        .collect();
    let kept: Vec<u32> = (0..scene.len() as u32)
        .filter(|&i| verdicts[i as usize] == Verdict::Kept)
        .collect();
    let mut radius = 0.0;
    if options.isolation > 0.0 && kept.len() > NEIGHBOURS && diagonal > 0.0 {
        radius = options.isolation * typical_spacing(scene, &kept, diagonal);
        if radius.is_finite() && radius > 0.0 {
            let grid = PointGrid::new(scene, &kept, radius);
            let isolated: Vec<bool> = kept
                .par_iter()
                .map(|&i| grid.count_within(scene.position[i as usize], radius, i) < NEIGHBOURS)
                .collect();
            for (&i, lone) in kept.iter().zip(isolated) {
                if lone {
                    verdicts[i as usize] = Verdict::Isolated;
                }
            }
        } else {
            radius = 0.0;
        }
    }
    let mut counts = CleanCounts {
        radius,
        ..CleanCounts::default()
    };
    for v in &verdicts {
        match v {
            Verdict::Kept => counts.kept += 1,
            Verdict::Broken => counts.broken += 1,
            Verdict::Transparent => counts.transparent += 1,
            Verdict::Huge => counts.huge += 1,
            Verdict::Isolated => counts.isolated += 1,
        }
    }
    (verdicts, counts)
}

/// The scene with only the Gaussians judged [`Verdict::Kept`].
pub fn keep(scene: &SplatScene, verdicts: &[Verdict]) -> SplatScene {
    let mut out = SplatScene::with_degree(scene.sh_degree);
    for (i, v) in verdicts.iter().enumerate() {
        if *v == Verdict::Kept {
            out.push(
                scene.position[i],
                scene.rotation[i],
                scene.scale[i],
                scene.opacity[i],
                scene.sh_of(i),
            );
        }
    }
    out
}

/// The median distance from a sampled Gaussian of `kept` to its
/// [`NEIGHBOURS`]-th nearest other, on a grid of a 64th of the diagonal.
fn typical_spacing(scene: &SplatScene, kept: &[u32], diagonal: f32) -> f32 {
    let cell = diagonal / 64.0;
    let grid = PointGrid::new(scene, kept, cell);
    let step = kept.len().div_ceil(DENSITY_SAMPLES).max(1);
    let mut distances: Vec<f32> = kept
        .par_iter()
        .step_by(step)
        .map(|&i| grid.kth_nearest(scene.position[i as usize], NEIGHBOURS, i))
        .collect();
    distances.sort_by(f32::total_cmp);
    distances[distances.len() / 2]
}

/// Gaussian centres hashed into cubic cells.
struct PointGrid<'a> {
    positions: &'a [Vec3],
    cell: f32,
    cells: HashMap<IVec3, Vec<u32>>,
}

impl<'a> PointGrid<'a> {
    fn new(scene: &'a SplatScene, indices: &[u32], cell: f32) -> Self {
        let mut cells: HashMap<IVec3, Vec<u32>> = HashMap::new();
        for &i in indices {
            let key = Self::key(scene.position[i as usize], cell);
            cells.entry(key).or_default().push(i);
        }
        Self {
            positions: &scene.position,
            cell,
            cells,
        }
    }

    fn key(p: Vec3, cell: f32) -> IVec3 {
        // Saturating casts: a far floater lands in a far (or the last) cell.
        (p / cell).floor().as_ivec3()
    }

    /// Keys of the cells at Chebyshev distance `ring` from `home`.
    fn ring(home: IVec3, ring: i32) -> impl Iterator<Item = IVec3> {
        let span = -ring..=ring;
        span.clone()
            .flat_map(move |z| span.clone().map(move |y| (y, z)))
            .flat_map(move |(y, z)| (-ring..=ring).map(move |x| IVec3::new(x, y, z)))
            .filter(move |d| d.abs().max_element() == ring)
            .map(move |d| home.saturating_add(d))
    }

    /// Others within `radius` of `p` (which is Gaussian `me`), counted up to
    /// [`NEIGHBOURS`] (the count stops there).
    fn count_within(&self, p: Vec3, radius: f32, me: u32) -> usize {
        let rings = (radius / self.cell).ceil().min(MAX_RINGS as f32) as i32;
        let home = Self::key(p, self.cell);
        let mut found = 0;
        for ring in 0..=rings {
            for key in Self::ring(home, ring) {
                for &j in self.cells.get(&key).map_or(&[][..], Vec::as_slice) {
                    if j != me && self.positions[j as usize].distance(p) <= radius {
                        found += 1;
                        if found >= NEIGHBOURS {
                            return found;
                        }
                    }
                }
            }
        }
        found
    }

    /// Distance from `p` (Gaussian `me`) to its `k`-th nearest other;
    /// infinite when none lies within [`MAX_RINGS`] rings of cells.
    fn kth_nearest(&self, p: Vec3, k: usize, me: u32) -> f32 {
        let home = Self::key(p, self.cell);
        let mut near: Vec<f32> = Vec::new();
        for ring in 0..=MAX_RINGS {
            for key in Self::ring(home, ring) {
                if let Some(list) = self.cells.get(&key) {
                    near.extend(
                        list.iter()
                            .filter(|&&j| j != me)
                            .map(|&j| self.positions[j as usize].distance(p)),
                    );
                }
            }
            if near.len() >= k {
                near.sort_by(f32::total_cmp);
                // Cells beyond this ring are at least `ring` cells away.
                if near[k - 1] <= ring as f32 * self.cell {
                    return near[k - 1];
                }
            }
        }
        if near.len() >= k {
            near[k - 1]
        } else {
            f32::INFINITY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::synthetic::synthetic_scene;
    use glam::Quat;

    #[test]
    fn planted_floaters_go_and_the_scene_stays() {
        // One Gaussian in a thousand is a floater 20-40 units out.
        for count in [2_000, 30_000] {
            let scene = synthetic_scene(count, 7);
            let (verdicts, counts) = judge(&scene, &CleanOptions::default());
            let floater = |i: usize| i % 1000 == 999;
            let caught = (0..count)
                .filter(|&i| floater(i) && verdicts[i] != Verdict::Kept)
                .count();
            let lost = (0..count)
                .filter(|&i| !floater(i) && verdicts[i] != Verdict::Kept)
                .count();
            assert_eq!(caught, count / 1000, "{count}: every floater goes");
            assert!(lost * 200 < count, "{count}: {lost} of the scene lost");
            assert_eq!(
                counts.kept + counts.isolated + counts.huge + counts.transparent + counts.broken,
                count
            );
            assert!(
                counts.radius > 0.0 && counts.radius < 5.0,
                "{}",
                counts.radius
            );
            assert_eq!(keep(&scene, &verdicts).len(), counts.kept);
        }
    }

    #[test]
    fn broken_transparent_and_huge_gaussians_go_for_their_reason() {
        let mut scene = synthetic_scene(3_000, 3);
        let n = scene.len();
        scene.position[10] = Vec3::new(f32::NAN, 0.0, 0.0);
        scene.scale[11] = Vec3::splat(f32::INFINITY);
        scene.rotation[12] = Quat::from_xyzw(0.0, 0.0, 0.0, f32::NAN);
        scene.opacity[13] = 0.001;
        scene.opacity[14] = 0.0;
        scene.scale[15] = Vec3::new(0.01, 5.0, 0.01);
        // A needle and a flat disc of ordinary size stay.
        scene.scale[16] = Vec3::new(0.0, 0.0, 0.05);
        let (verdicts, counts) = judge(&scene, &CleanOptions::default());
        assert_eq!(
            &verdicts[10..16],
            [
                Verdict::Broken,
                Verdict::Broken,
                Verdict::Broken,
                Verdict::Transparent,
                Verdict::Transparent,
                Verdict::Huge
            ]
        );
        assert_eq!(verdicts[16], Verdict::Kept);
        assert_eq!((counts.broken, counts.transparent, counts.huge), (3, 2, 1));
        assert_eq!(keep(&scene, &verdicts).len(), counts.kept);
        assert!(counts.kept > n - 20);
    }

    #[test]
    fn tiny_degenerate_and_empty_scenes_do_not_break_it() {
        let empty = SplatScene::with_degree(0);
        assert_eq!(
            judge(&empty, &CleanOptions::default()).1,
            CleanCounts::default()
        );
        // Every centre at one point: no spacing to measure, nothing isolated.
        let mut same = SplatScene::with_degree(0);
        for _ in 0..10 {
            same.push(Vec3::ONE, Quat::IDENTITY, Vec3::splat(0.1), 0.5, &[0.0; 3]);
        }
        let (_, counts) = judge(&same, &CleanOptions::default());
        assert_eq!(counts.kept, 10);
        // Huge coordinates stay finite and decided.
        let mut far = SplatScene::with_degree(0);
        for i in 0..50 {
            far.push(
                Vec3::new(1e30, i as f32 * 1e28, 0.0),
                Quat::IDENTITY,
                Vec3::splat(1e27),
                0.5,
                &[0.0; 3],
            );
        }
        let (verdicts, _) = judge(&far, &CleanOptions::default());
        assert_eq!(verdicts.len(), 50);
        // Isolation off keeps the floaters.
        let scene = synthetic_scene(2_000, 1);
        let off = CleanOptions {
            isolation: 0.0,
            ..CleanOptions::default()
        };
        assert_eq!(judge(&scene, &off).1.isolated, 0);
    }
}
