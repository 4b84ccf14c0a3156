//! The built-in database: 14 deterministic synthetic source avatars on the
//! procedural head, with distinct shapes, hair volume, skin tones (light to dark),
//! hair, brow, lip, iris and clothing colours, and Gaussians bound to triangles by
//! the GaussianAvatars convention with SH degree 3 and small view-dependent terms.

use glam::{Quat, Vec2, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::binding::{triangle_frames, world_to_local, WorldGaussian};
use super::database::{Database, SourceAvatar};
use super::gaussians::{logit, rgb_to_dc, sh_coefficients, GaussianSet, SH_C1};
use crate::model::builtin::layout::{Side, EYE_CENTER, EYE_OPENING, MOUTH_Y};
use crate::model::geometry::{fractal_noise, lerp, smoothstep, value_noise};
use crate::model::head::HeadModel;
use crate::model::motion::{builtin_motion, builtin_motions, BUILTIN_MOTIONS};
use crate::model::regions::Region;

/// How the built-in database is generated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SyntheticOptions {
    /// Seed for shapes, textures and Gaussian placement.
    pub seed: u64,
    /// Number of sources (1..=14).
    pub sources: usize,
    /// Gaussians per avatar (at least one per triangle is always placed).
    pub gaussians_per_avatar: usize,
}

impl Default for SyntheticOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            sources: MAX_SOURCES,
            gaussians_per_avatar: 50_000,
        }
    }
}

/// SH degree of the synthetic avatars.
pub const SYNTHETIC_SH_DEGREE: u8 = 3;

/// The appearance of one synthetic person (sRGB colours in 0..1).
#[derive(Clone, Copy)]
struct Look {
    name: &'static str,
    skin: [f32; 3],
    hair: [f32; 3],
    lips: [f32; 3],
    iris: [f32; 3],
    shirt: [f32; 3],
    /// Hair volume in metres at the crown.
    hair_thickness: f32,
    /// 0 = clean shaven, 1 = full beard.
    beard: f32,
    /// Amount of freckles / skin spots.
    freckles: f32,
}

// One row per person reads best as a table; a builder would hide the data.
#[allow(clippy::too_many_arguments)]
const fn look(
    name: &'static str,
    skin: [f32; 3],
    hair: [f32; 3],
    lips: [f32; 3],
    iris: [f32; 3],
    shirt: [f32; 3],
    hair_thickness: f32,
    beard: f32,
    freckles: f32,
) -> Look {
    Look {
        name,
        skin,
        hair,
        lips,
        iris,
        shirt,
        hair_thickness,
        beard,
        freckles,
    }
}

const BLACK: [f32; 3] = [0.05, 0.04, 0.035];
const DARK_BROWN: [f32; 3] = [0.17, 0.10, 0.06];
const BROWN: [f32; 3] = [0.32, 0.20, 0.11];
const AUBURN: [f32; 3] = [0.45, 0.17, 0.07];
const BLONDE: [f32; 3] = [0.80, 0.66, 0.40];
const PLATINUM: [f32; 3] = [0.88, 0.85, 0.76];
const GREY: [f32; 3] = [0.56, 0.55, 0.54];
const BLUE_EYES: [f32; 3] = [0.30, 0.45, 0.62];
const GREEN_EYES: [f32; 3] = [0.33, 0.45, 0.28];
const BROWN_EYES: [f32; 3] = [0.30, 0.17, 0.08];
const DARK_EYES: [f32; 3] = [0.14, 0.08, 0.05];
const HAZEL_EYES: [f32; 3] = [0.45, 0.35, 0.16];

/// The 14 synthetic people, skin from light to dark.
const LOOKS: [Look; 14] = [
    look(
        "ada",
        [0.96, 0.83, 0.74],
        AUBURN,
        [0.82, 0.48, 0.47],
        GREEN_EYES,
        [0.20, 0.32, 0.55],
        0.018,
        0.0,
        0.8,
    ),
    look(
        "bram",
        [0.94, 0.79, 0.68],
        BLONDE,
        [0.78, 0.50, 0.46],
        BLUE_EYES,
        [0.85, 0.85, 0.82],
        0.008,
        0.5,
        0.2,
    ),
    look(
        "cleo",
        [0.92, 0.76, 0.64],
        PLATINUM,
        [0.80, 0.42, 0.45],
        BLUE_EYES,
        [0.10, 0.10, 0.12],
        0.020,
        0.0,
        0.0,
    ),
    look(
        "dries",
        [0.89, 0.72, 0.60],
        BROWN,
        [0.72, 0.45, 0.40],
        HAZEL_EYES,
        [0.55, 0.12, 0.12],
        0.010,
        0.0,
        0.1,
    ),
    look(
        "elif",
        [0.86, 0.68, 0.55],
        DARK_BROWN,
        [0.70, 0.38, 0.36],
        BROWN_EYES,
        [0.30, 0.50, 0.35],
        0.022,
        0.0,
        0.0,
    ),
    look(
        "femi",
        [0.82, 0.64, 0.50],
        GREY,
        [0.68, 0.42, 0.38],
        GREEN_EYES,
        [0.45, 0.45, 0.48],
        0.006,
        0.8,
        0.0,
    ),
    look(
        "gaia",
        [0.78, 0.59, 0.45],
        DARK_BROWN,
        [0.66, 0.36, 0.33],
        HAZEL_EYES,
        [0.90, 0.72, 0.30],
        0.016,
        0.0,
        0.3,
    ),
    look(
        "hiro",
        [0.73, 0.54, 0.40],
        BLACK,
        [0.62, 0.38, 0.33],
        DARK_EYES,
        [0.15, 0.20, 0.30],
        0.012,
        0.2,
        0.0,
    ),
    look(
        "ines",
        [0.67, 0.48, 0.35],
        BLACK,
        [0.56, 0.30, 0.28],
        BROWN_EYES,
        [0.60, 0.25, 0.45],
        0.021,
        0.0,
        0.0,
    ),
    look(
        "jomo",
        [0.60, 0.42, 0.30],
        BLACK,
        [0.48, 0.28, 0.25],
        DARK_EYES,
        [0.92, 0.92, 0.90],
        0.005,
        0.6,
        0.0,
    ),
    look(
        "kemi",
        [0.53, 0.36, 0.25],
        DARK_BROWN,
        [0.44, 0.24, 0.22],
        BROWN_EYES,
        [0.20, 0.45, 0.45],
        0.019,
        0.0,
        0.0,
    ),
    look(
        "luca",
        [0.46, 0.31, 0.21],
        BLACK,
        [0.40, 0.22, 0.19],
        DARK_EYES,
        [0.35, 0.30, 0.22],
        0.009,
        0.3,
        0.0,
    ),
    look(
        "mele",
        [0.39, 0.26, 0.18],
        BLACK,
        [0.34, 0.19, 0.16],
        BROWN_EYES,
        [0.75, 0.35, 0.15],
        0.017,
        0.0,
        0.0,
    ),
    look(
        "nuru",
        [0.31, 0.20, 0.14],
        GREY,
        [0.28, 0.15, 0.13],
        DARK_EYES,
        [0.12, 0.12, 0.15],
        0.007,
        0.4,
        0.0,
    ),
];

/// Most sources the built-in database can generate.
pub const MAX_SOURCES: usize = LOOKS.len();

/// Generates the built-in database on `model` (usually the procedural head).
pub fn builtin_database(model: HeadModel, options: SyntheticOptions) -> Result<Database, String> {
    if options.sources == 0 || options.sources > MAX_SOURCES {
        return Err(format!(
            "the built-in database has 1 to {MAX_SOURCES} sources, not {}",
            options.sources
        ));
    }
    let normals = vertex_normals(&model.template, &model.triangles);
    let sources: Vec<SourceAvatar> = (0..options.sources)
        .into_par_iter()
        .map(|i| make_source(&model, &normals, i, &options))
        .collect();
    let motions = builtin_motions(model.expression_basis.names());
    Ok(Database {
        label: "builtin".into(),
        fingerprint: format!(
            "builtin v1 seed={} sources={} gaussians_per_avatar={}",
            options.seed, options.sources, options.gaussians_per_avatar
        ),
        model,
        sources,
        motions,
    })
}

fn make_source(
    model: &HeadModel,
    normals: &[Vec3],
    index: usize,
    options: &SyntheticOptions,
) -> SourceAvatar {
    let look = &LOOKS[index];
    let mut rng =
        ChaCha8Rng::seed_from_u64(options.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ index as u64);
    let shape: Vec<f32> = (0..model.shape_basis.len())
        .map(|_| {
            // Sum of uniforms: bell-shaped, bounded to ±1.5.
            let u: f32 = (0..3).map(|_| rng.random::<f32>()).sum();
            u - 1.5
        })
        .collect();
    let static_offset: Vec<glam::DVec3> = hair_offset(model, normals, look)
        .iter()
        .map(|o| o.as_dvec3())
        .collect();
    let neutral = model.neutral(&shape, Some(&static_offset));
    let motion_name = BUILTIN_MOTIONS[index % BUILTIN_MOTIONS.len()];
    let motion = builtin_motion(
        motion_name,
        model.expression_basis.names(),
        index as u64 + 1,
    )
    .expect("built-in motion name");
    let gaussians = place_gaussians(
        model,
        &neutral,
        look,
        &mut rng,
        options.gaussians_per_avatar,
    );
    SourceAvatar {
        name: look.name.to_string(),
        shape,
        static_offset,
        motion,
        gaussians,
        attributes: look_attributes(look),
    }
}

/// Skin luma (Rec. 709 weights on sRGB) at or above which a built-in person
/// is labelled light-skinned, and below which dark-skinned, with `medium` in
/// between.
const LIGHT_SKIN_LUMA: f32 = 0.6;
/// See [`LIGHT_SKIN_LUMA`].
const DARK_SKIN_LUMA: f32 = 0.4;
/// Crown hair volume (metres) from which hair counts as long.
const LONG_HAIR: f32 = 0.015;

/// The labels a built-in person carries: `skin_tone` (light, medium, dark),
/// `facial_hair` (beard, none) and `hair` (long, short). They play the part
/// of the thesis's skin-tone and gender labels in study constraints.
fn look_attributes(look: &Look) -> std::collections::BTreeMap<String, String> {
    let luma = 0.2126 * look.skin[0] + 0.7152 * look.skin[1] + 0.0722 * look.skin[2];
    let skin_tone = if luma >= LIGHT_SKIN_LUMA {
        "light"
    } else if luma >= DARK_SKIN_LUMA {
        "medium"
    } else {
        "dark"
    };
    let facial_hair = if look.beard > 0.0 { "beard" } else { "none" };
    let hair = if look.hair_thickness >= LONG_HAIR {
        "long"
    } else {
        "short"
    };
    [
        ("skin_tone", skin_tone),
        ("facial_hair", facial_hair),
        ("hair", hair),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v.to_string()))
    .collect()
}

/// Area-weighted vertex normals.
pub fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let face = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += face;
        }
    }
    n.into_iter().map(|v| v.normalize_or_zero()).collect()
}

/// Height of the hairline at an azimuth (0 = front, π = back), in metres.
fn hairline(azimuth: f32) -> f32 {
    let temples = lerp(0.072, 0.035, smoothstep(0.45, 1.3, azimuth));
    lerp(temples, -0.05, smoothstep(1.7, 2.4, azimuth))
}

/// Hair volume: the scalp pushed out along its normal, thickest at the crown and
/// fading out at the hairline.
fn hair_offset(model: &HeadModel, normals: &[Vec3], look: &Look) -> Vec<Vec3> {
    let mut on_scalp = vec![false; model.vertex_count()];
    for (t, r) in model.triangles.iter().zip(&model.triangle_regions) {
        if matches!(r, Region::Hair | Region::Remainder) {
            for &i in t {
                on_scalp[i as usize] = true;
            }
        }
    }
    model
        .template
        .iter()
        .zip(normals)
        .zip(on_scalp)
        .map(|((&p, &n), scalp)| {
            if !scalp {
                return Vec3::ZERO;
            }
            let azimuth = p.x.atan2(p.z).abs();
            let above = p.y - hairline(azimuth);
            let fade = smoothstep(-0.004, 0.02, above);
            let crown = 0.6 + 0.4 * smoothstep(0.0, 0.1, p.y);
            n * look.hair_thickness * fade * crown
        })
        .collect()
}

/// Relative Gaussian density per region (per unit area).
fn region_density(region: Region) -> f32 {
    match region {
        Region::LeftEyeball | Region::RightEyeball => 2.5,
        Region::LeftEyeRegion | Region::RightEyeRegion | Region::Lips => 2.5,
        Region::Nose | Region::TeethUpper | Region::TeethLower => 1.6,
        Region::Skin | Region::LeftEar | Region::RightEar => 1.3,
        Region::Hair => 1.2,
        Region::LeftEyeSocket | Region::RightEyeSocket | Region::LipsInside => 0.7,
        Region::Boundary => 0.6,
        Region::Neck | Region::Remainder => 0.9,
    }
}

/// Splits `total` Gaussians over triangles in proportion to `weights`, at least
/// one each (largest remainder method; deterministic).
pub fn allocate(weights: &[f32], total: usize) -> Vec<usize> {
    let n = weights.len();
    let extra = total.saturating_sub(n);
    let sum: f64 = weights.iter().map(|&w| w.max(0.0) as f64).sum();
    if sum <= 0.0 {
        return vec![1 + extra / n.max(1); n];
    }
    let shares: Vec<f64> = weights
        .iter()
        .map(|&w| w.max(0.0) as f64 / sum * extra as f64)
        .collect();
    let mut counts: Vec<usize> = shares.iter().map(|s| 1 + s.floor() as usize).collect();
    let mut left = total.saturating_sub(counts.iter().sum());
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        let fa = shares[a] - shares[a].floor();
        let fb = shares[b] - shares[b].floor();
        fb.total_cmp(&fa).then(a.cmp(&b))
    });
    for &i in order.iter().cycle().take(n * 2) {
        if left == 0 {
            break;
        }
        counts[i] += 1;
        left -= 1;
    }
    counts
}

/// Steps of the R2 low-discrepancy sequence (inverse powers of the plastic number).
const R2: (f32, f32) = (0.754_877_7, 0.569_840_3);

fn place_gaussians(
    model: &HeadModel,
    neutral: &[Vec3],
    look: &Look,
    rng: &mut ChaCha8Rng,
    total: usize,
) -> GaussianSet {
    let frames = triangle_frames(neutral, &model.triangles);
    let areas: Vec<f32> = model
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| neutral[i as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .collect();
    let weights: Vec<f32> = areas
        .iter()
        .zip(&model.triangle_regions)
        .map(|(a, r)| a * region_density(*r))
        .collect();
    let counts = allocate(&weights, total);
    let normals = vertex_normals(neutral, &model.triangles);
    let occlusion = cavity_occlusion(neutral, &normals, &model.triangles);
    let mut set = GaussianSet::with_degree(SYNTHETIC_SH_DEGREE);
    let coefficients = sh_coefficients(SYNTHETIC_SH_DEGREE);
    let mut sh = vec![0.0f32; 3 * coefficients];
    for (t, (&count, tri)) in counts.iter().zip(&model.triangles).enumerate() {
        let region = model.triangle_regions[t];
        let frame = &frames[t];
        let [a, b, c] = tri.map(|i| neutral[i as usize]);
        let [ta, tb, tc] = tri.map(|i| model.template[i as usize]);
        let [na, nb, nc] = tri.map(|i| normals[i as usize]);
        let [oa, ob, oc] = tri.map(|i| occlusion[i as usize]);
        let normal = frame.rotation.y_axis;
        let spacing = (areas[t] / count as f32).sqrt().max(1e-5);
        // Low-discrepancy (R2 sequence) positions cover the triangle evenly, the way a
        // trained avatar leaves no holes; a random start keeps triangles different.
        let start = (rng.random::<f32>(), rng.random::<f32>());
        for k in 0..count {
            let (mut u, mut v) = (
                (start.0 + k as f32 * R2.0).fract(),
                (start.1 + k as f32 * R2.1).fract(),
            );
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let on_surface = a + u * (b - a) + v * (c - a);
            // Texture coordinates follow the template so features stay put across shapes.
            let texel = ta + u * (tb - ta) + v * (tc - ta);
            let hairy = region == Region::Hair;
            let lift = if hairy {
                rng.random::<f32>() * 0.3 * look.hair_thickness.max(0.002)
            } else {
                (rng.random::<f32>() - 0.5) * 0.3 * spacing
            };
            let position = on_surface + normal * lift;
            let jitter = 0.8 + 0.4 * rng.random::<f32>();
            let (sigma, angle) = if hairy {
                let flow = hair_flow(texel, normal, frame.rotation);
                (
                    Vec3::new(1.7 * spacing, 0.12 * spacing, 0.35 * spacing) * jitter,
                    flow,
                )
            } else {
                (
                    Vec3::new(0.85 * spacing, 0.12 * spacing, 0.85 * spacing) * jitter,
                    rng.random::<f32>() * std::f32::consts::TAU,
                )
            };
            let local_rotation = Quat::from_rotation_y(angle);
            let world = WorldGaussian {
                position,
                rotation: frame.quat * local_rotation,
                scale: sigma,
            };
            let (local_position, _, log_scale) = world_to_local(frame, &world);
            let smooth_normal = (na + u * (nb - na) + v * (nc - na)).normalize_or(normal);
            let ao = oa + u * (ob - oa) + v * (oc - oa);
            let rgb = scale(
                surface_colour(look, region, texel, rng),
                baked_light(smooth_normal, ao),
            );
            let opacity = if hairy {
                0.80 + 0.15 * rng.random::<f32>()
            } else {
                0.94 + 0.05 * rng.random::<f32>()
            };
            let shine = specularity(region);
            fill_sh(&mut sh, rgb, normal, shine, rng);
            set.push(
                t as u32,
                local_position,
                local_rotation,
                log_scale,
                logit(opacity),
                &sh,
            );
        }
    }
    set
}

/// The opaque surface of built-in source `index` as a camera sees it (what
/// `visage capture` draws): the procedural colour of the point at template
/// position `texel` in `region`, under the baked studio light for `normal` and
/// ambient `occlusion`. The grain noise is a function of the texel, so every
/// camera sees the same surface.
pub fn surface_radiance(
    index: usize,
    region: Region,
    texel: Vec3,
    normal: Vec3,
    occlusion: f32,
) -> [f32; 3] {
    surface_radiance_toned(index, index, region, texel, normal, occlusion)
}

/// [`surface_radiance`] of source `index` wearing the skin of source
/// `skin_of`: its skin tone and skin detail (freckles), with `index`'s own
/// lips, iris, brows, hair, beard and clothes — a composite's appearance
/// when its skin tone is matched to its base.
pub fn surface_radiance_toned(
    index: usize,
    skin_of: usize,
    region: Region,
    texel: Vec3,
    normal: Vec3,
    occlusion: f32,
) -> [f32; 3] {
    let cell = (texel / 0.0005).round().as_ivec3();
    let seed = (cell.x as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
        ^ (cell.y as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
        ^ (cell.z as u64).wrapping_mul(0x1656_67b1_9e37_79f9);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let skin = &LOOKS[skin_of % LOOKS.len()];
    let look = Look {
        skin: skin.skin,
        freckles: skin.freckles,
        ..LOOKS[index % LOOKS.len()]
    };
    scale(
        surface_colour(&look, region, texel, &mut rng),
        baked_light(normal, occlusion),
    )
}

/// The index of the built-in person called `name` (their appearance), if any:
/// a trained avatar of a built-in source wears the same surface.
pub fn look_index(name: &str) -> Option<usize> {
    LOOKS.iter().position(|l| l.name == name)
}

/// Direction of the studio key light baked into the synthetic captures.
const KEY_LIGHT: Vec3 = Vec3::new(0.35, 0.55, 0.76);

/// Brightness of a surface point under the baked studio light: a soft wrapped key
/// light times ambient occlusion.
fn baked_light(normal: Vec3, occlusion: f32) -> f32 {
    let wrap = ((normal.dot(KEY_LIGHT.normalize()) + 0.4) / 1.4).max(0.0);
    occlusion * (0.55 + 0.5 * wrap)
}

/// Per-vertex ambient occlusion estimated from concavity: how far the vertex
/// lies below the centroid of its neighbours, relative to the local edge length.
pub fn cavity_occlusion(positions: &[Vec3], normals: &[Vec3], triangles: &[[u32; 3]]) -> Vec<f32> {
    let mut sum = vec![Vec3::ZERO; positions.len()];
    let mut count = vec![0u32; positions.len()];
    for t in triangles {
        for k in 0..3 {
            let (i, j, l) = (
                t[k] as usize,
                t[(k + 1) % 3] as usize,
                t[(k + 2) % 3] as usize,
            );
            sum[i] += positions[j] + positions[l];
            count[i] += 2;
        }
    }
    (0..positions.len())
        .map(|i| {
            if count[i] == 0 {
                return 1.0;
            }
            let centroid = sum[i] / count[i] as f32;
            let spread = (centroid - positions[i]).length().max(1e-6);
            let depth = (centroid - positions[i]).dot(normals[i]) / spread;
            (1.0 - 0.3 * depth.max(0.0)).clamp(0.55, 1.0)
        })
        .collect()
}

/// In-plane angle (about the triangle normal, in the local frame) that aligns a
/// hair Gaussian with the hair flow: away from the crown, then down.
fn hair_flow(p: Vec3, normal: Vec3, rotation: glam::Mat3) -> f32 {
    let crown = Vec3::new(0.0, 0.13, -0.03);
    let away = (p - crown).normalize_or(Vec3::NEG_Y) + Vec3::new(0.0, -0.6, 0.0);
    let tangent = (away - normal * away.dot(normal)).normalize_or(rotation.x_axis);
    let local = rotation.transpose() * tangent;
    // Rotation about local y maps x to (cos θ, 0, -sin θ).
    (-local.z).atan2(local.x)
}

fn specularity(region: Region) -> f32 {
    match region {
        Region::LeftEyeball | Region::RightEyeball => 0.14,
        Region::Lips | Region::TeethUpper | Region::TeethLower => 0.08,
        Region::Nose => 0.05,
        Region::Hair => 0.06,
        _ => 0.03,
    }
}

/// Writes SH coefficients: the DC colour, a first-order term that brightens the
/// Gaussian when seen along its normal (a soft highlight), and faint higher-order
/// noise. Layout is coefficient-major, see `GaussianSet`.
fn fill_sh(sh: &mut [f32], rgb: [f32; 3], normal: Vec3, shine: f32, rng: &mut ChaCha8Rng) {
    for ch in 0..3 {
        sh[ch] = rgb_to_dc(rgb[ch]);
        // 3DGS evaluates C1·(−y·f1 + z·f2 − x·f3) with d = normalize(μ − camera);
        // choosing f = shine·(n.y, −n.z, n.x)/C1 gives −shine·(n·d), positive when facing.
        sh[3 + ch] = shine * normal.y / SH_C1;
        sh[6 + ch] = -shine * normal.z / SH_C1;
        sh[9 + ch] = shine * normal.x / SH_C1;
    }
    for v in sh.iter_mut().skip(12) {
        *v = (rng.random::<f32>() - 0.5) * 0.02;
    }
}

fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [
        lerp(a[0], b[0], t),
        lerp(a[1], b[1], t),
        lerp(a[2], b[2], t),
    ]
}

fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    a.map(|x| (x * s).clamp(0.0, 1.0))
}

/// Colour of a point of the face by region, with procedural texture.
fn surface_colour(look: &Look, region: Region, p: Vec3, rng: &mut ChaCha8Rng) -> [f32; 3] {
    let grain = 0.94 + 0.12 * rng.random::<f32>();
    let rgb = match region {
        Region::LeftEyeball | Region::RightEyeball => eyeball_colour(look, p),
        Region::TeethUpper | Region::TeethLower => {
            let gap = smoothstep(0.15, 0.0, ((p.x / 0.0042).fract().abs() - 0.5).abs());
            scale([0.93, 0.90, 0.80], 1.0 - 0.25 * gap)
        }
        Region::LipsInside => [0.50, 0.16, 0.17],
        Region::LeftEyeSocket | Region::RightEyeSocket => [0.62, 0.30, 0.30],
        Region::Hair => hair_colour(look, p),
        _ => skin_colour(look, region, p),
    };
    scale(rgb, grain)
}

fn eyeball_colour(look: &Look, p: Vec3) -> [f32; 3] {
    let side = if p.x >= 0.0 { Side::Left } else { Side::Right };
    let d = (p - side.place(EYE_CENTER)).normalize_or(Vec3::Z);
    let polar = d.z.clamp(-1.0, 1.0).acos();
    if polar < 0.17 {
        return [0.02, 0.02, 0.02];
    }
    if polar < 0.43 {
        let azimuth = d.y.atan2(d.x);
        let streak = value_noise(Vec3::new(azimuth * 6.0, polar * 10.0, 0.0), 11);
        let limbus = smoothstep(0.34, 0.43, polar);
        return scale(look.iris, (0.75 + 0.5 * streak) * (1.0 - 0.5 * limbus));
    }
    let veins = smoothstep(0.75, 0.95, fractal_noise(p * 900.0, 5)) * smoothstep(0.8, 1.4, polar);
    mix([0.93, 0.91, 0.88], [0.80, 0.35, 0.33], 0.5 * veins)
}

fn hair_colour(look: &Look, p: Vec3) -> [f32; 3] {
    let strands = fractal_noise(Vec3::new(p.x * 900.0, p.y * 120.0, p.z * 900.0), 3);
    let highlight = smoothstep(0.55, 0.9, fractal_noise(p * 60.0, 9));
    scale(look.hair, 0.75 + 0.45 * strands + 0.25 * highlight)
}

fn skin_colour(look: &Look, region: Region, p: Vec3) -> [f32; 3] {
    let blotch = fractal_noise(p * 70.0, 21) - 0.5;
    let pores = value_noise(p * 900.0, 22) - 0.5;
    let mut rgb = scale(look.skin, 1.0 + 0.10 * blotch + 0.05 * pores);
    // Warmer cheeks, nose tip and ears.
    let flush = (-((Vec2::new(p.x.abs() - 0.045, p.y + 0.03)).length_squared() / 0.0004)).exp()
        + 0.6 * (-((Vec2::new(p.x, p.y + 0.035)).length_squared() / 0.0001)).exp();
    let ear = matches!(region, Region::LeftEar | Region::RightEar) as u8 as f32;
    rgb = mix(
        rgb,
        scale([0.85, 0.45, 0.42], look.skin[0]),
        0.18 * flush + 0.12 * ear,
    );
    if look.freckles > 0.0 && p.z > 0.04 {
        let spots = smoothstep(0.72, 0.8, value_noise(p * 500.0, 31));
        rgb = mix(rgb, scale(look.skin, 0.72), look.freckles * spots * 0.6);
    }
    match region {
        Region::Lips => {
            let d = Vec2::new(p.x / 0.026, (p.y - MOUTH_Y) / 0.011).length();
            rgb = mix(rgb, look.lips, smoothstep(1.05, 0.75, d));
        }
        Region::LeftEyeRegion | Region::RightEyeRegion => {
            let side = if p.x >= 0.0 { Side::Left } else { Side::Right };
            let e = side.place(EYE_CENTER);
            let d = Vec2::new((p.x - e.x) / EYE_OPENING.x, (p.y - e.y) / EYE_OPENING.y);
            // Lashes along the upper lid margin, a shadow in the crease, the brow above.
            let lash = smoothstep(1.45, 1.0, d.length()) * smoothstep(-0.2, 0.3, d.y);
            rgb = mix(rgb, [0.05, 0.04, 0.04], 0.85 * lash);
            let brow_y = e.y + 0.015 + 0.004 * (1.0 - ((p.x - e.x) / 0.02).powi(2));
            let brow = smoothstep(0.0035, 0.0015, (p.y - brow_y).abs())
                * smoothstep(0.024, 0.016, (p.x - e.x).abs());
            let hairs = 0.6 + 0.4 * value_noise(Vec3::new(p.x * 2000.0, p.y * 400.0, 0.0), 41);
            rgb = mix(rgb, scale(look.hair, 0.8), 0.9 * brow * hairs);
        }
        Region::Neck | Region::Boundary => {
            let collar = smoothstep(-0.150, -0.156, p.y);
            rgb = mix(scale(rgb, 0.93), look.shirt, collar);
        }
        Region::Remainder => {
            let azimuth = p.x.atan2(p.z).abs();
            let near_hair = smoothstep(-0.02, 0.0, p.y - hairline(azimuth));
            rgb = mix(rgb, hair_colour(look, p), near_hair);
        }
        _ => {}
    }
    if look.beard > 0.0 && p.z > 0.0 {
        let jaw = smoothstep(-0.04, -0.06, p.y) * smoothstep(0.02, 0.05, p.z);
        let moustache =
            (-((Vec2::new(p.x / 0.03, (p.y - MOUTH_Y - 0.009) / 0.005)).length_squared())).exp();
        let away_from_lips = smoothstep(
            0.8,
            1.2,
            Vec2::new(p.x / 0.026, (p.y - MOUTH_Y) / 0.011).length(),
        );
        let stubble = smoothstep(0.35, 0.65, value_noise(p * 1400.0, 51));
        let cover = look.beard * (jaw.max(moustache)) * away_from_lips * (0.5 + 0.5 * stubble);
        rgb = mix(rgb, scale(look.hair, 0.7), cover.min(1.0));
    }
    rgb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allocation_gives_every_triangle_one_and_hits_the_total() {
        let counts = allocate(&[1.0, 0.0, 3.0, 0.5], 20);
        assert_eq!(counts.iter().sum::<usize>(), 20);
        assert!(counts.iter().all(|&c| c >= 1));
        assert!(counts[2] > counts[0] && counts[0] > counts[1]);
        // Fewer Gaussians than triangles still gives one each.
        assert_eq!(allocate(&[1.0; 5], 2), vec![1; 5]);
    }

    #[test]
    fn skin_tones_go_from_light_to_dark() {
        let luma = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        for pair in LOOKS.windows(2) {
            assert!(luma(pair[0].skin) > luma(pair[1].skin), "{}", pair[1].name);
        }
    }
}
