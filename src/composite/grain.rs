//! The photo's grain, kept out of a brightening. Where a change adds light,
//! photo × (with / without) would scale the photo's noise with it (a lamp
//! doubled: its grain ×1.4 over the whole room); the added part is taken
//! from the photo with its grain smoothed out instead, so the grain stays as
//! shot. Where light is taken away the plain ratio already scales the grain
//! down, as a darker exposure has it.

use glam::Vec3;
use rayon::prelude::*;

use crate::image_io::Image;

/// The photo's relative noise: the robust spread (MAD) of each pixel's
/// luminance against the mean of its four neighbours, relative to that
/// mean. Edges and texture are a minority of pixels and leave the median.
pub fn relative_noise(photo: &Image) -> f64 {
    let (w, h) = (photo.width as usize, photo.height as usize);
    if w < 3 || h < 3 {
        return 0.0;
    }
    let lum = |x: usize, y: usize| {
        let p = photo.pixels[y * w + x];
        ((p.x + p.y + p.z) / 3.0) as f64
    };
    let mut rel: Vec<f64> = (1..h - 1)
        .into_par_iter()
        .flat_map_iter(|y| {
            (1..w - 1).filter_map(move |x| {
                let around = (lum(x - 1, y) + lum(x + 1, y) + lum(x, y - 1) + lum(x, y + 1)) / 4.0;
                (around > 0.0 && around.is_finite()).then(|| ((lum(x, y) - around) / around).abs())
            })
        })
        .collect();
    if rel.is_empty() {
        return 0.0;
    }
    let mid = rel.len() / 2;
    let median = *rel.select_nth_unstable_by(mid, f64::total_cmp).1;
    // MAD to a standard deviation; the neighbours' mean adds a quarter of
    // the variance to the difference.
    median / 0.6745 / 1.25f64.sqrt()
}

/// The photo smoothed within its noise: a 5×5 bilateral filter whose range
/// kernel is three times the relative noise, so that steps of texture and
/// shading larger than the grain stay sharp. Hand-written: the image
/// crates' bilateral filters take 8-bit single-channel images, not
/// floating-point radiance.
pub fn smoothed(photo: &Image, relative_noise: f64) -> Image {
    let (w, h) = (photo.width as usize, photo.height as usize);
    let range = (3.0 * relative_noise as f32).max(1e-6);
    let spatial = 1.5f32;
    let lum = |p: Vec3| (p.x + p.y + p.z) / 3.0;
    let mut out = photo.clone();
    out.pixels
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            for (x, o) in row.iter_mut().enumerate() {
                let c = photo.pixels[y * w + x];
                let lc = lum(c);
                if lc <= 0.0 || !lc.is_finite() {
                    continue;
                }
                let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
                for dy in -2i64..=2 {
                    for dx in -2i64..=2 {
                        let (qx, qy) = (x as i64 + dx, y as i64 + dy);
                        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                            continue;
                        }
                        let q = photo.pixels[qy as usize * w + qx as usize];
                        let step = (lum(q) - lc) / (lc * range);
                        let d2 = (dx * dx + dy * dy) as f32;
                        let wq = (-d2 / (2.0 * spatial * spatial) - 0.5 * step * step).exp();
                        if wq.is_finite() && q.is_finite() {
                            sum += q * wq;
                            weight += wq;
                        }
                    }
                }
                if weight > 0.0 {
                    *o = sum / weight;
                }
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w`×`h` image: `level(x)` times (1 + `noise`·a standard normal
    /// deviate per pixel, seeded by the pixel).
    fn noisy(w: u32, h: u32, noise: f64, level: impl Fn(u32) -> f32) -> Image {
        let mut img = Image::new(w, h);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            let mut s = crate::util::rng::hash2(i as u64, 7);
            let (u1, u2) = (
                crate::util::rng::unit_random(&mut s).max(1e-12),
                crate::util::rng::unit_random(&mut s),
            );
            let z = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
            *p = Vec3::splat(level(i as u32 % w) * (1.0 + noise * z) as f32);
        }
        img
    }

    fn relative_spread(img: &Image, columns: std::ops::Range<u32>, level: f32) -> f64 {
        let w = img.width;
        let d: Vec<f64> = (0..img.height)
            .flat_map(|y| columns.clone().map(move |x| (x, y)))
            .map(|(x, y)| (img.pixels[(y * w + x) as usize].x / level - 1.0) as f64)
            .collect();
        (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt()
    }

    #[test]
    fn the_noise_of_a_flat_photo_is_read_within_a_tenth() {
        for noise in [0.005, 0.02, 0.05] {
            let got = relative_noise(&noisy(256, 192, noise, |_| 0.3));
            assert!((got / noise - 1.0).abs() < 0.1, "noise {noise}: read {got}");
        }
    }

    #[test]
    fn smoothing_takes_the_grain_and_keeps_a_step() {
        // Two halves, 0.2 and 0.3 (a 50% step, as a shadow's or texture's
        // edge), under 2% grain.
        let level = |x: u32| if x < 64 { 0.2 } else { 0.3 };
        let photo = noisy(128, 96, 0.02, level);
        let smooth = smoothed(&photo, relative_noise(&photo));
        // Away from the step the grain falls to under half.
        let (left, right) = (
            relative_spread(&smooth, 4..60, 0.2),
            relative_spread(&smooth, 68..124, 0.3),
        );
        assert!(
            left < 0.01 && right < 0.01,
            "grain left {left}, right {right}"
        );
        // At the step each side keeps its level within the grain.
        for y in 2..94 {
            let (a, b) = (
                smooth.pixels[(y * 128 + 63) as usize].x,
                smooth.pixels[(y * 128 + 64) as usize].x,
            );
            assert!((a / 0.2 - 1.0).abs() < 0.05, "row {y}: {a} beside the step");
            assert!((b / 0.3 - 1.0).abs() < 0.05, "row {y}: {b} beside the step");
        }
    }
}
