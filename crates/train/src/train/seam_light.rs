//! The light in a seam fit's targets (method §7.12, "The light").
//!
//! A source's Gaussians carry the light of its own capture. `shading =
//! "relit"` (method §7.10) gives each Gaussian one gain for the surface it
//! sits on in the composite, but a Gaussian spans a piece of surface whose
//! exposure changes from point to point — a crease the blend flattens, a
//! hollow it deepens — and one gain cannot follow that. The fit's targets
//! can: a whole head drawn with the light its Gaussians were trained under
//! (`shading = "kept"`) is relit at each pixel by its source's light, for
//! the surface point the pixel shows on the composite over the same point
//! on the source's own neutral mesh. A whole under `skin = "base"` holds
//! Gaussians of two people, each trained under their own light on their own
//! face, so it is drawn once per person (the others' Gaussians black but
//! still in front) and each drawing relit by its own person's light.

use glam::Vec3;

use crate::avatar::gaussians::rgb_to_dc;
use crate::compose::engine::{Composite, Engine};
use crate::compose::recipe::Shading;
use crate::compose::shading::{vertex_exposures, BakedLight, Exposure};
use crate::model::head::HeadModel;
use crate::model::regions::Region;

use super::model::{Trainable, SH_STRIDE};
use super::seam_own_shape::Part;

/// Whether a composite's seam fit relights its targets pixel by pixel: when
/// the recipe relights its Gaussians (a recipe that keeps the sources'
/// light asks for their light as it was).
pub(super) fn relights(composite: &Composite) -> bool {
    composite.recipe.post.shading == Shading::Relit
}

/// The mouth's inside and the teeth, where a target keeps the light its
/// Gaussians were trained under: a light fitted to a person's skin says
/// nothing of surfaces facing into the mouth. Their parts are still read
/// from their own faces (`seam_own_shape`), which places them; relit by
/// the skin's light as well they measured the same over the ten bench
/// recipes (34.3231 against 34.3223 dB); relit without own-face reads,
/// random-02's teeth lost 2 dB.
pub(super) fn inner(region: Region) -> bool {
    matches!(
        region,
        Region::TeethUpper | Region::TeethLower | Region::LipsInside
    )
}

/// What relights a target pixel by pixel: the exposure at every vertex of
/// the composite's neutral mesh and of each source's, with each source's
/// light.
pub(super) struct PixelLight {
    /// The exposure at every vertex of the composite's neutral mesh.
    composite: Vec<Exposure>,
    /// Per source of the database: its neutral's vertex exposures and its
    /// light, for the sources the composite's wholes draw on (None for the
    /// rest).
    sources: Vec<Option<(Vec<Exposure>, BakedLight)>>,
}

impl PixelLight {
    /// The light of `sources` (database indices) on `composite`'s surface.
    pub(super) fn new(engine: &Engine, composite: &Composite, sources: &[usize]) -> PixelLight {
        let model = &engine.database().model;
        let mut per_source = vec![None; engine.database().sources.len()];
        for &s in sources {
            if let Some(light) = engine.light(s) {
                let exposures = vertex_exposures(engine.source_neutral(s), &model.triangles);
                per_source[s] = Some((exposures, *light));
            }
        }
        PixelLight {
            composite: vertex_exposures(&composite.neutral, &model.triangles),
            sources: per_source,
        }
    }

    /// The gain that relights what source `s`'s Gaussians show at
    /// barycentric `bary` of the triangle with `corners`: its light there on
    /// the composite over its light at the same point of its own neutral;
    /// one where it has no light or either surface no normal.
    pub(super) fn gain(&self, s: usize, corners: [u32; 3], bary: [f32; 3]) -> Vec3 {
        let Some(Some((own, light))) = self.sources.get(s) else {
            return Vec3::ONE;
        };
        let here = Exposure::at(&self.composite, corners, bary);
        let there = Exposure::at(own, corners, bary);
        if here.normal == Vec3::ZERO || there.normal == Vec3::ZERO {
            return Vec3::ONE;
        }
        light.gain(there, here)
    }
}

/// A whole head with the light its Gaussians were trained under, to be
/// drawn once per person whose Gaussians it holds ([`KeptWhole::part`]).
pub(super) struct KeptWhole {
    drawable: Trainable,
    /// The composite's blocks as (source, range): they tile its Gaussians.
    owners: Vec<(usize, std::ops::Range<usize>)>,
    /// The sources, sorted, each once.
    sources: Vec<usize>,
}

impl KeptWhole {
    /// `whole` (composed with `shading = "kept"`) and its drawable set.
    pub(super) fn new(whole: &Composite, drawable: Trainable) -> KeptWhole {
        let owners: Vec<(usize, std::ops::Range<usize>)> = whole
            .blocks
            .iter()
            .map(|b| (b.source, b.start..b.end))
            .collect();
        // The drawings add up to the whole only if every Gaussian is in
        // exactly one of them.
        debug_assert!(
            owners.iter().map(|(_, r)| r.len()).sum::<usize>() == drawable.len()
                && owners.windows(2).all(|w| w[0].1.end == w[1].1.start),
            "the blocks do not tile the composite's Gaussians"
        );
        let mut sources: Vec<usize> = owners.iter().map(|(s, _)| *s).collect();
        sources.sort_unstable();
        sources.dedup();
        KeptWhole {
            drawable,
            owners,
            sources,
        }
    }

    /// The sources whose Gaussians the whole holds.
    pub(super) fn sources(&self) -> &[usize] {
        &self.sources
    }

    /// The whole with every Gaussian not from `source` black (colour zero,
    /// SH bands zero) but as opaque as before: drawn on black, the parts of
    /// a whole add up to it (the renderer clamps each Gaussian's colour at
    /// zero, not a pixel's sum). The whole itself where it holds one source.
    pub(super) fn part(&self, source: usize) -> std::borrow::Cow<'_, Trainable> {
        if self.sources.len() == 1 {
            return std::borrow::Cow::Borrowed(&self.drawable);
        }
        let mut part = self.drawable.clone();
        let black = f64::from(rgb_to_dc(0.0));
        for (_, range) in self.owners.iter().filter(|(s, _)| *s != source) {
            for i in range.clone() {
                let sh = &mut part.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
                sh.fill(0.0);
                sh[..3].fill(black);
            }
        }
        std::borrow::Cow::Owned(part)
    }

    /// The whole with `source`'s Gaussians white and every other one black,
    /// all as opaque as before: drawn on black, how much of each pixel
    /// `source`'s Gaussians show.
    pub(super) fn coverage(&self, source: usize) -> Trainable {
        let mut out = self.drawable.clone();
        let (black, white) = (f64::from(rgb_to_dc(0.0)), f64::from(rgb_to_dc(1.0)));
        for (s, range) in &self.owners {
            let dc = if *s == source { white } else { black };
            for i in range.clone() {
                let sh = &mut out.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
                sh.fill(0.0);
                sh[..3].fill(dc);
            }
        }
        out
    }
}

/// A whole's target image: per pixel showing surface (`hits`: triangle and
/// barycentric point), the sum of its parts' drawings (`parts`, per source)
/// each relit by its source's [`PixelLight::gain`] there — on the mouth's
/// inside and on the teeth ([`inner`]) as they are; off the surface,
/// `relit` (the whole drawn with the per-Gaussian light). The parts, not
/// `relit`, in the mouth too: their drawings on their people's own faces
/// put the teeth where they belong on the surface, which the Gaussians
/// reshaped onto a new mouth miss (random-02's teeth, nuru's on kemi's
/// mouth, 12.7 → 13.8 dB). The gain scales all the colour a pixel shows,
/// its view-dependent part too: the target is what the light makes of the
/// pixel, and the fit then moves the Gaussians' colours, opacities and
/// reach.
pub(super) fn relit_target(
    model: &HeadModel,
    light: &PixelLight,
    hits: &[Option<(u32, [f32; 3], f64)>],
    relit: &[f64],
    parts: &[Part],
) -> Vec<f64> {
    let mut out = relit.to_vec();
    for (p, hit) in hits.iter().enumerate() {
        let Some((t, bary, _)) = hit else { continue };
        let as_trained = inner(model.triangle_regions[*t as usize]);
        let corners = model.triangles[*t as usize];
        let pixel = &mut out[3 * p..3 * p + 3];
        pixel.fill(0.0);
        for part in parts {
            let gain = if as_trained {
                Vec3::ONE
            } else {
                light.gain(part.person, corners, *bary)
            };
            for c in 0..3 {
                pixel[c] += part.colour[3 * p + c] * f64::from(gain[c]);
            }
        }
    }
    out
}

/// Per Gaussian of `composite`: whether the light on its parent triangle
/// changed — any corner's normal or cavity on the composite's neutral off
/// its source's by more than 10⁻³. Those the fit moves, as it moves a
/// seam's (§7.12); where nothing moved nothing is fitted, so a composite on
/// its sources' own shapes keeps its bits.
pub(super) fn light_moved(engine: &Engine, composite: &Composite) -> Vec<bool> {
    let model = &engine.database().model;
    let here = vertex_exposures(&composite.neutral, &model.triangles);
    let mut moved_by_source: Vec<Option<Vec<bool>>> = vec![None; engine.database().sources.len()];
    let mut out = vec![false; composite.gaussians.len()];
    for block in &composite.blocks {
        // A source without a light is never relit. The mouth's inside is
        // fitted too, though its own target keeps the trained light
        // ([`relit_target`]): its Gaussians reach the relit lips round it
        // (left out, largest-shape lost 0.09 dB).
        if engine.light(block.source).is_none() {
            continue;
        }
        let moved = moved_by_source[block.source].get_or_insert_with(|| {
            let there = vertex_exposures(engine.source_neutral(block.source), &model.triangles);
            model
                .triangles
                .iter()
                .map(|corners| {
                    corners.iter().any(|&v| {
                        let (a, b) = (here[v as usize], there[v as usize]);
                        (a.normal - b.normal).length() > 1e-3 || (a.cavity - b.cavity).abs() > 1e-3
                    })
                })
                .collect()
        });
        for (i, flag) in out.iter_mut().enumerate().take(block.end).skip(block.start) {
            let t = composite.gaussians.binding[i] as usize;
            *flag = moved.get(t).copied().unwrap_or(false);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::binding::triangle_frames;
    use crate::avatar::gaussians::GaussianSet;
    use crate::render::Backend;
    use crate::train::capture::rig;
    use crate::train::holes::Obscurer;
    use crate::train::model::Render;
    use crate::train::raster::Rasterizer;
    use crate::train::seam_test_people::{name_of, ours, two_people};

    /// The composite of source 1's mouth on source 0, with the mouth's shape
    /// when `reshaped`, post-processed as `post ours`.
    fn mouth_swap(engine: &Engine, reshaped: bool) -> Composite {
        let name = |s: usize| name_of(engine, s);
        let shape = if reshaped {
            format!("shape = {{ {} = 1.0 }}\n", name(1))
        } else {
            String::new()
        };
        let text = format!(
            "base = \"{}\"\n[groups.mouth]\ngaussians = \"{}\"\n{shape}",
            name(0),
            name(1)
        );
        engine.compose(&ours(&text).resolve(engine.database()).unwrap())
    }

    #[test]
    fn a_head_drawn_person_by_person_adds_up_to_itself() {
        let engine = two_people(3_000);
        let composite = mouth_swap(&engine, true);
        let whole = Trainable::from_set(&composite.gaussians);
        let kept = KeptWhole::new(&composite, whole.clone());
        assert_eq!(kept.sources(), [0, 1]);
        let parts: Vec<Trainable> = kept
            .sources()
            .iter()
            .map(|&s| kept.part(s).into_owned())
            .collect();
        let model = &engine.database().model;
        let frames = triangle_frames(&composite.neutral, &model.triangles);
        let (cameras, _) = rig(2, false, [48, 48]);
        let mut rasterizer = Rasterizer::open(Backend::Cpu).unwrap();
        for camera in &cameras {
            let mut draw = |t: &Trainable| {
                let r = Render::new(
                    t,
                    &frames,
                    camera,
                    [0.0; 3],
                    &Obscurer::None,
                    &mut rasterizer,
                );
                r.unwrap().image().to_vec()
            };
            let all = draw(&whole);
            let drawn: Vec<Vec<f64>> = parts.iter().map(&mut draw).collect();
            for (p, &value) in all.iter().enumerate() {
                let sum: f64 = drawn.iter().map(|d| d[p]).sum();
                assert!(
                    (sum - value).abs() < 1e-6,
                    "pixel {p}: {sum} against {value}"
                );
            }
            // Each person shows somewhere: the split is not all one side.
            for d in &drawn {
                assert!(d.iter().any(|&v| v > 0.05));
            }
        }
    }

    #[test]
    fn the_light_moves_only_where_the_shape_does() {
        let engine = two_people(3_000);
        // Source 1's Gaussians on the base's shape: its own light moved, the
        // base's did not.
        let swapped = mouth_swap(&engine, false);
        let moved = light_moved(&engine, &swapped);
        for block in &swapped.blocks {
            let any = moved[block.start..block.end].iter().any(|&m| m);
            if block.source == 0 {
                assert!(!any, "the base's own shape moved in {:?}", block.region);
            }
        }
        let of_source_1 = swapped.blocks.iter().filter(|b| b.source == 1);
        assert!(of_source_1.flat_map(|b| &moved[b.start..b.end]).any(|&m| m));
        // The mouth's shape too moves some of the base's light round it.
        let reshaped = mouth_swap(&engine, true);
        let moved = light_moved(&engine, &reshaped);
        let base = reshaped.blocks.iter().filter(|b| b.source == 0);
        assert!(base.flat_map(|b| &moved[b.start..b.end]).any(|&m| m));
    }

    /// One source on another's shape: no seam, but its light moved, so
    /// the fit refits the Gaussians whose light moved — and those alone —
    /// where the recipe relights, and leaves the head be where the recipe
    /// keeps the trained light.
    #[test]
    fn a_head_of_one_source_on_a_new_shape_is_fitted_where_its_light_moved() {
        use crate::compose::recipe::Shading;
        use crate::train::seam_fit::{fit_seams, SeamFit};

        use crate::train::seam_test_people::base_on_the_others_face;

        let engine = two_people(3_000);
        let mut recipe = base_on_the_others_face(&engine);
        let options = SeamFit {
            iterations: 6,
            size: 32,
            cameras: 2,
            renderer: Backend::Cpu,
        };
        let relit = engine.compose(&recipe.resolve(engine.database()).unwrap());
        let moved = light_moved(&engine, &relit);
        assert!(moved.iter().any(|&m| m) && !moved.iter().all(|&m| m));
        let (fitted, report) = fit_seams(&engine, &relit, &options, &mut |_, _| {}).unwrap();
        assert_eq!(report.fitted, moved.iter().filter(|&&m| m).count());
        let before = &relit.gaussians;
        let stride = before.sh_stride();
        let (mut refitted, mut reshaped, mut banded) = (0, 0, 0);
        for (i, &moved) in moved.iter().enumerate() {
            let sh = |set: &GaussianSet| set.sh[i * stride..(i + 1) * stride].to_vec();
            let shape = before.opacity_logit[i].to_bits() == fitted.opacity_logit[i].to_bits()
                && before.log_scale[i] == fitted.log_scale[i];
            let (a, b) = (sh(before), sh(&fitted));
            let same = shape && a == b;
            assert!(
                moved || same,
                "Gaussian {i}: its light stayed, yet it moved"
            );
            refitted += usize::from(!same);
            reshaped += usize::from(!shape);
            banded += usize::from(a[3..] != b[3..]);
        }
        // Not in colour alone: opacity, reach and the view-dependent bands
        // move too, as a seam's do.
        assert!(
            refitted > 0 && reshaped > 0,
            "{refitted} refitted, {reshaped} reshaped"
        );
        assert!(stride == 3 || banded > 0, "no band moved");

        recipe.post.shading = Shading::Kept;
        let kept = engine.compose(&recipe.resolve(engine.database()).unwrap());
        let (same, report) = fit_seams(&engine, &kept, &options, &mut |_, _| {}).unwrap();
        assert_eq!(report.fitted, 0);
        assert_eq!(same.sh, kept.gaussians.sh);
    }

    #[test]
    fn a_target_is_relit_pixel_by_pixel_but_in_the_mouth() {
        let engine = two_people(3_000);
        let model = &engine.database().model;
        let composite = mouth_swap(&engine, false);
        let light = PixelLight::new(&engine, &composite, &[0, 1]);
        let region_triangle =
            |r: Region| model.triangle_regions.iter().position(|&x| x == r).unwrap() as u32;
        let at = [1.0 / 3.0; 3];
        // A triangle of the mouth's inside whose light the shape moved, for
        // the source the skin's light would relight there.
        let teeth = (0..model.triangles.len() as u32)
            .find(|&t| {
                inner(model.triangle_regions[t as usize])
                    && light.gain(1, model.triangles[t as usize], at) != Vec3::ONE
            })
            .expect("a mouth's inside the skin's light would relight");
        let skin = region_triangle(Region::Skin);
        let hits = [Some((teeth, at, 1.0)), Some((skin, at, 1.0)), None];
        let relit = vec![0.9; 9];
        let part = |person: usize, value: f64| Part {
            person,
            colour: vec![value; 9],
            coverage: None,
        };
        let parts = [part(0, 0.2), part(1, 0.1)];
        let out = relit_target(model, &light, &hits, &relit, &parts);
        // The teeth show their parts as drawn (as trained, placed by their
        // own faces), not the whole with the per-Gaussian light, and not
        // relit where the skin's light would relight them.
        for value in &out[0..3] {
            assert!(
                (value - 0.3).abs() < 1e-12,
                "the teeth are not relit: {value}"
            );
        }
        assert_eq!(&out[6..9], &[0.9; 3], "off the surface nothing is relit");
        // The base on its own shape keeps its light; source 1's is relit.
        let corners = model.triangles[skin as usize];
        assert_eq!(light.gain(0, corners, at), Vec3::ONE);
        let gain = light.gain(1, corners, at);
        for c in 0..3 {
            let expected = 0.2 + 0.1 * f64::from(gain[c]);
            assert!((out[3 + c] - expected).abs() < 1e-12);
        }
        // A source without a light, or past the database, is not relit.
        assert_eq!(light.gain(7, corners, at), Vec3::ONE);
    }
}
