//! The photometric loss of 3DGS and GaussianAvatars, with its gradient:
//! (1 − λ)·L1 + λ·(1 − SSIM), λ = 0.2, SSIM with an 11 × 11 Gaussian window
//! (σ = 1.5) per channel, zero padding, C1 = 0.01², C2 = 0.03², averaged over
//! pixels and channels. Images are RGB, row-major, f64 in [0, 1].

use rayon::prelude::*;

/// Weight of the D-SSIM term.
pub const LAMBDA_DSSIM: f64 = 0.2;
const WINDOW: usize = 11;
const SIGMA: f64 = 1.5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// The loss's value and parts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossValue {
    /// The weighted total.
    pub total: f64,
    /// Mean absolute error.
    pub l1: f64,
    /// Mean SSIM.
    pub ssim: f64,
}

/// The normalised 1-D Gaussian window.
fn window() -> [f64; WINDOW] {
    let half = (WINDOW / 2) as f64;
    let mut w: [f64; WINDOW] =
        std::array::from_fn(|i| (-((i as f64 - half).powi(2)) / (2.0 * SIGMA * SIGMA)).exp());
    let sum: f64 = w.iter().sum();
    w.iter_mut().for_each(|x| *x /= sum);
    w
}

/// One channel of an image convolved with the window (separable, zero
/// padding): rows first, then columns, each output line in parallel. Every
/// pixel sums its taps in window order, as a serial loop would, so the result
/// does not depend on the number of threads.
fn blur(plane: &[f64], width: usize, height: usize, w: &[f64; WINDOW]) -> Vec<f64> {
    if plane.is_empty() || width == 0 {
        return vec![0.0; plane.len()];
    }
    let mut rows = vec![0.0; plane.len()];
    rows.par_chunks_mut(width)
        .zip(plane.par_chunks(width))
        .for_each(|(out, line)| blur_line(line, out, w));
    // Columns as weighted sums of whole rows: contiguous reads, no stride.
    let half = (WINDOW / 2) as isize;
    let mut out = vec![0.0; plane.len()];
    out.par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, out_row)| {
            for (k, wk) in w.iter().enumerate() {
                let j = y as isize + k as isize - half;
                if (0..height as isize).contains(&j) {
                    let source = &rows[j as usize * width..][..width];
                    for (o, s) in out_row.iter_mut().zip(source) {
                        *o += wk * s;
                    }
                }
            }
        });
    out
}

/// One line convolved with the window (zero padding): the taps that fall
/// off the line are skipped near its ends, and the interior runs without a
/// test per tap.
fn blur_line(line: &[f64], out: &mut [f64], w: &[f64; WINDOW]) {
    let half = WINDOW / 2;
    let length = line.len() as isize;
    let edge = |i: usize| {
        let mut acc = 0.0;
        for (k, wk) in w.iter().enumerate() {
            let j = i as isize + k as isize - half as isize;
            if (0..length).contains(&j) {
                acc += wk * line[j as usize];
            }
        }
        acc
    };
    if line.len() < WINDOW {
        out.iter_mut().enumerate().for_each(|(i, o)| *o = edge(i));
        return;
    }
    for i in (0..half).chain(line.len() - half..line.len()) {
        out[i] = edge(i);
    }
    for (o, taps) in out[half..line.len() - half]
        .iter_mut()
        .zip(line.windows(WINDOW))
    {
        let mut acc = 0.0;
        for (wk, v) in w.iter().zip(taps) {
            acc += wk * v;
        }
        *o = acc;
    }
}

fn channel(image: &[f64], ch: usize) -> Vec<f64> {
    image.iter().skip(ch).step_by(3).copied().collect()
}

/// The SSIM map of one channel and, when asked, ∂(Σ SSIM map)/∂x.
fn ssim_channel(
    x: &[f64],
    y: &[f64],
    width: usize,
    height: usize,
    grad: bool,
) -> (Vec<f64>, Vec<f64>) {
    let w = window();
    let product =
        |a: &[f64], b: &[f64]| a.par_iter().zip(b).map(|(p, q)| p * q).collect::<Vec<_>>();
    let mu_x = blur(x, width, height, &w);
    let mu_y = blur(y, width, height, &w);
    let m_xx = blur(&product(x, x), width, height, &w);
    let m_yy = blur(&product(y, y), width, height, &w);
    let m_xy = blur(&product(x, y), width, height, &w);
    let n = x.len();
    // Per pixel: the SSIM and, for the gradient, its partials by the three
    // blurred moments.
    let pixel = |p: usize| {
        let (mx, my) = (mu_x[p], mu_y[p]);
        let sxx = m_xx[p] - mx * mx;
        let syy = m_yy[p] - my * my;
        let sxy = m_xy[p] - mx * my;
        let a = 2.0 * mx * my + C1;
        let b = 2.0 * sxy + C2;
        let c = mx * mx + my * my + C1;
        let d = sxx + syy + C2;
        let s = a * b / (c * d);
        let ds_dmx = 2.0 * my * b / (c * d) - s * 2.0 * mx / c;
        let ds_dsxy = 2.0 * a / (c * d);
        let ds_dsxx = -s / d;
        // sxx = m_xx − μx², sxy = m_xy − μx μy.
        [
            s,
            ds_dmx - 2.0 * mx * ds_dsxx - my * ds_dsxy,
            ds_dsxx,
            ds_dsxy,
        ]
    };
    if !grad {
        return (
            (0..n).into_par_iter().map(|p| pixel(p)[0]).collect(),
            Vec::new(),
        );
    }
    let parts: Vec<[f64; 4]> = (0..n).into_par_iter().map(pixel).collect();
    let part = |k: usize| parts.par_iter().map(|v| v[k]).collect::<Vec<f64>>();
    let (map, d_mu, d_m2, d_mxy) = (part(0), part(1), part(2), part(3));
    // The window is symmetric and zero padding makes the blur its own transpose.
    let (b_mu, b_m2, b_mxy) = (
        blur(&d_mu, width, height, &w),
        blur(&d_m2, width, height, &w),
        blur(&d_mxy, width, height, &w),
    );
    let g = (0..n)
        .into_par_iter()
        .map(|p| b_mu[p] + 2.0 * x[p] * b_m2[p] + y[p] * b_mxy[p])
        .collect();
    (map, g)
}

/// The SSIM of `image` against `target` at each pixel, averaged over the
/// three channels (for SSIM over a mask: the mean of this map over it).
pub fn ssim_map(image: &[f64], target: &[f64], width: usize, height: usize) -> Vec<f64> {
    let maps: Vec<Vec<f64>> = (0..3)
        .into_par_iter()
        .map(|ch| {
            ssim_channel(
                &channel(image, ch),
                &channel(target, ch),
                width,
                height,
                false,
            )
            .0
        })
        .collect();
    (0..width * height)
        .map(|p| (maps[0][p] + maps[1][p] + maps[2][p]) / 3.0)
        .collect()
}

/// The loss of `image` against `target` (both `width × height` RGB) and, when
/// `grad` is set, its gradient with respect to `image`.
pub fn photometric_loss(
    image: &[f64],
    target: &[f64],
    width: usize,
    height: usize,
    grad: bool,
) -> (LossValue, Vec<f64>) {
    let count = image.len() as f64;
    let l1 = image
        .iter()
        .zip(target)
        .map(|(a, b)| (a - b).abs())
        .sum::<f64>()
        / count;
    let mut ssim_sum = 0.0;
    let mut gradient = if grad {
        image
            .iter()
            .zip(target)
            .map(|(a, b)| {
                // The subgradient 0 where they agree (signum(0.0) is 1).
                let sign = if a == b { 0.0 } else { (a - b).signum() };
                (1.0 - LAMBDA_DSSIM) * sign / count
            })
            .collect()
    } else {
        Vec::new()
    };
    let channels: Vec<(Vec<f64>, Vec<f64>)> = (0..3)
        .into_par_iter()
        .map(|ch| {
            let (x, y) = (channel(image, ch), channel(target, ch));
            ssim_channel(&x, &y, width, height, grad)
        })
        .collect();
    for (ch, (map, g)) in channels.into_iter().enumerate() {
        ssim_sum += map.iter().sum::<f64>();
        for (p, gp) in g.iter().enumerate() {
            gradient[p * 3 + ch] -= LAMBDA_DSSIM * gp / count;
        }
    }
    let ssim = ssim_sum / count;
    (
        LossValue {
            total: (1.0 - LAMBDA_DSSIM) * l1 + LAMBDA_DSSIM * (1.0 - ssim),
            l1,
            ssim,
        },
        gradient,
    )
}

/// PSNR in dB of two images in [0, 1] (values clamped first), infinite when equal.
pub fn psnr(image: &[f64], target: &[f64]) -> f64 {
    let mse = image
        .iter()
        .zip(target)
        .map(|(a, b)| (a.clamp(0.0, 1.0) - b.clamp(0.0, 1.0)).powi(2))
        .sum::<f64>()
        / image.len().max(1) as f64;
    -10.0 * mse.log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn images(w: usize, h: usize) -> (Vec<f64>, Vec<f64>) {
        let a = (0..w * h * 3)
            .map(|i| (((i * 7919) % 101) as f64 / 101.0) * 0.8 + 0.1)
            .collect();
        let b = (0..w * h * 3)
            .map(|i| (((i * 104_729) % 97) as f64 / 97.0) * 0.9 + 0.05)
            .collect();
        (a, b)
    }

    /// The parallel blur (rows, then columns as sums of rows, an interior
    /// without per-tap tests) gives the plain serial separable blur bit for
    /// bit, on planes narrower and shorter than the window too, so training
    /// does not depend on the number of threads.
    #[test]
    fn blur_is_the_serial_blur_bit_for_bit() {
        let w = window();
        let serial = |plane: &[f64], width: usize, height: usize| {
            let pass = |input: &[f64], length: usize, count: usize, step: (usize, usize)| {
                let mut out = vec![0.0; input.len()];
                for line in 0..count {
                    for i in 0..length {
                        let mut acc = 0.0;
                        for (k, wk) in w.iter().enumerate() {
                            let j = i as isize + k as isize - (WINDOW / 2) as isize;
                            if (0..length as isize).contains(&j) {
                                acc += wk * input[line * step.1 + j as usize * step.0];
                            }
                        }
                        out[line * step.1 + i * step.0] = acc;
                    }
                }
                out
            };
            let rows = pass(plane, width, height, (1, width));
            pass(&rows, height, width, (width, 1))
        };
        for (width, height) in [(7, 5), (11, 3), (23, 17), (64, 48)] {
            let plane: Vec<f64> = (0..width * height)
                .map(|i| ((i * 7919) % 101) as f64 / 101.0)
                .collect();
            let one_thread = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| blur(&plane, width, height, &w));
            let expected = serial(&plane, width, height);
            assert!(
                blur(&plane, width, height, &w) == expected,
                "{width}x{height}"
            );
            assert!(one_thread == expected, "{width}x{height}");
        }
    }

    #[test]
    fn ssim_of_an_image_with_itself_is_one_and_the_loss_zero() {
        let (a, _) = images(20, 15);
        let (v, g) = photometric_loss(&a, &a, 20, 15, true);
        assert!((v.ssim - 1.0).abs() < 1e-12 && v.l1 == 0.0 && v.total.abs() < 1e-12);
        assert!(g.iter().all(|x| x.abs() < 1e-12), "a minimum");
        assert!(psnr(&a, &a).is_infinite());
    }

    /// The gradient against central differences in f64, pixel by pixel.
    #[test]
    fn gradient_matches_central_differences() {
        let (w, h) = (17, 13);
        let (a, b) = images(w, h);
        let (_, g) = photometric_loss(&a, &b, w, h, true);
        let step = 1e-6;
        for p in (0..a.len()).step_by(7) {
            let mut plus = a.clone();
            plus[p] += step;
            let mut minus = a.clone();
            minus[p] -= step;
            let numeric = (photometric_loss(&plus, &b, w, h, false).0.total
                - photometric_loss(&minus, &b, w, h, false).0.total)
                / (2.0 * step);
            let error = (g[p] - numeric).abs() / numeric.abs().max(1e-6);
            assert!(error < 1e-4, "{p}: {} vs {numeric}", g[p]);
        }
    }
}
