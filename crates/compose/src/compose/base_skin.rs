//! The base's skin under a swapped source's features (`skin = "base"`,
//! docs/method.md §7.11): how surely each Gaussian is skin, how much of each
//! triangle a source shows is skin, and how fully the base's skin takes over
//! there — so that a swapped region shows its source's lips, brows, lashes,
//! iris, hair and beard over the base's own skin where the base's Gaussians
//! fit the composite's surface and both sides' skin allow it.

use glam::Vec3;
use rayon::prelude::*;

use super::dark_features::{holds_dark_features, holds_stubble};
use super::recipe::ResolvedRecipe;
use super::selection::{sharing_a_corner, Csr};
use super::skin_transfer::{semantic_skin_likeness, SkinStats};
use crate::avatar::binding::triangle_frame;
use crate::model::geometry::smoothstep;
use crate::model::regions::{Group, Region};

/// The skin shares triangles' mean likeness must reach, on both sides, for
/// the base's skin to take over (smoothly between the two): where either
/// shows a feature (lips, brows, beard, a collar) the source keeps its own.
pub const BOTH_SKIN: (f32, f32) = (0.5, 0.9);

/// The misfit ([`similarity_misfit`]) of the composite's surface to the
/// base's at which the base's skin starts to take over by fit (first) and
/// takes over in full (second), whatever the base's shape weight (method
/// §7.11). Swapped ears measure 0.16-0.33, noses 0.04-0.08, necks
/// 0.005-0.05; (0.2, 0.1) took ears over too and lost 1-4 dB there.
pub const BASE_FIT: (f32, f32) = (0.08, 0.03);

/// Under `skin = "base"` (docs/method.md §7.11): the share of its opacity a
/// Gaussian of a swapped region keeps. A source's Gaussian gives up the part
/// that is skin where the base's skin takes over; a base's Gaussian shows the
/// part that is skin there.
#[derive(Clone, Copy, Debug)]
pub struct SkinShare<'e> {
    /// Per Gaussian of the block's source: how surely it is skin.
    pub likeness: &'e [f32],
    /// Per triangle: how fully the base's skin takes over there.
    pub confidence: &'e [f32],
    /// Whether the block is the base's skin (else the source's Gaussians).
    pub of_base: bool,
}

/// Gaussians whose share is at most this are left out: invisible (under
/// 0.5 % opacity), they would only cost drawing.
pub const SHARE_FLOOR: f32 = 1e-3;

impl SkinShare<'_> {
    /// The share Gaussian `i`, counted for triangle `t`, keeps.
    pub fn of(&self, i: u32, t: u32) -> f32 {
        let taken = self.likeness[i as usize] * self.confidence[t as usize];
        if self.of_base {
            taken
        } else {
            1.0 - taken
        }
    }

    /// Whether Gaussian `i`, counted for triangle `t`, shows at all.
    pub fn shows(&self, i: u32, t: u32) -> bool {
        self.of(i, t) > SHARE_FLOOR
    }
}

/// Per Gaussian: how surely it is skin, by its source's skin statistics
/// `stats` and the region of the triangle it counts for (`counted`, indexing
/// `regions`), from its colour as the cameras saw it (method §7.7); all 0
/// for a source without skin statistics. On the regions that hold stubble
/// (`dark_features::holds_stubble`) it is at most the share of the
/// Gaussian that is skin by its brightness, `area_share(i)`
/// (`dark_features::skin_share_of_area`) where that can be told (method
/// §7.11): the lenient likeness reads skin mixed with dark stubble as skin.
pub fn skin_likeness(
    colours: &[Vec3],
    counted: &[u32],
    regions: &[Region],
    stats: Option<&SkinStats>,
    area_share: impl Fn(usize) -> Option<f32> + Sync,
) -> Vec<f32> {
    let Some(stats) = stats else {
        return vec![0.0; colours.len()];
    };
    colours
        .par_iter()
        .zip(counted)
        .enumerate()
        .map(|(i, (&rgb, &t))| {
            let Some(region) = regions.get(t as usize).copied() else {
                return 0.0;
            };
            let likeness = semantic_skin_likeness(rgb, region, stats).unwrap_or(0.0);
            if !holds_stubble(region) {
                return likeness;
            }
            area_share(i).map_or(likeness, |share| likeness.min(share))
        })
        .collect()
}

/// Per triangle (of `triangles`): how much of what a source shows there is
/// skin — its Gaussians' `likeness`, weighted by `weights` (a mean colour's,
/// method §7.5); 0 where none counts.
pub fn triangle_skin(
    counted: &[u32],
    likeness: &[f32],
    weights: &[f32],
    triangles: usize,
) -> Vec<f32> {
    let (mut skin, mut total) = (vec![0.0f32; triangles], vec![0.0f32; triangles]);
    for ((&t, &k), &w) in counted.iter().zip(likeness).zip(weights) {
        if let (Some(s), Some(n)) = (skin.get_mut(t as usize), total.get_mut(t as usize)) {
            *s += k * w;
            *n += w;
        }
    }
    skin.iter()
        .zip(&total)
        .map(|(&s, &n)| if n > 0.0 { s / n } else { 0.0 })
        .collect()
}

/// The mesh topology [`base_skin_confidence`] looks round a triangle with.
#[derive(Clone, Copy)]
pub struct Topology<'a> {
    /// Corner vertices of each triangle.
    pub triangles: &'a [[u32; 3]],
    /// Per vertex, the triangles that have it as a corner.
    pub vertex_triangles: &'a Csr,
}

/// Per triangle (region `regions[t]`): how fully the base's skin takes over
/// from the skin of the source the triangle's region shows — how well the
/// base's Gaussians fit the composite's surface there (the larger of the
/// base's share of the group's shape and the fit its `misfit` gives, see
/// [`BASE_FIT`]; the fit counts nowhere beside a feature — either side's,
/// or only the base's where [`only_base_features_keep_off`] says so — nor
/// the shape weight beside one round the eyes where the base's skin is
/// lighter)
/// times how surely both show skin there; 0 where the region shows the
/// base. `skin_of(s)` is source s's [`triangle_skin`]; `misfit` is
/// [`similarity_misfit`] from the base's neutral to the composite's, None
/// to judge by the shape weight alone; `brightens(s)` says whether the skin
/// transfer from source s to the base brightens
/// ([`transfer_brightens`](super::dark_features::transfer_brightens)).
pub fn base_skin_confidence<'a>(
    recipe: &ResolvedRecipe,
    regions: &[Region],
    skin_of: impl Fn(usize) -> &'a [f32],
    misfit: Option<(&[f32], Topology)>,
    brightens: impl Fn(usize) -> bool,
) -> Vec<f32> {
    let base = skin_of(recipe.base);
    // How surely both sides show skin on triangle t.
    let both = |t: usize| {
        let f = recipe.gaussians[regions[t].group().index()];
        skin_of(f)[t].min(base[t])
    };
    // Only the eye regions' rules ask the transfer's direction, and it
    // converts colours: ask once, for the eyes' source.
    let eyes_brighten = brightens(recipe.gaussians[Group::Eyes.index()]);
    let beside_feature = misfit.map(|(_, topology)| {
        let features = Features {
            either: (0..regions.len()).map(|t| both(t) < BOTH_SKIN.0).collect(),
            base: (0..regions.len()).map(|t| base[t] < BOTH_SKIN.0).collect(),
        };
        let only_base = |t: usize| only_base_features_keep_off(regions[t], eyes_brighten);
        beside_feature(topology, regions.len(), &features, only_base)
    });
    (0..regions.len())
        .map(|t| {
            let group = regions[t].group().index();
            let source = recipe.gaussians[group];
            if source == recipe.base {
                return 0.0;
            }
            // A triangle past the topology's counts as beside a feature: the
            // cautious reading, the source keeps its own there.
            let beside = beside_feature
                .as_ref()
                .is_some_and(|b| b.get(t).copied().unwrap_or(true));
            // Beside a feature (either side's) round the eyes, a lighter
            // base's skin paints over the source's brows and lashes; a
            // darker one's errs little there, and takes over the lid skin a
            // light source would leave light.
            let light_beside_dark = beside && holds_dark_features(regions[t]) && eyes_brighten;
            let shape = if light_beside_dark {
                0.0
            } else {
                recipe.shape[group].get(recipe.base).copied().unwrap_or(0.0) as f32
            };
            let fit = match misfit {
                Some((m, _)) if !beside => m
                    .get(t)
                    .map_or(0.0, |&m| smoothstep(BASE_FIT.0, BASE_FIT.1, m)),
                _ => 0.0,
            };
            shape.max(fit) * smoothstep(BOTH_SKIN.0, BOTH_SKIN.1, both(t))
        })
        .collect()
}

/// Per triangle: where a feature stands, on either side of a swap and on
/// the base's alone (a skin share under [`BOTH_SKIN`]'s lower edge).
struct Features {
    either: Vec<bool>,
    base: Vec<bool>,
}

/// Whether only the base's own features keep the base's skin off a
/// triangle of `region` beside them (else either side's do), `eyes_brighten`
/// saying whether the skin transfer from the eyes' source to the base
/// brightens. The base's
/// skin Gaussians at the edge of one of its features carry that feature's
/// colour; beside one of the source's they were trained beside skin, and
/// what the source's Gaussians there hold is mostly the transfer's error
/// where the source's features are those a skin share reads poorly: the
/// neck's shade and light stubble, the sockets' lid skin over the
/// eyeball's rim, the lids where the transfer does not brighten (method
/// §7.11, "Beside whose feature"). A dark source's brows and lashes under a
/// brightening transfer, and a hairline's hair, are drawn to their edge by
/// the source's Gaussians beside them, and those stay.
fn only_base_features_keep_off(region: Region, eyes_brighten: bool) -> bool {
    match region {
        Region::Neck | Region::LeftEyeSocket | Region::RightEyeSocket => true,
        Region::LeftEyeRegion | Region::RightEyeRegion => !eyes_brighten,
        _ => false,
    }
}

/// Per triangle (of the first `triangles`): whether it shares a corner with
/// a triangle where a feature stands — a collar's edge, a beard's, a lip's:
/// the base's own alone where `only_base(t)`, either side's elsewhere (why,
/// in [`only_base_features_keep_off`]). The fitted part of the base's skin
/// stays off those: the base's skin Gaussians beside its own features were
/// trained beside them (every-group's neck lost 3.2 dB to a light line along
/// cleo's collar without this); round the eyes, under a brightening
/// transfer, the shape-weighted part does too. A corner past the topology's
/// table counts as beside no feature ([`sharing_a_corner`]).
fn beside_feature(
    topology: Topology,
    triangles: usize,
    features: &Features,
    only_base: impl Fn(usize) -> bool,
) -> Vec<bool> {
    let corners = &topology.triangles[..triangles.min(topology.triangles.len())];
    let beside = |marked: &[bool]| sharing_a_corner(corners, topology.vertex_triangles, marked);
    let (base, either) = (beside(&features.base), beside(&features.either));
    (0..corners.len())
        .map(|t| if only_base(t) { base[t] } else { either[t] })
        .collect()
}

/// Per triangle: how far the surface round it on mesh `to` is from a similar
/// copy of the same place on mesh `from` (the same topology), in units of
/// the triangle's size on `to` — what Gaussians trained on `from` and
/// carried by the triangle's similarity (method §6.7) get wrong on `to`. The
/// triangle's similarity (its frame's rotation, size and centroid, method
/// §3.1) carries every corner of the triangles sharing a corner with it from
/// `from`; the misfit is the root mean square of their distances to where
/// `to` has them, over the triangle's size on `to`. 0 for a mesh moved,
/// turned or scaled whole; infinite where the triangle has no size on either
/// mesh, a corner is past either mesh or the result is not finite.
pub fn similarity_misfit(from: &[Vec3], to: &[Vec3], topology: Topology) -> Vec<f32> {
    let triangles = topology.triangles;
    triangles
        .par_iter()
        .map(|tri| {
            let misfit = (|| {
                let corners = |mesh: &[Vec3]| -> Option<[Vec3; 3]> {
                    Some([
                        *mesh.get(tri[0] as usize)?,
                        *mesh.get(tri[1] as usize)?,
                        *mesh.get(tri[2] as usize)?,
                    ])
                };
                let ([a, b, c], [a2, b2, c2]) = (corners(from)?, corners(to)?);
                let (old, new) = (triangle_frame(a, b, c), triangle_frame(a2, b2, c2));
                if !(old.scale > 0.0 && new.scale > 0.0) {
                    return None;
                }
                let carry = new.rotation * old.rotation.transpose() * (new.scale / old.scale);
                let (mut sum, mut count) = (0.0f32, 0u32);
                for &v in tri {
                    for &u in topology.vertex_triangles.row(v as usize) {
                        let ring = triangles.get(u as usize)?;
                        for w in ring.map(|w| w as usize) {
                            let (p, q) = (*from.get(w)?, *to.get(w)?);
                            sum += (new.center + carry * (p - old.center) - q).length_squared();
                            count += 1;
                        }
                    }
                }
                Some((sum / count.max(1) as f32).sqrt() / new.scale)
            })();
            misfit.filter(|m| m.is_finite()).unwrap_or(f32::INFINITY)
        })
        .collect()
}

/// The Gaussians of `all` (counted for the triangles `counted`) that show
/// under `share`.
pub fn showing(share: SkinShare, all: &[u32], counted: &[u32]) -> Vec<u32> {
    all.iter()
        .copied()
        .filter(|&i| share.shows(i, counted[i as usize]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compose::colour::srgb_to_lab;

    fn stats(rgb: Vec3) -> SkinStats {
        let lab = srgb_to_lab(rgb);
        SkinStats {
            mean: lab,
            tone: lab,
            hair: None,
        }
    }

    #[test]
    fn likeness_is_skin_for_the_skin_and_none_for_lips_black_nan_or_no_stats() {
        let skin = Vec3::new(0.8, 0.6, 0.5);
        let colours = [skin, Vec3::new(0.5, 0.1, 0.12), Vec3::ZERO, Vec3::NAN, skin];
        let regions = [Region::Nose, Region::Lips];
        let counted = [0, 1, 0, 0, 7];
        let k = skin_likeness(&colours, &counted, &regions, Some(&stats(skin)), |_| None);
        assert_eq!(k[0], 1.0);
        assert_eq!(k[1], 0.0, "lips are no skin");
        assert_eq!(k[2], 0.0, "black is no skin");
        assert_eq!(k[3], 0.0, "NaN is no skin");
        assert_eq!(k[4], 0.0, "a triangle past the model is no skin");
        assert_eq!(
            skin_likeness(&colours, &counted, &regions, None, |_| None),
            [0.0; 5]
        );
    }

    #[test]
    fn on_the_neck_likeness_is_at_most_the_skins_share_of_the_area() {
        let skin = Vec3::new(0.8, 0.6, 0.5);
        let colours = [skin; 4];
        let regions = [Region::Neck, Region::Nose];
        let counted = [0, 0, 1, 0];
        // Gaussian 1 is a half-stubble mix by its brightness, 3 cannot be
        // told; the nose is no stubble's place.
        let area = |i: usize| [Some(1.0), Some(0.5), Some(0.5), None][i];
        let k = skin_likeness(&colours, &counted, &regions, Some(&stats(skin)), area);
        assert_eq!(k, [1.0, 0.5, 1.0, 1.0]);
        let plain = skin_likeness(&colours, &counted, &regions, Some(&stats(skin)), |_| None);
        assert_eq!(plain, [1.0; 4]);
    }

    #[test]
    fn triangle_skin_is_the_weighted_mean_and_zero_where_nothing_counts() {
        let counted = [0, 0, 2, 9];
        let likeness = [1.0, 0.0, 0.5, 1.0];
        let weights = [3.0, 1.0, 0.0, 1.0];
        let t = triangle_skin(&counted, &likeness, &weights, 3);
        assert_eq!(t, [0.75, 0.0, 0.0]);
    }

    /// A recipe on base 0 whose `group` shows source 1, every group's shape
    /// weighted by `shape`.
    fn from_source_one(group: Group, shape: Vec<f64>) -> ResolvedRecipe {
        ResolvedRecipe {
            base: 0,
            gaussians: std::array::from_fn(|g| usize::from(g == group.index())),
            shape: std::array::from_fn(|_| shape.clone()),
            post: Default::default(),
            motion: None,
            frame: 0,
            mode: Default::default(),
            offsets: Default::default(),
            camera: Default::default(),
        }
    }

    #[test]
    fn the_base_takes_over_by_its_shape_weight_where_both_show_skin() {
        let nose = Group::Nose.index();
        let mut recipe = from_source_one(Group::Nose, vec![1.0, 0.0, 0.0]);
        let regions = [Region::Nose, Region::Nose, Region::Skin, Region::Nose];
        let skin_of = |s: usize| -> &'static [f32] {
            match s {
                0 => &[1.0, 1.0, 1.0, 0.2],
                _ => &[1.0, 0.7, 1.0, 1.0],
            }
        };
        for (weights, expected) in [
            (
                vec![1.0, 0.0, 0.0],
                [1.0, smoothstep(0.5, 0.9, 0.7), 0.0, 0.0],
            ),
            (
                vec![0.5, 0.5, 0.0],
                [0.5, 0.5 * smoothstep(0.5, 0.9, 0.7), 0.0, 0.0],
            ),
            (vec![0.0, 1.0, 0.0], [0.0; 4]),
        ] {
            recipe.shape[nose] = weights;
            let c = base_skin_confidence(&recipe, &regions, skin_of, None, |_| false);
            for (got, want) in c.iter().zip(expected) {
                assert!((got - want).abs() < 1e-6, "{c:?} against {expected:?}");
            }
        }
    }

    #[test]
    fn shares_split_a_skin_gaussian_between_source_and_base_and_leave_features() {
        let likeness = [1.0, 0.0, 0.25];
        let confidence = [1.0, 0.5];
        let source = SkinShare {
            likeness: &likeness,
            confidence: &confidence,
            of_base: false,
        };
        let base = SkinShare {
            of_base: true,
            ..source
        };
        assert_eq!((source.of(0, 0), base.of(0, 0)), (0.0, 1.0));
        assert_eq!((source.of(1, 0), base.of(1, 0)), (1.0, 0.0));
        assert_eq!((source.of(2, 1), base.of(2, 1)), (0.875, 0.125));
        assert_eq!(showing(source, &[0, 1, 2], &[0, 0, 1]), [1, 2]);
        assert_eq!(showing(base, &[0, 1, 2], &[0, 0, 1]), [0, 2]);
    }

    /// A 4×4-vertex grid of unit squares in the z = 0 plane, two triangles
    /// each (18 triangles), with its vertex-to-triangle table.
    struct Grid {
        vertices: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        vertex_triangles: Csr,
    }

    impl Grid {
        fn topology(&self) -> Topology<'_> {
            Topology {
                triangles: &self.triangles,
                vertex_triangles: &self.vertex_triangles,
            }
        }
    }

    fn grid() -> Grid {
        let vertices: Vec<Vec3> = (0..16)
            .map(|i| Vec3::new((i % 4) as f32, (i / 4) as f32, 0.0))
            .collect();
        let mut triangles = Vec::new();
        for y in 0..3u32 {
            for x in 0..3u32 {
                let v = y * 4 + x;
                triangles.push([v, v + 1, v + 5]);
                triangles.push([v, v + 5, v + 4]);
            }
        }
        let vertex_triangles = Csr::vertex_triangles(vertices.len(), &triangles);
        Grid {
            vertices,
            triangles,
            vertex_triangles,
        }
    }

    #[test]
    fn the_misfit_is_zero_for_a_mesh_moved_turned_or_scaled_whole_and_grows_with_a_bend() {
        let grid = grid();
        let (from, topology) = (&grid.vertices, grid.topology());
        let turn = glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 1.1);
        let whole: Vec<Vec3> = from
            .iter()
            .map(|&v| turn * (v * 2.5) + Vec3::new(1e3, -7.0, 0.5))
            .collect();
        let m = similarity_misfit(from, &whole, topology);
        assert!(m.iter().all(|&m| m < 1e-3), "{m:?}");
        // Lift the far column: the triangles beside it bend, the far side stays.
        let mut bent = from.clone();
        for v in bent.iter_mut().filter(|v| v.x == 3.0) {
            v.z = 0.5;
        }
        let m = similarity_misfit(from, &bent, topology);
        assert!(m[4] > 0.05 && m[0] < 1e-6, "{m:?}");
        assert!(m[5] > m[0]);
    }

    #[test]
    fn the_misfit_is_infinite_for_degenerate_triangles_broken_or_missing_corners() {
        let grid = grid();
        let (from, topology) = (&grid.vertices, grid.topology());
        let mut collapsed = from.clone();
        collapsed[0] = Vec3::ZERO;
        collapsed[1] = Vec3::ZERO;
        collapsed[5] = Vec3::ZERO;
        assert_eq!(
            similarity_misfit(from, &collapsed, topology)[0],
            f32::INFINITY
        );
        let mut broken = from.clone();
        broken[15] = Vec3::NAN;
        let m = similarity_misfit(from, &broken, topology);
        assert_eq!(m[17], f32::INFINITY);
        assert!(m[0].is_finite());
        assert!(similarity_misfit(from, &from[..8], topology)
            .iter()
            .all(|&m| m == f32::INFINITY));
    }

    /// Per triangle, how much of what each side shows is skin: all of the
    /// base's (source 0), all of source 1's but on the last triangle, where
    /// it shows a feature.
    struct FeatureOnLast {
        base: Vec<f32>,
        source: Vec<f32>,
    }

    impl FeatureOnLast {
        fn new(triangles: usize) -> Self {
            let mut source = vec![1.0f32; triangles];
            source[triangles - 1] = 0.0;
            FeatureOnLast {
                base: vec![1.0f32; triangles],
                source,
            }
        }

        fn of(&self, s: usize) -> &[f32] {
            if s == 0 {
                &self.base
            } else {
                &self.source
            }
        }
    }

    #[test]
    fn the_base_takes_over_where_its_gaussians_fit_but_not_beside_a_feature() {
        let grid = grid();
        let (triangles, topology) = (&grid.triangles, grid.topology());
        let recipe = from_source_one(Group::Nose, vec![0.0, 1.0]);
        let regions = vec![Region::Nose; triangles.len()];
        // The source shows a feature (a beard) on the last triangle only.
        let skins = FeatureOnLast::new(triangles.len());
        let skin_of = |s: usize| skins.of(s);
        let mut misfit = vec![0.0f32; triangles.len()];
        misfit[2] = BASE_FIT.0 + 0.01; // an ear's bend: the source keeps it
        misfit[3] = 0.5 * (BASE_FIT.0 + BASE_FIT.1);
        let c = base_skin_confidence(
            &recipe,
            &regions,
            skin_of,
            Some((&misfit, topology)),
            |_| false,
        );
        assert_eq!(c[0], 1.0, "fits: the base's skin in full at shape weight 0");
        assert_eq!(c[2], 0.0, "too far from the base's shape");
        assert!((c[3] - 0.5).abs() < 1e-6, "half way: {}", c[3]);
        // Triangle 17 and those sharing a corner with it keep the source.
        assert_eq!(c[17], 0.0);
        assert_eq!(c[16], 0.0);
        assert_eq!(c[11], 0.0);
        // Judged by the shape weight alone, the base takes nothing.
        let c = base_skin_confidence(&recipe, &regions, skin_of, None, |_| false);
        assert!(c.iter().all(|&c| c == 0.0));
    }

    #[test]
    fn on_the_neck_and_in_the_sockets_only_the_bases_own_features_keep_its_skin_off() {
        let grid = grid();
        let (triangles, topology) = (&grid.triangles, grid.topology());
        let misfit = vec![0.0f32; triangles.len()];
        let confidence = |group: Group, region: Region, skins: &FeatureOnLast, brightens: bool| {
            let recipe = from_source_one(group, vec![0.0, 1.0]);
            let regions = vec![region; triangles.len()];
            let skin_of = |s: usize| skins.of(s);
            base_skin_confidence(&recipe, &regions, skin_of, Some((&misfit, topology)), |s| {
                s == 1 && brightens
            })
        };
        // The source's feature (light stubble, shade read as one) on the last
        // triangle: on the neck, in a socket and on a lid under a darkening
        // transfer the base takes over beside it; on the nose, and on a lid
        // under a brightening transfer (a dark source's brow), it does not.
        // The base's own feature (its collar) keeps its skin off everywhere.
        let source_feature = FeatureOnLast::new(triangles.len());
        let base_feature = FeatureOnLast {
            base: source_feature.source.clone(),
            source: source_feature.base.clone(),
        };
        let (takes_over, keeps_off) = ((0.0, 1.0, 1.0, 1.0), (0.0, 0.0, 0.0, 1.0));
        let cases = [
            (Group::Neck, Region::Neck, &source_feature, true, takes_over),
            (
                Group::Eyes,
                Region::RightEyeSocket,
                &source_feature,
                true,
                takes_over,
            ),
            (
                Group::Eyes,
                Region::LeftEyeSocket,
                &source_feature,
                false,
                takes_over,
            ),
            (
                Group::Eyes,
                Region::LeftEyeRegion,
                &source_feature,
                false,
                takes_over,
            ),
            (
                Group::Eyes,
                Region::RightEyeRegion,
                &source_feature,
                false,
                takes_over,
            ),
            (Group::Nose, Region::Nose, &source_feature, true, keeps_off),
            (
                Group::Eyes,
                Region::LeftEyeRegion,
                &source_feature,
                true,
                keeps_off,
            ),
            (
                Group::Eyes,
                Region::RightEyeRegion,
                &source_feature,
                true,
                keeps_off,
            ),
            (Group::Neck, Region::Neck, &base_feature, false, keeps_off),
            (
                Group::Eyes,
                Region::LeftEyeSocket,
                &base_feature,
                false,
                keeps_off,
            ),
            (
                Group::Eyes,
                Region::RightEyeRegion,
                &base_feature,
                false,
                keeps_off,
            ),
            (Group::Nose, Region::Nose, &base_feature, false, keeps_off),
        ];
        for (group, region, skins, brightens, expected) in cases {
            let c = confidence(group, region, skins, brightens);
            assert_eq!((c[17], c[16], c[11], c[0]), expected, "{region:?}: {c:?}");
        }
    }

    #[test]
    fn a_lighter_bases_skin_stays_off_a_dark_sources_brows_whatever_its_shape_weight() {
        let grid = grid();
        let (triangles, topology) = (&grid.triangles, grid.topology());
        // The base's shape weight is ½; the misfit is too large for the fit.
        let misfit = vec![1.0f32; triangles.len()];
        // The source shows a feature (a brow) on the last triangle only.
        let skins = FeatureOnLast::new(triangles.len());
        let skin_of = |s: usize| skins.of(s);
        let confidence = |group: Group, region: Region, brightens: bool| {
            let recipe = from_source_one(group, vec![0.5, 0.5]);
            let regions = vec![region; triangles.len()];
            base_skin_confidence(&recipe, &regions, skin_of, Some((&misfit, topology)), |s| {
                s == 1 && brightens
            })
        };
        // Round the eyes, onto a lighter base: nothing beside the brow.
        let c = confidence(Group::Eyes, Region::LeftEyeRegion, true);
        assert_eq!((c[17], c[16], c[11]), (0.0, 0.0, 0.0), "{c:?}");
        assert_eq!(c[0], 0.5, "away from the brow the shape weight counts");
        // Onto a darker base, and on a nose, the shape weight counts beside it.
        for (group, region, brightens) in [
            (Group::Eyes, Region::RightEyeRegion, false),
            (Group::Nose, Region::Nose, true),
        ] {
            let c = confidence(group, region, brightens);
            assert_eq!((c[17], c[16], c[11], c[0]), (0.0, 0.5, 0.5, 0.5), "{c:?}");
        }
    }
}
