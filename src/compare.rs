//! [`Comparison`]: the error of an image against a reference photograph, in
//! linear radiance (RMSE, relative RMSE) and as seen (PSNR of the
//! sRGB-encoded images), optionally over a mask.

use std::path::Path;

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::image_io::{Image, linear_to_srgb};

mod bands;
pub use bands::BandComparison;

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
    // Sums row by row, added in row order: in parallel, the same figures
    // whatever the thread count, and the same as [`BandComparison`]'s,
    // which is handed the rows a band at a time.
    let w = (image.width as usize).max(1);
    let rows: Vec<Sums> = image
        .pixels
        .par_chunks(w)
        .zip(reference.pixels.par_chunks(w))
        .enumerate()
        .map(|(y, (a, b))| row_sums(a, b, mask.map(|m| &m[y * w..(y + 1) * w])))
        .collect();
    let mut total = Sums::default();
    rows.iter().for_each(|s| total.add(s));
    total.comparison()
}

/// A comparison's sums: pixels, squared error linear and sRGB-encoded,
/// and the two images' sums.
#[derive(Debug, Clone, Copy, Default)]
struct Sums([f64; 5]);

impl Sums {
    fn add(&mut self, other: &Sums) {
        for (t, s) in self.0.iter_mut().zip(other.0) {
            *t += s;
        }
    }

    fn comparison(&self) -> Comparison {
        let [count, se, se_srgb, sum_a, sum_b] = self.0;
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
}

/// One row's [`Sums`] of `a` against `b` where `mask` is true.
fn row_sums(a: &[Vec3], b: &[Vec3], mask: Option<&[bool]>) -> Sums {
    let mut s = [0.0f64; 5];
    for (j, (a, b)) in a.iter().zip(b).enumerate() {
        if mask.is_some_and(|m| !m[j]) {
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
    Sums(s)
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

/// Means over a (2r+1)² window of `N` image-sized fields (`at(x, y)` gives
/// their values), the window clamped at the image's edges (edge values
/// repeated), handed to `each` a row at a time. Holds 2r+1 rows of
/// horizontal sums, never a whole field: a 24-megapixel frame's skill took
/// four field-sized f64 arrays (760 MB) by a summed-area table.
fn box_rows<const N: usize>(
    width: usize,
    height: usize,
    r: usize,
    at: impl Fn(usize, usize) -> [f64; N],
    mut each: impl FnMut(usize, &[[f64; N]]),
) {
    let mut window: std::collections::VecDeque<(usize, Vec<[f64; N]>)> = Default::default();
    let mut means = vec![[0.0; N]; width];
    for y in 0..height {
        let (lo, hi) = (y.saturating_sub(r), (y + r).min(height - 1));
        while window.front().is_some_and(|(row, _)| *row < lo) {
            window.pop_front();
        }
        for row in window.back().map_or(lo, |(last, _)| last + 1)..=hi {
            let values: Vec<[f64; N]> = (0..width).map(|x| at(x, row)).collect();
            window.push_back((row, horizontal_sums(&values, r)));
        }
        let rows: Vec<&[[f64; N]]> = (window_rows(y, r, height))
            .map(|row| window[row - lo].1.as_slice())
            .collect();
        vertical_means(&rows, &mut means);
        each(y, &means);
    }
}

/// The rows of row `y`'s window of radius `r`, top to bottom, clamped.
fn window_rows(y: usize, r: usize, height: usize) -> impl Iterator<Item = usize> {
    (-(r as isize)..=r as isize)
        .map(move |dy| (y as isize + dy).clamp(0, height as isize - 1) as usize)
}

/// Each value's sum over x − r..=x + r of its row (edges repeated).
fn horizontal_sums<const N: usize>(row: &[[f64; N]], r: usize) -> Vec<[f64; N]> {
    let width = row.len();
    (0..width)
        .map(|x| {
            let mut sum = [0.0; N];
            for dx in -(r as isize)..=r as isize {
                let v = row[(x as isize + dx).clamp(0, width as isize - 1) as usize];
                (0..N).for_each(|n| sum[n] += v[n]);
            }
            sum
        })
        .collect()
}

/// The window means at each x from its 2r+1 rows of horizontal sums (in
/// order, top to bottom).
fn vertical_means<const N: usize>(rows: &[&[[f64; N]]], means: &mut [[f64; N]]) {
    let area = (rows.len() * rows.len()) as f64;
    for (x, mean) in means.iter_mut().enumerate() {
        let mut sum = [0.0; N];
        for row in rows {
            (0..N).for_each(|n| sum[n] += row[x][n]);
        }
        *mean = sum.map(|v| v / area);
    }
}

/// The skill of `result` at reproducing the change from `photo` to
/// `truth` (all three the same size).
pub fn skill(result: &Image, truth: &Image, photo: &Image) -> Skill {
    let changed = changed_pixels(truth, photo);
    Skill::of(
        compare(result, truth, Some(&changed)),
        compare(photo, truth, Some(&changed)),
    )
}

impl Skill {
    /// From the result's and the photo's comparisons over the changed pixels.
    fn of(ours: Comparison, photo_error: Comparison) -> Skill {
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
}

/// The window radius of [`Skill::changed_pixels`]' means (5 × 5).
const CHANGE_RADIUS: usize = 2;

/// What a pixel's change window averages: |truth − photo| and the photo,
/// each the mean of its channels.
fn change_values(truth: Vec3, photo: Vec3) -> [f64; 2] {
    let mean = |p: Vec3| (p.x as f64 + p.y as f64 + p.z as f64) / 3.0;
    [mean((truth - photo).abs()), mean(photo)]
}

/// Whether a pixel whose window means are `means` is changed.
fn is_changed([diff, level]: [f64; 2]) -> bool {
    diff > SKILL_RELATIVE * level + SKILL_FLOOR
}

/// The pixels a change touches ([`Skill::changed_pixels`]), from the
/// truth and the photo alone.
pub fn changed_pixels(truth: &Image, photo: &Image) -> Vec<bool> {
    let (w, h) = (truth.width as usize, truth.height as usize);
    let at = |x: usize, y: usize| change_values(truth.pixels[y * w + x], photo.pixels[y * w + x]);
    let mut changed = vec![false; w * h];
    box_rows(w, h, CHANGE_RADIUS, at, |y, means| {
        for (c, m) in changed[y * w..(y + 1) * w].iter_mut().zip(means) {
            *c = is_changed(*m);
        }
    });
    changed
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
    fn box_means_clamp_at_the_edges() {
        // 3×2 field, rows [0, 3, 6] and [6, 9, 12], radius 1: 3×3 windows
        // with edges repeated (the first row's window takes it twice).
        let field = [[0.0, 3.0, 6.0], [6.0, 9.0, 12.0]];
        let mut rows = Vec::new();
        box_rows(3, 2, 1, |x, y| [field[y][x]], |_, m| rows.push(m.to_vec()));
        let row_mean = |r: [f64; 3], x: usize| match x {
            0 => (2.0 * r[0] + r[1]) / 3.0,
            1 => r[1],
            _ => (r[1] + 2.0 * r[2]) / 3.0,
        };
        for (y, row) in rows.iter().enumerate() {
            for (x, m) in row.iter().enumerate() {
                let (a, b) = (row_mean(field[0], x), row_mean(field[1], x));
                let expect = if y == 0 {
                    (2.0 * a + b) / 3.0
                } else {
                    (a + 2.0 * b) / 3.0
                };
                assert!(
                    (m[0] - expect).abs() < 1e-12,
                    "({x}, {y}): {m:?} against {expect}"
                );
            }
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
