//! RGB images: the renderers' output, PNG files and the PSNR used to compare
//! renderers with each other and with stored images.

use std::path::Path;

/// An RGB8 image, row-major, top row first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 3` bytes.
    pub pixels: Vec<u8>,
}

impl RgbImage {
    /// A filled image.
    pub fn new(width: u32, height: u32, fill: [u8; 3]) -> Self {
        let pixels = fill
            .iter()
            .copied()
            .cycle()
            .take(width as usize * height as usize * 3)
            .collect();
        Self {
            width,
            height,
            pixels,
        }
    }

    /// Converts linear-in-file colours in [0, 1] (clamped) to 8 bits, rounding.
    pub fn from_f32(width: u32, height: u32, rgb: &[f32]) -> Self {
        Self {
            width,
            height,
            pixels: rgb.iter().map(|&c| quantize(c)).collect(),
        }
    }

    /// Writes a PNG; a failure is an I/O error (exit 4).
    pub fn save_png(&self, path: &Path) -> crate::error::Result<()> {
        image::save_buffer(
            path,
            &self.pixels,
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| crate::error::Error::io("write", path, e))
    }

    /// Reads a PNG (any colour type; converted to RGB8).
    pub fn load_png(path: &Path) -> Result<Self, String> {
        let img = image::open(path)
            .map_err(|e| format!("cannot read image {}: {e}", path.display()))?
            .to_rgb8();
        Ok(Self {
            width: img.width(),
            height: img.height(),
            pixels: img.into_raw(),
        })
    }

    /// Bilinear resize (pixel centres aligned), for previews rendered at a lower
    /// resolution.
    pub fn resized(&self, width: u32, height: u32) -> RgbImage {
        let mut out = RgbImage::new(width, height, [0; 3]);
        if self.width == 0 || self.height == 0 {
            return out;
        }
        let sx = self.width as f32 / width as f32;
        let sy = self.height as f32 / height as f32;
        for y in 0..height {
            let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (self.height - 1) as f32);
            let (y0, ty) = (fy.floor() as u32, fy.fract());
            let y1 = (y0 + 1).min(self.height - 1);
            for x in 0..width {
                let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (self.width - 1) as f32);
                let (x0, tx) = (fx.floor() as u32, fx.fract());
                let x1 = (x0 + 1).min(self.width - 1);
                let (a, b, c, d) = (
                    self.pixel(x0, y0),
                    self.pixel(x1, y0),
                    self.pixel(x0, y1),
                    self.pixel(x1, y1),
                );
                let k = ((y * width + x) * 3) as usize;
                for ch in 0..3 {
                    let top = a[ch] as f32 + (b[ch] as f32 - a[ch] as f32) * tx;
                    let bottom = c[ch] as f32 + (d[ch] as f32 - c[ch] as f32) * tx;
                    out.pixels[k + ch] = (top + (bottom - top) * ty + 0.5) as u8;
                }
            }
        }
        out
    }

    /// The RGB triple at (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let k = (y as usize * self.width as usize + x as usize) * 3;
        [self.pixels[k], self.pixels[k + 1], self.pixels[k + 2]]
    }
}

/// Rounds a colour in [0, 1] to 8 bits (NaN → 0).
pub fn quantize(c: f32) -> u8 {
    if c.is_nan() {
        0
    } else {
        (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
    }
}

/// Peak signal-to-noise ratio in dB between two 8-bit images of equal size
/// (infinite when identical); `None` when the sizes differ.
pub fn psnr(a: &RgbImage, b: &RgbImage) -> Option<f64> {
    if a.width != b.width || a.height != b.height {
        return None;
    }
    let sum: f64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(&x, &y)| {
            let d = x as f64 - y as f64;
            d * d
        })
        .sum();
    let mse = sum / a.pixels.len().max(1) as f64;
    Some(if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    })
}

/// PSNR for reports: capped at 100 dB (identical images report 100), so it is
/// always a finite number in JSON.
pub fn psnr_report(a: &RgbImage, b: &RgbImage) -> Option<f64> {
    psnr(a, b).map(|p| p.min(100.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_of_identical_and_shifted_images() {
        let a = RgbImage::new(4, 4, [10, 20, 30]);
        assert_eq!(psnr(&a, &a), Some(f64::INFINITY));
        let b = RgbImage::new(4, 4, [11, 21, 31]);
        assert!((psnr(&a, &b).unwrap() - 48.13).abs() < 0.01);
        assert_eq!(psnr(&a, &RgbImage::new(2, 2, [0; 3])), None);
    }

    #[test]
    fn quantize_rounds_and_clamps() {
        assert_eq!(quantize(-1.0), 0);
        assert_eq!(quantize(2.0), 255);
        assert_eq!(quantize(0.5), 128);
        assert_eq!(quantize(f32::NAN), 0);
    }
}
