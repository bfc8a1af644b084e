//! [`Comparison`]: the error of an image against a reference photograph, in
//! linear radiance (RMSE, relative RMSE) and as seen (PSNR of the
//! sRGB-encoded images), optionally over a mask.

use std::path::Path;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::image_io::{Image, linear_to_srgb};

/// Error figures of `image` against `reference` over the compared pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Comparison {
    /// Pixels compared (all, or those inside the mask).
    pub pixels: usize,
    /// Root mean square difference over pixels and the three channels, linear.
    pub rmse: f64,
    /// `rmse` divided by the reference's mean over the same pixels (`None`
    /// for an all-black reference).
    pub relative_rmse: Option<f64>,
    /// PSNR in dB of the sRGB-encoded images clamped to [0, 1] (peak 1);
    /// `None` when they are identical.
    pub psnr_srgb_db: Option<f64>,
    /// Mean of the image and of the reference over the compared pixels.
    pub mean: f64,
    pub mean_reference: f64,
}

/// Compares `image` with `reference` (same size) over the pixels where
/// `mask` is true (all pixels when there is no mask).
pub fn compare(image: &Image, reference: &Image, mask: Option<&[bool]>) -> Comparison {
    assert_eq!(
        (image.width, image.height),
        (reference.width, reference.height)
    );
    let (mut n, mut se, mut se_srgb, mut sum_a, mut sum_b) =
        (0usize, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (i, (a, b)) in image.pixels.iter().zip(&reference.pixels).enumerate() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        n += 1;
        for c in 0..3 {
            let (x, y) = (a[c] as f64, b[c] as f64);
            se += (x - y) * (x - y);
            let (sx, sy) = (linear_to_srgb(a[c]) as f64, linear_to_srgb(b[c]) as f64);
            se_srgb += (sx - sy) * (sx - sy);
            sum_a += x;
            sum_b += y;
        }
    }
    let samples = (3 * n).max(1) as f64;
    let rmse = (se / samples).sqrt();
    let mean_reference = sum_b / samples;
    let mse_srgb = se_srgb / samples;
    Comparison {
        pixels: n,
        rmse,
        relative_rmse: (mean_reference > 0.0).then(|| rmse / mean_reference),
        psnr_srgb_db: (mse_srgb > 0.0).then(|| -10.0 * mse_srgb.log10()),
        mean: sum_a / samples,
        mean_reference,
    }
}

/// Reads a mask image: a pixel is inside where its grey value is above one half.
pub fn read_mask(path: &Path, width: u32, height: u32) -> Result<Vec<bool>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    let img = image::load_from_memory(&bytes)
        .map_err(|e| Error::file(path, format!("malformed image: {e}")))?;
    let grey = img.to_luma8();
    if grey.dimensions() != (width, height) {
        return Err(Error::file(
            path,
            format!(
                "mask is {}x{}, the images are {width}x{height}",
                grey.width(),
                grey.height()
            ),
        ));
    }
    Ok(grey.pixels().map(|p| p.0[0] > 127).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn figures_match_hand_computation() {
        let mut a = Image::new(2, 1);
        let mut b = Image::new(2, 1);
        a.pixels = vec![Vec3::splat(0.5), Vec3::splat(0.2)];
        b.pixels = vec![Vec3::splat(0.4), Vec3::splat(0.2)];
        let c = compare(&a, &b, None);
        assert_eq!(c.pixels, 2);
        assert!((c.rmse - (0.01f64 / 2.0).sqrt()).abs() < 1e-7);
        assert!((c.relative_rmse.unwrap() - c.rmse / 0.3).abs() < 1e-7);
        assert!((c.mean - 0.35).abs() < 1e-7 && (c.mean_reference - 0.3).abs() < 1e-7);
        let ds = linear_to_srgb(0.5) as f64 - linear_to_srgb(0.4) as f64;
        assert!((c.psnr_srgb_db.unwrap() - (-10.0 * (ds * ds / 2.0).log10())).abs() < 1e-4);
        let masked = compare(&a, &b, Some(&[false, true]));
        assert_eq!(
            (masked.pixels, masked.rmse, masked.psnr_srgb_db),
            (1, 0.0, None)
        );
    }
}
