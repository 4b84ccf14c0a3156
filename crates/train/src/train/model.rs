//! A trainable avatar's parameters and the differentiable render of them:
//! project every Gaussian through its triangle's frame ([`project`]),
//! rasterise ([`raster`]), and on the way back combine the rasteriser's
//! per-splat gradients with each projection's Jacobian into gradients for the
//! stored parameters — local position, log-scale, raw quaternion, opacity
//! logit and SH coefficients.

use rayon::prelude::*;

use super::holes::Obscurer;
use super::project::{project, Geometry, Projected, TrainCamera, GEOMETRY};
use super::raster::{Backdrop, Rasterized, Rasterizer, Splat};
use crate::avatar::binding::TriangleFrame;
use crate::avatar::gaussians::GaussianSet;
use crate::error::Result;

/// SH coefficients stored per Gaussian (degree 3, 16 × RGB), whatever degree
/// is active.
pub const SH_STRIDE: usize = 48;

/// Triangle-bound Gaussians in f64, as the optimiser changes them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trainable {
    /// Parent triangle of each Gaussian.
    pub binding: Vec<u32>,
    /// Geometry per Gaussian.
    pub geometry: Vec<Geometry>,
    /// Opacity before the sigmoid.
    pub opacity_logit: Vec<f64>,
    /// SH coefficients, [`SH_STRIDE`] per Gaussian, coefficient-major.
    pub sh: Vec<f64>,
    /// The SH degree drawn (raised during training).
    pub sh_degree: u8,
}

/// ∂loss/∂ every stored parameter, plus the screen-space gradient norms
/// densification reads.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gradients {
    /// Per Gaussian: position (3), log-scale (3), quaternion (4).
    pub geometry: Vec<[f64; GEOMETRY]>,
    /// Per Gaussian.
    pub opacity_logit: Vec<f64>,
    /// Same layout as [`Trainable::sh`].
    pub sh: Vec<f64>,
    /// Per Gaussian: ∂loss/∂ projected centre in pixels (0 when not drawn).
    pub screen_xy: Vec<[f64; 2]>,
}

impl Trainable {
    /// Gaussians in the set, degree-3 storage.
    pub fn from_set(set: &GaussianSet) -> Self {
        let stride = set.sh_stride();
        let mut sh = vec![0.0; set.len() * SH_STRIDE];
        for i in 0..set.len() {
            for (k, &c) in set.sh[i * stride..(i + 1) * stride].iter().enumerate() {
                sh[i * SH_STRIDE + k] = c as f64;
            }
        }
        Self {
            binding: set.binding.clone(),
            geometry: (0..set.len())
                .map(|i| {
                    let q = set.rotation[i];
                    Geometry {
                        position: set.position[i].as_dvec3().to_array(),
                        log_scale: set.log_scale[i].as_dvec3().to_array(),
                        rotation: [q.w, q.x, q.y, q.z].map(f64::from),
                    }
                })
                .collect(),
            opacity_logit: set.opacity_logit.iter().map(|&o| o as f64).collect(),
            sh,
            sh_degree: set.sh_degree,
        }
    }

    /// The Gaussians as a set of the given SH degree (f32, for export and the
    /// renderers).
    pub fn to_set(&self, sh_degree: u8) -> GaussianSet {
        let stride = 3 * (sh_degree as usize + 1).pow(2);
        let mut set = GaussianSet::with_degree(sh_degree);
        set.binding = self.binding.clone();
        for (i, g) in self.geometry.iter().enumerate() {
            set.position.push(glam::DVec3::from(g.position).as_vec3());
            set.log_scale.push(glam::DVec3::from(g.log_scale).as_vec3());
            let [w, x, y, z] = g.rotation.map(|c| c as f32);
            set.rotation.push(glam::Quat::from_xyzw(x, y, z, w));
            set.opacity_logit.push(self.opacity_logit[i] as f32);
            set.sh.extend(
                self.sh[i * SH_STRIDE..i * SH_STRIDE + stride]
                    .iter()
                    .map(|&c| c as f32),
            );
        }
        set
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.binding.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.binding.is_empty()
    }
}

/// A differentiable render: the image and what its backward pass needs.
pub struct Render {
    projected: Vec<Projected>,
    /// Gaussian index of each drawn splat.
    drawn: Vec<u32>,
    splats: Vec<Splat>,
    raster: Rasterized,
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

impl Render {
    /// Renders `model` on the posed triangle `frames` from `camera` over
    /// `background` with `rasterizer`, with hole filling's `obscurer` drawn
    /// but not optimised.
    pub fn new(
        model: &Trainable,
        frames: &[TriangleFrame],
        camera: &TrainCamera,
        background: [f64; 3],
        obscurer: &Obscurer,
        rasterizer: &mut Rasterizer,
    ) -> Result<Self> {
        let last = frames.len().saturating_sub(1);
        let projected: Vec<(u32, Projected)> = (0..model.len())
            .into_par_iter()
            .with_min_len(256)
            .filter_map(|i| {
                let opacity = sigmoid(model.opacity_logit[i]);
                if opacity.is_nan() || opacity <= 0.0 || frames.is_empty() {
                    return None;
                }
                let frame = &frames[(model.binding[i] as usize).min(last)];
                let sh = &model.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
                project(
                    &model.geometry[i],
                    sh,
                    model.sh_degree,
                    opacity.min(1.0),
                    frame,
                    camera,
                )
                .map(|p| (i as u32, p))
            })
            .collect();
        let (drawn, projected): (Vec<u32>, Vec<Projected>) = projected.into_iter().unzip();
        let splats: Vec<Splat> = drawn
            .iter()
            .zip(&projected)
            .map(|(&i, p)| Splat {
                center: p.center.map(|c| c.v),
                conic: p.conic.map(|c| c.v),
                opacity: sigmoid(model.opacity_logit[i as usize]).min(1.0),
                rgb: p.drawn_rgb(),
                radius: p.radius,
                depth: p.depth,
            })
            .chain(match obscurer {
                Obscurer::Gaussian(s) => Some(*s),
                _ => None,
            })
            .collect();
        let mut backdrop = Backdrop::uniform(camera.size, background);
        if let Obscurer::Interior { colour, depth } = obscurer {
            for (p, &d) in depth.iter().enumerate().filter(|(_, d)| d.is_finite()) {
                backdrop.colour[p] = *colour;
                backdrop.stop[p] = d;
            }
        }
        let raster = rasterizer.forward(&splats, camera.size, &backdrop)?;
        Ok(Self {
            projected,
            drawn,
            splats,
            raster,
        })
    }

    /// The image: RGB, row-major, f64 (not clamped).
    pub fn image(&self) -> &[f64] {
        &self.raster.image
    }

    /// Pixels the splats cover (almost) completely: transmittance below 1 %.
    pub fn saturated_pixels(&self) -> usize {
        self.raster.saturated_pixels()
    }

    /// The Gaussians drawn, in drawing order of [`Render::radii`].
    pub fn drawn_indices(&self) -> &[u32] {
        &self.drawn
    }

    /// Footprint radii (pixels) of the drawn Gaussians.
    pub fn radii(&self) -> impl Iterator<Item = f64> + '_ {
        self.splats[..self.drawn.len()].iter().map(|s| s.radius)
    }

    /// Per pixel, the opacity accumulated over it: 1 − the transmittance
    /// left (row-major).
    pub fn opacity(&self) -> Vec<f64> {
        self.raster.final_t.iter().map(|t| 1.0 - t).collect()
    }

    /// Gaussians drawn (not culled).
    pub fn drawn(&self) -> usize {
        self.drawn.len()
    }

    /// ∂loss/∂ every parameter of `model`, given ∂loss/∂ the image, with the
    /// rasteriser that drew it.
    pub fn backward(
        &self,
        model: &Trainable,
        d_image: &[f64],
        rasterizer: &mut Rasterizer,
    ) -> Result<Gradients> {
        let screen = rasterizer.backward(&self.splats, &self.raster, d_image)?;
        let n = model.len();
        let mut grads = Gradients {
            geometry: vec![[0.0; GEOMETRY]; n],
            opacity_logit: vec![0.0; n],
            sh: vec![0.0; n * SH_STRIDE],
            screen_xy: vec![[0.0; 2]; n],
        };
        let coefficients = (model.sh_degree as usize + 1).pow(2);
        for ((&i, p), g) in self.drawn.iter().zip(&self.projected).zip(&screen) {
            let i = i as usize;
            let geometry = &mut grads.geometry[i];
            let mut add = |weight: f64, d: &[f64; GEOMETRY]| {
                for (out, x) in geometry.iter_mut().zip(d) {
                    *out += weight * x;
                }
            };
            for k in 0..2 {
                add(g.center[k], &p.center[k].d);
            }
            for k in 0..3 {
                add(g.conic[k], &p.conic[k].d);
            }
            for ch in 0..3 {
                if p.rgb[ch].v < 0.0 {
                    continue; // clamped at 0: no gradient
                }
                add(g.rgb[ch], &p.rgb[ch].d);
                for j in 0..coefficients {
                    grads.sh[i * SH_STRIDE + j * 3 + ch] += g.rgb[ch] * p.basis[j];
                }
            }
            let o = sigmoid(model.opacity_logit[i]);
            grads.opacity_logit[i] = g.opacity * o * (1.0 - o);
            grads.screen_xy[i] = g.center;
        }
        Ok(grads)
    }
}

/// The gradient check `visage bench train` reports and the tests bound: a
/// small scene with the hard cases, every parameter's analytic gradient
/// against central differences (h = 1e-6) of the f64 forward.
pub mod gradient_check {
    use super::*;
    use crate::scene::camera::Orbit;
    use glam::{Mat3, Quat, Vec3};

    /// Three triangle frames, tilted and scaled differently.
    pub fn frames() -> Vec<TriangleFrame> {
        [(0.0f32, 0.09f32), (0.7, 0.12), (-0.4, 0.05)]
            .iter()
            .enumerate()
            .map(|(k, &(angle, scale))| {
                let rotation = Mat3::from_quat(Quat::from_euler(
                    glam::EulerRot::XYZ,
                    angle,
                    0.3 * k as f32,
                    -angle,
                ));
                TriangleFrame {
                    center: Vec3::new(0.04 * k as f32 - 0.04, 0.02 * k as f32, 0.0),
                    rotation,
                    quat: Quat::from_mat3(&rotation),
                    scale,
                }
            })
            .collect()
    }

    /// Ordinary Gaussians plus the hard cases: one close to the near plane,
    /// one tiny (the dilation dominates), one huge, a zero quaternion, and an
    /// opaque stack that saturates pixels (α clamped, transmittance stop).
    pub fn model() -> Trainable {
        let mut m = Trainable {
            sh_degree: 3,
            ..Trainable::default()
        };
        let mut push = |b: u32, position: [f64; 3], log_scale: [f64; 3], q: [f64; 4], o: f64| {
            let i = m.binding.len();
            m.binding.push(b);
            m.geometry.push(Geometry {
                position,
                log_scale,
                rotation: q,
            });
            m.opacity_logit.push(o);
            m.sh.extend((0..SH_STRIDE).map(|k| {
                let x = ((i * 31 + k * 7) % 23) as f64 / 23.0 - 0.5;
                if k < 3 {
                    x + 0.3
                } else {
                    0.15 * x
                }
            }));
        };
        push(
            0,
            [0.1, 0.2, -0.1],
            [-0.7, -0.9, -1.2],
            [0.9, 0.2, -0.1, 0.3],
            0.2,
        );
        push(
            1,
            [-0.3, 0.1, 0.2],
            [-1.0, -0.4, -0.8],
            [0.5, -0.5, 0.4, 0.1],
            -0.5,
        );
        push(
            2,
            [0.2, -0.2, 0.4],
            [-0.6, -1.1, -0.5],
            [0.2, 0.9, 0.3, -0.2],
            1.0,
        );
        push(
            0,
            [0.5, 0.0, -0.3],
            [-9.0, -9.5, -8.5],
            [1.0, 0.0, 0.1, 0.0],
            0.8,
        ); // tiny
        push(
            1,
            [0.0, 0.1, 0.0],
            [0.6, 0.4, 0.5],
            [0.7, 0.1, 0.6, 0.2],
            -2.5,
        ); // huge
        push(
            2,
            [-0.1, 0.3, 0.1],
            [-1.0, -1.0, -1.0],
            [0.0, 0.0, 0.0, 0.0],
            0.3,
        ); // zero q
           // Opaque stack.
        for k in 0..4 {
            push(
                0,
                [-0.4, -0.3, 0.1 * k as f64],
                [-0.2, -0.3, -0.25],
                [0.95, 0.05, 0.0, 0.1],
                4.0 + k as f64,
            );
        }
        // Close to the camera: 0.02 in front of it (the near plane is at 0.004).
        let cam = camera();
        let forward = -glam::DVec3::from(cam.rotation[2]);
        let world =
            glam::DVec3::from(cam.eye) + 0.02 * forward + glam::DVec3::new(0.001, -0.002, 0.0);
        let frame = frames()[1];
        let local = frame.rotation.as_dmat3().transpose()
            * ((world - frame.center.as_dvec3()) / frame.scale as f64);
        push(
            1,
            local.to_array(),
            [-3.5, -3.6, -3.4],
            [0.8, 0.3, 0.1, 0.2],
            0.0,
        );
        m
    }

    /// A close camera (0.4 from the origin), 40 × 32 pixels.
    pub fn camera() -> TrainCamera {
        TrainCamera::from_camera(
            &Orbit {
                yaw_deg: 15.0,
                pitch_deg: 10.0,
                radius: 0.4,
                fov_deg: 40.0,
                target: [0.0, 0.0, 0.0],
                ..Orbit::STUDY
            }
            .camera(40, 32),
        )
    }

    /// The check scene's background.
    const BACKGROUND: [f64; 3] = [0.05, 0.1, 0.2];

    /// The check scene drawn by `rasterizer`, and the fixed weights w of its
    /// loss Σ w·image.
    fn check_render(model: &Trainable, rasterizer: &mut Rasterizer) -> Result<(Render, Vec<f64>)> {
        let render = Render::new(
            model,
            &frames(),
            &camera(),
            BACKGROUND,
            &Obscurer::None,
            rasterizer,
        )?;
        let weights = (0..render.image().len())
            .map(|i| ((i * 13) % 29) as f64 / 29.0 - 0.45)
            .collect();
        Ok((render, weights))
    }

    /// Every gradient of the check scene as one flat list (geometry, opacity
    /// logit, SH), from `rasterizer`.
    fn flat_gradients(rasterizer: &mut Rasterizer) -> Result<Vec<f64>> {
        let model = model();
        let (render, weights) = check_render(&model, rasterizer)?;
        let g = render.backward(&model, &weights, rasterizer)?;
        Ok(g.geometry
            .iter()
            .flatten()
            .chain(&g.opacity_logit)
            .chain(&g.sh)
            .copied()
            .collect())
    }

    /// How far a renderer's gradients on the check scene are from the f64
    /// CPU pass's: the largest difference over the largest gradient (the
    /// wgpu pass is f32, so about 1e-6 to 1e-4 is its rounding).
    pub fn agreement_with_cpu(backend: crate::render::Backend) -> Result<f64> {
        let mut rasterizer = Rasterizer::open(backend)?;
        let theirs = flat_gradients(&mut rasterizer)?;
        let ours = flat_gradients(&mut Rasterizer::Cpu)?;
        let largest = ours.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        let difference = ours
            .iter()
            .zip(&theirs)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        Ok(difference / largest.max(1e-30))
    }

    /// The largest relative error over every checked parameter (relative to
    /// max(|numeric|, 1e-2)), and how many parameters were checked.
    pub fn worst_relative_error() -> (f64, usize) {
        let (frames, camera, model) = (frames(), camera(), model());
        let cpu = || Rasterizer::Cpu;
        let (render, weights) =
            check_render(&model, &mut cpu()).expect("the CPU rasteriser does not fail");
        let loss = |m: &Trainable| -> f64 {
            Render::new(m, &frames, &camera, BACKGROUND, &Obscurer::None, &mut cpu())
                .expect("the CPU rasteriser does not fail")
                .image()
                .iter()
                .zip(&weights)
                .map(|(a, b)| a * b)
                .sum()
        };
        let grads = render
            .backward(&model, &weights, &mut cpu())
            .expect("the CPU rasteriser does not fail");
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        let mut checked = 0;
        let mut check = |analytic: f64, change: &dyn Fn(&mut Trainable, f64)| {
            let mut plus = model.clone();
            change(&mut plus, h);
            let mut minus = model.clone();
            change(&mut minus, -h);
            let numeric = (loss(&plus) - loss(&minus)) / (2.0 * h);
            worst = worst.max((analytic - numeric).abs() / numeric.abs().max(1e-2));
            checked += 1;
        };
        for i in 0..model.len() {
            for k in 0..GEOMETRY {
                check(grads.geometry[i][k], &|m, e| match k {
                    0..3 => m.geometry[i].position[k] += e,
                    3..6 => m.geometry[i].log_scale[k - 3] += e,
                    _ => m.geometry[i].rotation[k - 6] += e,
                });
            }
            check(grads.opacity_logit[i], &|m, e| m.opacity_logit[i] += e);
            for k in [0, 1, 2, 5, 13, 47] {
                check(grads.sh[i * SH_STRIDE + k], &|m, e| {
                    m.sh[i * SH_STRIDE + k] += e
                });
            }
        }
        (worst, checked)
    }
}

#[cfg(test)]
mod tests {
    use super::gradient_check::*;
    use super::*;

    /// Every parameter's gradient against central differences of the f64
    /// forward, through the binding, for Σ w·image — on a scene with a
    /// Gaussian near the near plane, tiny and huge ones, a zero quaternion and
    /// an opaque stack that saturates pixels.
    #[test]
    fn parameter_gradients_match_central_differences() {
        let render = Render::new(
            &model(),
            &frames(),
            &camera(),
            [0.05, 0.1, 0.2],
            &Obscurer::None,
            &mut Rasterizer::Cpu,
        )
        .unwrap();
        assert!(render.drawn() >= 10, "{} drawn", render.drawn());
        assert!(
            render.saturated_pixels() > 0,
            "the opaque stack saturates pixels"
        );
        let (worst, checked) = worst_relative_error();
        assert_eq!(checked, model().len() * (GEOMETRY + 7));
        assert!(worst < 1e-4, "worst relative error {worst}");
    }
}
