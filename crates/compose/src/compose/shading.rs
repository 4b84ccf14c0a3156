//! Baked light under a new shape (docs/method.md §7.10). A trained avatar's
//! colours hold the light of its capture: a cheek facing the key light is
//! brighter than one turned away, a hollow darker than an open cheek. A
//! composite moves a source's Gaussians onto the blended face, where many
//! triangles face another way and hollows deepen or open, but their colours
//! still say how the source's own face was lit. Each source's light is
//! estimated from its own skin — colour as a linear function of the surface
//! normal, darkened in proportion to how far the surface lies in a hollow,
//! c = (a + b·n)·(1 + e·κ) per channel (first-order irradiance times an
//! ambient occlusion; the skin's albedo is taken as even) — and every
//! Gaussian moved onto a triangle whose exposure changed is relit by the
//! ratio of that light there to the light it had.

use glam::{DVec3, Vec3, Vec4};

use super::colour::{colour_weight, srgb_to_lab};
use super::skin_transfer::{skin_likeness, SkinStats};
use crate::avatar::gaussians::{dc_to_rgb, GaussianSet};
use crate::avatar::synthetic::vertex_normals;

/// Largest and smallest relighting gain: a turn that would change a colour
/// more than this is more likely a bad fit or a degenerate triangle.
pub const RELIGHT_RANGE: (f32, f32) = (0.5, 2.0);

/// A gain this close to one is a normal that moved by rounding alone.
const ROUNDING: f32 = 1e-5;

/// Fewest skin Gaussians a light is fitted to.
const MIN_SAMPLES: usize = 64;

/// Weighted variance of the samples' cavity below which it tells the light
/// nothing (a surface without hollows): the fit leaves the term out.
const MIN_CAVITY_VARIANCE: f64 = 1e-6;

/// The most a unit of cavity depth may take of the light (e ≥ −0.9), so
/// that a hollow keeps some: an occlusion that put a pit out entirely
/// would relight by dividing by nothing.
const MAX_OCCLUSION: f32 = 0.9;

/// Rounds of the occlusion's alternating fit ([`BakedLight::fit_occlusion`])
/// at most;
/// it stops sooner once e moves by less than [`OCCLUSION_SETTLED`].
const OCCLUSION_ROUNDS: usize = 50;

/// A change of e (per channel, per unit of cavity depth) under which the
/// occlusion's fit has settled.
const OCCLUSION_SETTLED: f64 = 1e-7;

/// What the light baked at a point of a surface depends on: which way the
/// surface faces and how far it lies in a hollow.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Exposure {
    /// Unit normal (zero where the surface has none).
    pub normal: Vec3,
    /// Cavity depth (≥ 0; zero on convex and flat surface), see [`cavities`].
    pub cavity: f32,
}

/// The light a source's skin shows: per channel, brightness
/// (a + b·n)·(1 + e·κ) for a surface of unit normal n in a hollow of cavity
/// depth κ (−0.9 ≤ e ≤ 0: hollows are shaded by the rest of the face, and
/// the shade takes a share of whatever light reaches them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakedLight {
    /// Per channel (r, g, b): (bx, by, bz, a).
    channels: [Vec4; 3],
    /// Per channel: e, the share of the light a unit of cavity depth takes
    /// away.
    occlusion: Vec3,
}

/// A light's coefficients in f64 while it is fitted: per channel (a, bx,
/// by, bz), and per channel a cavity term (a brightness in the additive
/// first step, a share of the light after).
type Coefficients = ([[f64; 4]; 3], DVec3);

/// a + b·n per channel, of coefficients (a, bx, by, bz) per channel.
fn unoccluded_brightness(channels: &[[f64; 4]; 3], normal: Vec3) -> DVec3 {
    let n = normal.as_dvec3();
    DVec3::from_array(channels.map(|[a, x, y, z]| a + x * n.x + y * n.y + z * n.z))
}

/// Adds one sample's row `x`, weighted `w`, to a least-squares normal
/// matrix: w·x·xᵀ over its leading `x.len()` rows and columns.
fn add_outer(system: &mut [[f64; 5]; 5], x: &[f64], w: f64) {
    for (row, &xi) in system.iter_mut().zip(x) {
        for (entry, &xj) in row.iter_mut().zip(x) {
            *entry += w * xi * xj;
        }
    }
}

/// e kept within [−[`MAX_OCCLUSION`], 0] per channel.
fn clamp_occlusion(e: DVec3) -> DVec3 {
    e.clamp(DVec3::splat(-MAX_OCCLUSION as f64), DVec3::ZERO)
}

impl BakedLight {
    /// The light of these per-channel (a, bx, by, bz) and occlusion terms e.
    pub fn new(channels: [[f64; 4]; 3], occlusion: Vec3) -> BakedLight {
        BakedLight {
            channels: channels
                .map(|[a, x, y, z]| Vec4::new(x as f32, y as f32, z as f32, a as f32)),
            occlusion,
        }
    }

    /// Fits the light to skin samples: each a colour (display RGB), the
    /// exposure of the surface it sits on, and a weight. None when the
    /// samples are too few, do not span enough directions to tell the
    /// light's, or leave a channel dark where they face. The cavity term is
    /// left out where the samples' hollows vary too little to tell it, or
    /// where they would come out brighter (no light does that).
    ///
    /// First the weighted least squares of c ≈ a + b·n + e'·κ (a cavity
    /// that takes the same brightness whatever the light) decides whether
    /// there is a cavity term; where there is, (a + b·n)·(1 + e·κ) is
    /// fitted from there by alternating least squares: (a, b) with e held,
    /// then e with (a, b) held, each step lowering the same squared error.
    pub fn fit(samples: impl IntoIterator<Item = (Vec3, Exposure, f32)>) -> Option<BakedLight> {
        let mut system = [[0.0f64; 5]; 5];
        let mut rhs = [[0.0f64; 5]; 3];
        let mut kept = Vec::new();
        for (colour, exposure, weight) in samples {
            let Exposure { normal: n, cavity } = exposure;
            if !(weight > 0.0 && colour.is_finite() && n.is_finite() && cavity.is_finite()) {
                continue;
            }
            kept.push((colour, exposure, weight));
            let x = [1.0, n.x as f64, n.y as f64, n.z as f64, cavity as f64];
            let w = weight as f64;
            add_outer(&mut system, &x, w);
            for (ch, r) in rhs.iter_mut().enumerate() {
                for (entry, &xi) in r.iter_mut().zip(&x) {
                    *entry += w * xi * colour[ch] as f64;
                }
            }
        }
        if kept.len() < MIN_SAMPLES {
            return None;
        }
        let total = system[0][0].max(f64::MIN_POSITIVE);
        let cavity_variance = system[4][4] / total - (system[0][4] / total).powi(2);
        let with_cavity = cavity_variance > MIN_CAVITY_VARIANCE;
        let occluded = with_cavity
            .then(|| Self::solve(&system, &rhs, true))
            .flatten()
            .filter(|(_, cavity)| cavity.max_element() <= 0.0 && *cavity != DVec3::ZERO)
            .and_then(|additive| Self::fit_occlusion(&kept, additive));
        let (channels, occlusion) = match occluded {
            Some(fitted) => fitted,
            None => Self::solve(&system, &rhs, false)?,
        };
        let light = BakedLight::new(channels, occlusion.as_vec3());
        let mean_normal = Vec3::new(
            (system[0][1] / total) as f32,
            (system[0][2] / total) as f32,
            (system[0][3] / total) as f32,
        );
        let facing = light.brightness(Exposure {
            normal: mean_normal.normalize_or(Vec3::Z),
            cavity: 0.0,
        });
        (light.channels.iter().all(|c| c.is_finite()) && facing.min_element() > 0.05)
            .then_some(light)
    }

    /// The light (a + b·n)·(1 + e·κ) closest to the samples in weighted
    /// squares, from the additive light `start` (a + b·n + e'·κ): e begins
    /// as e' over the samples' mean brightness, then (a, b) and e are
    /// fitted in turn, in f64, until e moves by less than
    /// [`OCCLUSION_SETTLED`] or [`OCCLUSION_ROUNDS`] have run. None where a
    /// step cannot tell (a, b) (normals all alike) or e is not a number;
    /// e stays within [−[`MAX_OCCLUSION`], 0].
    fn fit_occlusion(
        samples: &[(Vec3, Exposure, f32)],
        start: Coefficients,
    ) -> Option<Coefficients> {
        let (mut channels, additive) = start;
        let (mut lit, mut total) = (DVec3::ZERO, 0.0f64);
        for &(_, exposure, weight) in samples {
            lit += weight as f64 * unoccluded_brightness(&channels, exposure.normal);
            total += weight as f64;
        }
        let mut occlusion = clamp_occlusion(additive / (lit / total).max(DVec3::splat(1e-3)));
        for _ in 0..OCCLUSION_ROUNDS {
            channels = Self::fit_unoccluded(samples, occlusion)?;
            let (mut along, mut norm) = (DVec3::ZERO, DVec3::ZERO);
            for &(colour, exposure, weight) in samples {
                let lit = unoccluded_brightness(&channels, exposure.normal);
                let shade = exposure.cavity as f64 * lit;
                along += weight as f64 * shade * (colour.as_dvec3() - lit);
                norm += weight as f64 * shade * shade;
            }
            let best = DVec3::select(norm.cmpgt(DVec3::ZERO), along / norm, DVec3::ZERO);
            if !best.is_finite() {
                return None;
            }
            let next = clamp_occlusion(best);
            let settled = (next - occlusion).abs().max_element() < OCCLUSION_SETTLED;
            occlusion = next;
            if settled {
                break;
            }
        }
        Some((channels, occlusion))
    }

    /// The weighted least squares of c ≈ (a + b·n)·(1 + e·κ) for (a, b) per
    /// channel, with e = `occlusion` held.
    fn fit_unoccluded(
        samples: &[(Vec3, Exposure, f32)],
        occlusion: DVec3,
    ) -> Option<[[f64; 4]; 3]> {
        let mut channels = [[0.0f64; 4]; 3];
        for (ch, out) in channels.iter_mut().enumerate() {
            let mut system = [[0.0f64; 5]; 5];
            let mut rhs = [0.0f64; 5];
            for &(colour, Exposure { normal: n, cavity }, weight) in samples {
                let s = 1.0 + occlusion[ch] * cavity as f64;
                let x = [s, s * n.x as f64, s * n.y as f64, s * n.z as f64];
                let w = weight as f64;
                add_outer(&mut system, &x, w);
                for (entry, &xi) in rhs.iter_mut().zip(&x) {
                    *entry += w * xi * colour[ch] as f64;
                }
            }
            // Scaled by its first entry (the weights times (1 + e·κ)²), so
            // the weights' size does not decide.
            let scale = system[0][0].max(f64::MIN_POSITIVE);
            system.iter_mut().flatten().for_each(|v| *v /= scale);
            rhs.iter_mut().for_each(|v| *v /= scale);
            let x = cholesky_solve(&cholesky(&system, 4)?, &rhs, 4);
            out.copy_from_slice(&x[..4]);
        }
        Some(channels)
    }

    /// Solves the weighted least squares of c ≈ a + b·n + e'·κ
    /// ([`BakedLight::fit`]'s first step), with the cavity term or without;
    /// None for a system that cannot tell the light (normals all alike).
    /// Without it the light is final (e = 0); with it, e' is a brightness,
    /// not yet a share, and only starts [`BakedLight::fit_occlusion`].
    fn solve(
        system: &[[f64; 5]; 5],
        rhs: &[[f64; 5]; 3],
        with_cavity: bool,
    ) -> Option<Coefficients> {
        let n = if with_cavity { 5 } else { 4 };
        // Scaled by the total weight, so its size does not decide.
        let scale = system[0][0].max(f64::MIN_POSITIVE);
        let mut matrix = [[0.0f64; 5]; 5];
        for (i, row) in matrix.iter_mut().enumerate().take(n) {
            for (j, entry) in row.iter_mut().enumerate().take(n) {
                *entry = system[i][j] / scale;
            }
        }
        let factor = cholesky(&matrix, n)?;
        let mut channels = [[0.0f64; 4]; 3];
        let mut cavity = DVec3::ZERO;
        for ch in 0..3 {
            let b: [f64; 5] = std::array::from_fn(|i| rhs[ch][i] / scale);
            let x = cholesky_solve(&factor, &b, n);
            channels[ch].copy_from_slice(&x[..4]);
            cavity[ch] = if with_cavity { x[4] } else { 0.0 };
        }
        Some((channels, cavity))
    }

    /// Brightness per channel of a surface of this exposure.
    pub fn brightness(&self, at: Exposure) -> Vec3 {
        self.unoccluded(at.normal) * (Vec3::ONE + self.occlusion * at.cavity)
    }

    /// Brightness per channel of a surface of unit normal `normal` outside
    /// any hollow: a + b·n.
    fn unoccluded(&self, normal: Vec3) -> Vec3 {
        let x = normal.extend(1.0);
        Vec3::new(
            self.channels[0].dot(x),
            self.channels[1].dot(x),
            self.channels[2].dot(x),
        )
    }

    /// The per-channel gain that relights a colour seen on a surface of
    /// exposure `from` as it would look at `to`: exactly one when they are
    /// equal or differ by rounding (a source's mesh moved whole), one where
    /// the light is too dark to divide by, within [`RELIGHT_RANGE`].
    pub fn gain(&self, from: Exposure, to: Exposure) -> Vec3 {
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

/// Lower-triangular L with L·Lᵀ = the leading n×n block of `m`; None when
/// it is not (numerically) positive definite.
fn cholesky(m: &[[f64; 5]; 5], n: usize) -> Option<[[f64; 5]; 5]> {
    let mut l = [[0.0f64; 5]; 5];
    for i in 0..n {
        for j in 0..=i {
            let sum: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = m[i][i] - sum;
                // Relative to the diagonal: a column that depends on others.
                // NaN fails the test too.
                let pivot_ok = d > 1e-9 * m[i][i].abs().max(1e-300);
                if !pivot_ok {
                    return None;
                }
                l[i][i] = d.sqrt();
            } else {
                l[i][j] = (m[i][j] - sum) / l[j][j];
            }
        }
    }
    Some(l)
}

/// x with L·Lᵀ·x = b (the leading n entries).
fn cholesky_solve(l: &[[f64; 5]; 5], b: &[f64; 5], n: usize) -> [f64; 5] {
    let mut y = [0.0f64; 5];
    for i in 0..n {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = [0.0f64; 5];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    x
}

/// The light baked into a source's colours, fitted to its Gaussians
/// `indices` (its skin regions'): each counts by its weight in a mean colour
/// times how skin-like its colour is (`stats`), at the exposure of its
/// parent triangle on the source's neutral mesh (`exposures`, per triangle).
/// Fitted to the DC colours, which relighting scales (fitted to the colours
/// a facing camera sees instead, `largest-shape` lost 0.13 dB at 128²).
pub fn source_light(
    set: &GaussianSet,
    exposures: &[Exposure],
    indices: &[u32],
    stats: Option<&SkinStats>,
) -> Option<BakedLight> {
    let stride = set.sh_stride();
    let samples = indices.iter().filter_map(|&i| {
        let i = i as usize;
        let exposure = *exposures.get(i)?;
        let dc = &set.sh[i * stride..i * stride + 3];
        let colour = Vec3::new(dc_to_rgb(dc[0]), dc_to_rgb(dc[1]), dc_to_rgb(dc[2]));
        let likeness = stats.map_or(1.0, |s| skin_likeness(srgb_to_lab(colour), s));
        (exposure.normal != Vec3::ZERO).then_some((
            colour,
            exposure,
            colour_weight(set, i) * likeness,
        ))
    });
    BakedLight::fit(samples)
}

impl Exposure {
    /// The exposure at barycentric coordinates `bary` of the triangle with
    /// corners `tri`, from its corners' (`vertex`, per vertex): normal and
    /// cavity interpolated as a renderer interpolates them. Zero normal where
    /// the corners' cancel or a corner is past the mesh.
    pub fn at(vertex: &[Exposure], tri: [u32; 3], bary: [f32; 3]) -> Exposure {
        let (mut normal, mut cavity) = (Vec3::ZERO, 0.0);
        for (&v, &b) in tri.iter().zip(&bary) {
            let Some(corner) = vertex.get(v as usize) else {
                return Exposure::default();
            };
            normal += b * corner.normal;
            cavity += b * corner.cavity;
        }
        Exposure {
            normal: normal.normalize_or_zero(),
            cavity,
        }
    }
}

/// Each vertex's exposure on `mesh`: its area-weighted smooth normal and
/// cavity depth.
pub fn vertex_exposures(mesh: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Exposure> {
    let normals = vertex_normals(mesh, triangles);
    let depth = cavities(mesh, triangles, &normals);
    normals
        .into_iter()
        .zip(depth)
        .map(|(normal, cavity)| Exposure { normal, cavity })
        .collect()
}

/// Per vertex: whether it lies in a hollow, and how squarely — the cosine
/// of the angle between its umbrella vector (from it to the centroid of its
/// neighbours, the discrete mean-curvature normal) and its normal, zero
/// where the surface bulges or the umbrella lies in the tangent plane. A
/// scale-free cavity indicator: ambient light reaches a hollow from fewer
/// directions, so its skin looks darker than its normal alone says, and
/// how much darker each source's own skin tells ([`BakedLight::fit`]).
pub fn cavities(mesh: &[Vec3], triangles: &[[u32; 3]], normals: &[Vec3]) -> Vec<f32> {
    let mut sum = vec![Vec3::ZERO; mesh.len()];
    let mut count = vec![0u32; mesh.len()];
    for t in triangles {
        for k in 0..3 {
            let (i, j) = (t[k] as usize, t[(k + 1) % 3] as usize);
            sum[i] += mesh[j];
            sum[j] += mesh[i];
            count[i] += 1;
            count[j] += 1;
        }
    }
    (0..mesh.len())
        .map(|v| {
            if count[v] == 0 {
                return 0.0;
            }
            let umbrella = sum[v] / count[v] as f32 - mesh[v];
            let length = umbrella.length();
            let cosine = umbrella.dot(normals[v]) / length;
            if length > 0.0 && cosine.is_finite() {
                cosine.max(0.0)
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each triangle's exposure at its centroid.
    fn triangle_exposures(mesh: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Exposure> {
        let vertex = vertex_exposures(mesh, triangles);
        triangles
            .iter()
            .map(|&t| Exposure::at(&vertex, t, [1.0 / 3.0; 3]))
            .collect()
    }

    /// A surface facing `normal` outside any hollow.
    fn facing(normal: Vec3) -> Exposure {
        Exposure {
            normal,
            cavity: 0.0,
        }
    }

    /// Samples of a hemisphere lit by a wrapped key light, in hollows of
    /// depth 0 to 0.9 that take a share `darkening` of the light per unit
    /// of depth away (as the built-in generator's occlusion does).
    fn sphere_samples(light: Vec3, albedo: Vec3, darkening: f32) -> Vec<(Vec3, Exposure, f32)> {
        let mut out = Vec::new();
        for i in 0..40 {
            for j in 0..20 {
                let (theta, phi) = (i as f32 * 0.157, j as f32 * 0.078);
                let n = Vec3::new(theta.sin() * phi.cos(), phi.sin(), theta.cos() * phi.cos());
                if n.z < 0.0 {
                    continue;
                }
                let cavity = ((i * 7 + j * 3) % 10) as f32 / 10.0;
                let shade = (0.55 + 0.5 * (n.dot(light) + 0.4) / 1.4) * (1.0 - darkening * cavity);
                let exposure = Exposure { normal: n, cavity };
                out.push((albedo * shade, exposure, 1.0));
            }
        }
        out
    }

    fn key() -> Vec3 {
        Vec3::new(0.35, 0.55, 0.76).normalize()
    }

    /// A wrapped key light (linear in the normal where it is not clipped)
    /// is recovered, and relighting a colour from one normal to another
    /// gives the colour the light gives there.
    #[test]
    fn recovers_a_linear_light_and_relights_by_its_ratio() {
        let albedo = Vec3::new(0.8, 0.6, 0.5);
        let light = BakedLight::fit(sphere_samples(key(), albedo, 0.0)).unwrap();
        let (from, to) = (facing(Vec3::Z), facing(Vec3::new(0.6, 0.0, 0.8)));
        let shade = |n: Vec3| 0.55 + 0.5 * (n.dot(key()) + 0.4) / 1.4;
        let relit = albedo * shade(from.normal) * light.gain(from, to);
        assert!(
            (relit - albedo * shade(to.normal)).abs().max_element() < 1e-4,
            "{relit}"
        );
        assert_eq!(light.gain(to, to), Vec3::ONE);
        let nudged = facing((to.normal + Vec3::splat(1e-7)).normalize());
        assert_eq!(light.gain(to, nudged), Vec3::ONE);
    }

    /// Skin darker in its hollows by a share of its light gives the light
    /// that share as its occlusion: a Gaussian moved out of a hollow
    /// brightens by what the hollow took, one moved into a hollow darkens —
    /// by more where it faces the light, which a hollow taking the same
    /// brightness everywhere got wrong — and one that only turned relights
    /// as before.
    #[test]
    fn recovers_the_darkening_of_hollows() {
        let albedo = Vec3::new(0.8, 0.6, 0.5);
        let light = BakedLight::fit(sphere_samples(key(), albedo, 0.3)).unwrap();
        assert!(
            (light.occlusion - Vec3::splat(-0.3)).abs().max_element() < 1e-4,
            "{:?}",
            light.occlusion
        );
        let shade =
            |e: Exposure| (0.55 + 0.5 * (e.normal.dot(key()) + 0.4) / 1.4) * (1.0 - 0.3 * e.cavity);
        let hollow = Exposure {
            normal: Vec3::Z,
            cavity: 0.8,
        };
        let open = facing(Vec3::new(0.6, 0.0, 0.8));
        for (from, to) in [(hollow, open), (open, hollow), (facing(Vec3::Z), open)] {
            let relit = albedo * shade(from) * light.gain(from, to);
            assert!(
                (relit - albedo * shade(to)).abs().max_element() < 1e-4,
                "{from:?} -> {to:?}: {relit}"
            );
        }
        assert!(light.gain(hollow, facing(Vec3::Z)).min_element() > 1.2);
        let away = Exposure {
            normal: Vec3::new(-0.6, 0.0, 0.8),
            cavity: 0.8,
        };
        let toward = Exposure {
            normal: Vec3::new(0.6, 0.0, 0.8),
            ..away
        };
        for to in [away, toward] {
            let from = facing(to.normal);
            let relit = albedo * shade(from) * light.gain(from, to);
            assert!(
                (relit - albedo * shade(to)).abs().max_element() < 1e-4,
                "{to:?}: {relit}"
            );
        }
    }

    /// Hollows whose shade would take more than all of their light (the
    /// deepest samples' colours below zero): the occlusion stops at
    /// [`MAX_OCCLUSION`], and a Gaussian moved into the deepest hollow
    /// darkens, within [`RELIGHT_RANGE`].
    #[test]
    fn an_occlusion_that_takes_everything_stops_short() {
        let light = BakedLight::fit(sphere_samples(key(), Vec3::splat(0.7), 1.2)).unwrap();
        assert_eq!(light.occlusion, Vec3::splat(-MAX_OCCLUSION));
        let pit = Exposure {
            normal: Vec3::Z,
            cavity: 1.0,
        };
        let gain = light.gain(facing(Vec3::Z), pit);
        assert!(gain.max_element() < 1.0, "{gain}");
        assert!(gain.min_element() >= RELIGHT_RANGE.0, "{gain}");
    }

    /// A cavity term that would brighten hollows (no light does; an albedo
    /// that happens to be lighter there), or hollows that never vary, leave
    /// the term out: the light is the one fitted to the normals alone.
    #[test]
    fn leaves_out_a_cavity_term_the_samples_cannot_tell() {
        let albedo = Vec3::new(0.7, 0.5, 0.4);
        let normals_only = BakedLight::fit(
            sphere_samples(key(), albedo, 0.0)
                .into_iter()
                .map(|(c, e, w)| (c, facing(e.normal), w)),
        )
        .unwrap();
        assert_eq!(normals_only.occlusion, Vec3::ZERO);
        let brighter = BakedLight::fit(sphere_samples(key(), albedo, -0.2)).unwrap();
        assert_eq!(brighter.occlusion, Vec3::ZERO);
        let hollow = Exposure {
            normal: Vec3::Z,
            cavity: 0.9,
        };
        assert_eq!(brighter.gain(hollow, facing(Vec3::Z)), Vec3::ONE);
    }

    /// The bottom of a pit is a hollow (its umbrella points along its
    /// normal), the top of a bump and the middle of a plane are not; an
    /// isolated vertex, a repeated one and a degenerate fan give zero,
    /// never NaN.
    #[test]
    fn cavities_find_pits_not_bumps_or_planes() {
        // A fan of six around a centre at height h, normal +z.
        let fan = |h: f32| {
            let mut mesh = vec![Vec3::new(0.0, 0.0, h)];
            for k in 0..6 {
                let a = k as f32 * std::f32::consts::TAU / 6.0;
                mesh.push(Vec3::new(a.cos(), a.sin(), 0.0));
            }
            let triangles: Vec<[u32; 3]> = (0..6).map(|k| [0, 1 + k, 1 + (k + 1) % 6]).collect();
            (mesh, triangles)
        };
        let up = vec![Vec3::Z; 7];
        for (h, expected) in [(-0.5f32, 1.0f32), (0.5, 0.0), (0.0, 0.0)] {
            let (mesh, triangles) = fan(h);
            let depth = cavities(&mesh, &triangles, &up);
            assert!((depth[0] - expected).abs() < 1e-5, "h {h}: {}", depth[0]);
        }
        let mesh = [Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::X];
        let depth = cavities(&mesh, &[[0, 1, 2]], &[Vec3::Z; 4]);
        assert!(depth.iter().all(|d| *d == 0.0), "{depth:?}");
        let exposure = triangle_exposures(&mesh, &[[0, 1, 2]]);
        assert!(exposure
            .iter()
            .all(|e| e.cavity.is_finite() && e.normal.is_finite()));
    }

    /// Normals of a mesh with a degenerate triangle, a sliver and a part on
    /// its own: unit where a triangle's corners agree, zero where a lone
    /// degenerate triangle has none, never NaN.
    #[test]
    fn normals_of_hard_meshes_are_unit_or_zero() {
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
        let normals: Vec<Vec3> = triangle_exposures(&mesh, &triangles)
            .iter()
            .map(|e| e.normal)
            .collect();
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

    /// The exposure at a point of a triangle is its corner's at a corner,
    /// between them a unit normal and the interpolated cavity; corners
    /// whose normals cancel or that lie past the mesh give a zero normal,
    /// never NaN.
    #[test]
    fn exposure_at_a_point_interpolates_its_corners() {
        let corner = |x: f32, cavity: f32| Exposure {
            normal: Vec3::new(x, 0.0, 1.0).normalize(),
            cavity,
        };
        let vertex = [corner(-1.0, 0.0), corner(1.0, 0.6), corner(0.0, 0.3)];
        let tri = [0, 1, 2];
        let at_corner = Exposure::at(&vertex, tri, [0.0, 1.0, 0.0]);
        assert!((at_corner.normal - vertex[1].normal).length() < 1e-6);
        assert_eq!(at_corner.cavity, vertex[1].cavity);
        let middle = Exposure::at(&vertex, tri, [0.5, 0.5, 0.0]);
        assert!((middle.normal - Vec3::Z).length() < 1e-6, "{middle:?}");
        assert!((middle.cavity - 0.3).abs() < 1e-6);
        let near_one = Exposure::at(&vertex, tri, [0.1, 0.9, 0.0]);
        assert!((near_one.normal.length() - 1.0).abs() < 1e-6);
        assert!(near_one.normal.x > 0.5 && near_one.normal.x < vertex[1].normal.x);
        let opposed = [facing(Vec3::Z), facing(-Vec3::Z), facing(Vec3::Z)];
        assert_eq!(
            Exposure::at(&opposed, tri, [0.5, 0.5, 0.0]).normal,
            Vec3::ZERO
        );
        assert_eq!(
            Exposure::at(&vertex, [0, 1, 7], [0.3, 0.3, 0.4]),
            Exposure::default()
        );
    }

    /// Near-black skin (a dark skin in deep shade) shows no light to fit.
    #[test]
    fn near_black_skin_gives_no_light() {
        assert!(BakedLight::fit(sphere_samples(key(), Vec3::splat(0.03), 0.0)).is_none());
        assert!(BakedLight::fit(sphere_samples(key(), Vec3::splat(0.15), 0.0)).is_some());
    }

    /// Too few samples, all one normal, or non-finite ones give no light;
    /// a dark light gives no gain and a steep one at most the clamp.
    #[test]
    fn refuses_what_tells_no_light() {
        let one_way = vec![(Vec3::splat(0.5), facing(Vec3::Z), 1.0); 500];
        assert!(BakedLight::fit(one_way).is_none());
        let few = sphere_samples(Vec3::Z, Vec3::ONE, 0.0)
            .into_iter()
            .take(10)
            .collect::<Vec<_>>();
        assert!(BakedLight::fit(few).is_none());
        let mut bad = sphere_samples(Vec3::Z, Vec3::ONE, 0.0);
        for s in bad.iter_mut() {
            s.0 = Vec3::NAN;
        }
        assert!(BakedLight::fit(bad).is_none());
        let dark = BakedLight::new([[0.01, 0.0, 0.0, 0.0]; 3], Vec3::ZERO);
        assert_eq!(dark.gain(facing(Vec3::Z), facing(Vec3::X)), Vec3::ONE);
        let steep = BakedLight::new([[0.5, 0.0, 0.0, 0.45]; 3], Vec3::ZERO);
        let g = steep.gain(
            facing(Vec3::Z),
            facing(Vec3::new(0.0, 0.0, -1.0).lerp(Vec3::X, 0.5).normalize()),
        );
        assert!(g.min_element() >= RELIGHT_RANGE.0);
    }
}
