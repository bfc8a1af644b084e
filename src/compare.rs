//! [`Comparison`]: the error of an image against a reference photograph, in
//! linear radiance (RMSE, relative RMSE) and as seen (PSNR of the
//! sRGB-encoded images), optionally over a mask.

use std::path::Path;

use rayon::prelude::*;
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
    // Partial sums over fixed chunks, added in order: in parallel, and the
    // same figures whatever the thread count.
    const CHUNK: usize = 1 << 14;
    let partial: Vec<[f64; 5]> = image
        .pixels
        .par_chunks(CHUNK)
        .zip(reference.pixels.par_chunks(CHUNK))
        .enumerate()
        .map(|(k, (a, b))| {
            let mut s = [0.0f64; 5];
            for (j, (a, b)) in a.iter().zip(b).enumerate() {
                if mask.is_some_and(|m| !m[k * CHUNK + j]) {
                    continue;
                }
                s[0] += 1.0;
                for c in 0..3 {
                    let (x, y) = (a[c] as f64, b[c] as f64);
                    s[1] += (x - y) * (x - y);
                    let (sx, sy) = (linear_to_srgb(a[c]) as f64, linear_to_srgb(b[c]) as f64);
                    s[2] += (sx - sy) * (sx - sy);
                    s[3] += x;
                    s[4] += y;
                }
            }
            s
        })
        .collect();
    let total = partial.iter().fold([0.0f64; 5], |mut t, s| {
        for (t, s) in t.iter_mut().zip(s) {
            *t += s;
        }
        t
    });
    let [count, se, se_srgb, sum_a, sum_b] = total;
    let n = count as usize;
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

/// How much of a change a result gets right, over the pixels the change
/// touches: 1 is perfect, 0 no better than leaving the photo alone,
/// negative worse.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Skill {
    /// Pixels the change touches: where the 5×5 box-filtered |truth − photo|
    /// (mean of channels) exceeds 3% of the 5×5 box-filtered photo plus
    /// [`SKILL_FLOOR`] (edges clamped), so that the mask follows the change
    /// and not a reference's Monte Carlo noise.
    pub changed_pixels: usize,
    /// RMSE of the result against the truth over the changed pixels.
    pub rmse_changed: f64,
    /// RMSE of the unchanged photo against the truth over them.
    pub rmse_photo_changed: f64,
    /// 1 − rmse_changed / rmse_photo_changed (`None` when nothing changed).
    pub skill: Option<f64>,
}

/// The relative change under which a pixel counts as untouched, and the
/// absolute floor added to it (radiance units).
pub(crate) const SKILL_RELATIVE: f64 = 0.03;
pub const SKILL_FLOOR: f64 = 0.002;

/// Mean over a (2r+1)² window of an image-sized field, the window clamped
/// at the image's edges (edge values repeated), by a summed-area table.
fn box_filter(values: &[f64], width: usize, height: usize, r: usize) -> Vec<f64> {
    let (pw, ph) = (width + 2 * r, height + 2 * r);
    let at = |x: usize, y: usize| {
        let cx = x.saturating_sub(r).min(width - 1);
        let cy = y.saturating_sub(r).min(height - 1);
        values[cy * width + cx]
    };
    let mut sat = vec![0.0f64; (pw + 1) * (ph + 1)];
    for y in 0..ph {
        for x in 0..pw {
            sat[(y + 1) * (pw + 1) + x + 1] =
                at(x, y) + sat[y * (pw + 1) + x + 1] + sat[(y + 1) * (pw + 1) + x]
                    - sat[y * (pw + 1) + x];
        }
    }
    let k = 2 * r + 1;
    let area = (k * k) as f64;
    let mut out = vec![0.0; width * height];
    for y in 0..height {
        for x in 0..width {
            let (x1, y1) = (x + k, y + k);
            out[y * width + x] =
                (sat[y1 * (pw + 1) + x1] - sat[y * (pw + 1) + x1] - sat[y1 * (pw + 1) + x]
                    + sat[y * (pw + 1) + x])
                    / area;
        }
    }
    out
}

/// The skill of `result` at reproducing the change from `photo` to
/// `truth` (all three the same size).
pub fn skill(result: &Image, truth: &Image, photo: &Image) -> Skill {
    let changed = changed_pixels(truth, photo);
    let ours = compare(result, truth, Some(&changed));
    let photo_error = compare(photo, truth, Some(&changed));
    let (rmse_changed, rmse_photo_changed) = if ours.pixels == 0 {
        (0.0, 0.0)
    } else {
        (ours.rmse, photo_error.rmse)
    };
    Skill {
        changed_pixels: ours.pixels,
        rmse_changed,
        rmse_photo_changed,
        skill: (rmse_photo_changed > 0.0).then(|| 1.0 - rmse_changed / rmse_photo_changed),
    }
}

/// The pixels a change touches ([`Skill::changed_pixels`]), from the
/// truth and the photo alone.
pub fn changed_pixels(truth: &Image, photo: &Image) -> Vec<bool> {
    let (w, h) = (truth.width as usize, truth.height as usize);
    let mean = |p: glam::Vec3| (p.x as f64 + p.y as f64 + p.z as f64) / 3.0;
    let diff: Vec<f64> = truth
        .pixels
        .iter()
        .zip(&photo.pixels)
        .map(|(t, p)| mean((*t - *p).abs()))
        .collect();
    let level: Vec<f64> = photo.pixels.iter().map(|p| mean(*p)).collect();
    let (diff, level) = (box_filter(&diff, w, h, 2), box_filter(&level, w, h, 2));
    diff.iter()
        .zip(&level)
        .map(|(d, l)| *d > SKILL_RELATIVE * l + SKILL_FLOOR)
        .collect()
}

/// The best skill a reference allows when its own Monte Carlo noise is
/// `noise` (relative per-pixel RMSE, as each dataset's `NOISE.txt` gives
/// it): the skill of a result whose only error is that noise, i.e. whose
/// RMSE over the changed pixels is `noise` × the reference's mean there.
/// (Where real pixels show through, the composite also carries the
/// photo's own noise, so the skill reachable there is lower still.)
pub fn skill_floor(truth: &Image, photo: &Image, noise: f64) -> Option<f64> {
    let changed = changed_pixels(truth, photo);
    let photo_error = compare(photo, truth, Some(&changed));
    if photo_error.pixels == 0 || photo_error.rmse <= 0.0 {
        return None;
    }
    let floor = noise * photo_error.mean_reference;
    Some(1.0 - floor / photo_error.rmse)
}

/// A reference's relative noise measured from an independent second
/// render of it: RMSE between the two / √2 / the reference's mean.
pub fn twin_noise(reference: &Image, twin: &Image) -> f64 {
    let c = compare(twin, reference, None);
    c.relative_rmse.unwrap_or(0.0) / std::f64::consts::SQRT_2
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
    fn figures_are_the_same_on_one_thread_or_three() {
        let (w, h) = (300, 200);
        let mut a = Image::new(w, h);
        let mut b = Image::new(w, h);
        for (i, (p, q)) in a.pixels.iter_mut().zip(&mut b.pixels).enumerate() {
            *p = Vec3::splat((i % 97) as f32 * 0.013);
            *q = Vec3::splat((i % 89) as f32 * 0.011);
        }
        let mask: Vec<bool> = (0..(w * h) as usize).map(|i| i % 3 != 0).collect();
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| compare(&a, &b, Some(&mask)))
        };
        let (one, three) = (on(1), on(3));
        assert_eq!(one.rmse.to_bits(), three.rmse.to_bits());
        assert_eq!(one.mean.to_bits(), three.mean.to_bits());
        assert_eq!(one.pixels, (w * h) as usize * 2 / 3);
    }

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

    #[test]
    fn box_filter_clamps_at_the_edges() {
        // 3×1 row [0, 3, 6], radius 1: windows of 3×3 with edges repeated.
        let f = box_filter(&[0.0, 3.0, 6.0], 3, 1, 1);
        let expect = [(0.0 + 0.0 + 3.0) / 3.0, 3.0, (3.0 + 6.0 + 6.0) / 3.0];
        for (a, b) in f.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{f:?}");
        }
    }

    #[test]
    fn skill_is_one_for_the_truth_zero_for_the_photo_and_half_halfway() {
        let (w, h) = (20u32, 10u32);
        let photo = Image {
            width: w,
            height: h,
            pixels: vec![Vec3::splat(0.5); (w * h) as usize],
        };
        let mut truth = photo.clone();
        // A 6×4 patch darkened by 40%: well above the 3% threshold.
        for y in 3..7 {
            for x in 5..11 {
                truth.pixels[(y * w + x) as usize] = Vec3::splat(0.3);
            }
        }
        let halfway = Image {
            pixels: photo
                .pixels
                .iter()
                .zip(&truth.pixels)
                .map(|(p, t)| (*p + *t) * 0.5)
                .collect(),
            ..photo.clone()
        };
        let s = skill(&truth, &truth, &photo);
        assert_eq!(s.skill, Some(1.0));
        // Changed: the pixels whose 5×5 window holds at least 3 of the
        // patch's (3 × 0.2 / 25 > 0.03 × 0.5 + 0.002), 68 by brute force.
        assert_eq!(s.changed_pixels, 68);
        assert_eq!(skill(&photo, &truth, &photo).skill, Some(0.0));
        let half = skill(&halfway, &truth, &photo).skill.unwrap();
        assert!((half - 0.5).abs() < 1e-6, "{half}");
        assert_eq!(skill(&photo, &photo, &photo).skill, None);
    }
}
