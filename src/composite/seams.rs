//! Where the model's real surfaces meet in the image: one surface against
//! another, a fold between two planes, the end of the model. A pixel on
//! such a seam mixes what the photo shows on either side, and a rough
//! model (vertices centimetres off, boards thicker or thinner than the
//! real ones) puts its seams a pixel or two off the photo's edges; either
//! way the one surface the pixel's centre meets gives it a change the
//! photo's content there does not take (thin boards come out with bright
//! and dark lines along their edges). There the change is taken from the
//! neighbours that look like the pixel in the photo: a joint bilateral
//! filter of the change, guided by the photo (as joint bilateral
//! upsampling guides a coarse solution by a photo; Kopf et al. 2007).
//!
//! Measured (pixel path, against the same code without it): lounge
//! `stool_b` skill 0.801 → 0.813, `stool_table` 0.805 → 0.811,
//! `lamp_off_bulb_on` RMSE 0.01595 → 0.01535, `panel_2_x2` 0.00645 →
//! 0.00633; desk `panel_off` 0.00150 → 0.00134, `virtual_light_only`
//! 0.00612 → 0.00582 (the exact model's seams are anti-aliased mixes);
//! `box_floor_a` the same; `whitebox` within 0.5%.

use glam::Vec3;
use rayon::prelude::*;

use super::Composite;
use crate::image_io::Image;
use crate::pda::{PixelDataArray, SAME_PLANE_COS};

/// How near a seam (in pixels, either axis) a pixel counts as on it: a
/// rough model's edges stray a pixel or two at the photo's resolution.
const REACH: i64 = 2;
/// Half the filter's window: 7 × 7 pixels.
const WINDOW: i64 = 3;
/// How far from a pixel the filter reads: its window's pixels, and whether
/// each lies on a seam. A crop's pixel data reaches this far past the crop,
/// so that a tile's pixels are the whole frame's.
const NEIGHBOURHOOD: u32 = (REACH + WINDOW) as u32;
// The pixel data reaches as far as the filter reads (no import the other way).
const _: () = assert!(NEIGHBOURHOOD <= crate::pda::MARGIN);
/// A seam pixel is filtered where the change among its 3 × 3 neighbours
/// spans more than this fraction of its own: above the change's own noise
/// (shadow rays, the grain kept), below a pixel's step across a seam.
const JUMP: f32 = 0.03;
/// The filter's spatial σ, in pixels.
const SIGMA_SPACE: f32 = 1.5;
/// The filter's photo σ, on the natural log of each channel: neighbours
/// more than ~20% apart in the photo show something else.
const SIGMA_PHOTO: f32 = 0.2;
/// The weight of a neighbour on a seam against one off it: the stray
/// pixels lie on seams, and at full weight would spread their change to
/// the pixels beside them.
const SEAM_TRUST: f32 = 0.2;
/// Photo values below this carry no ratio.
const DARK: f32 = 1e-6;

/// The pixels (ascending) whose real point lies within [`REACH`] of a
/// pixel that sees another surface, another plane, or no real surface.
/// They depend on the real surfaces alone: a session finds them once.
pub(super) fn seam_pixels(pda: &PixelDataArray) -> Vec<u32> {
    let (w, h) = (pda.width as i64, pda.height as i64);
    let point = |x: i64, y: i64| {
        let k = pda.real_at((y * w + x) as usize);
        (k != u32::MAX).then(|| &pda.real.points[k as usize])
    };
    (pda.rows.0 as i64..pda.rows.1 as i64)
        .into_par_iter()
        .flat_map_iter(|y| {
            (0..w).filter_map(move |x| {
                let p = point(x, y)?;
                let differs = (y - REACH..=y + REACH).any(|v| {
                    (x - REACH..=x + REACH).any(|u| {
                        if u < 0 || v < 0 || u >= w || v >= h {
                            return false;
                        }
                        point(u, v).is_none_or(|q| {
                            q.surface != p.surface || q.normal.dot(p.normal) < SAME_PLANE_COS
                        })
                    })
                });
                differs.then_some((y * w + x) as u32)
            })
        })
        .collect()
}

/// Filters the change at the seam pixels of `pda` where it jumps (see the
/// module): the image's value there becomes the photo × the mean of the
/// neighbours' ratios of image to photo, weighted by their likeness in
/// the photo and their distance, and less where they lie on a seam
/// themselves (the stray pixels are among them, and would spread their
/// change to the pixels beside them). Only pixels that show a real point
/// alone take part (`no_object`: whether a pixel shows no object).
pub(super) fn smooth_seams(
    pda: &PixelDataArray,
    photo: &Image,
    seams: &[u32],
    no_object: &(dyn Fn(usize) -> bool + Sync),
    out: &mut Composite,
) {
    let (w, h) = (pda.width as i64, pda.height as i64);
    // The composite holds the rows the pixel data holds.
    let first = out.first_row as usize * pda.width as usize;
    let plain = |i: usize| {
        pda.real_at(i) != u32::MAX && photo.pixels[i].min_element() > DARK && no_object(i)
    };
    let image = &out.image.pixels;
    let gain = |i: usize| image[i - first] / photo.pixels[i];
    let filtered: Vec<(usize, Vec3)> = seams
        .par_iter()
        .filter_map(|&s| {
            let i = s as usize;
            if !plain(i) {
                return None;
            }
            let (x, y) = (i as i64 % w, i as i64 / w);
            let window =
                |r: i64| (y - r..=y + r).flat_map(move |v| (x - r..=x + r).map(move |u| (u, v)));
            let inside = |(u, v): &(i64, i64)| *u >= 0 && *v >= 0 && *u < w && *v < h;
            let own = gain(i).element_sum() / 3.0;
            let (lo, hi) = window(1)
                .filter(inside)
                .map(|(u, v)| (u + v * w) as usize)
                .filter(|&j| plain(j))
                .map(|j| gain(j).element_sum() / 3.0)
                .fold((own, own), |(lo, hi), g| (lo.min(g), hi.max(g)));
            if hi - lo <= JUMP * own.abs().max(1e-3) {
                return None;
            }
            let log_i = photo.pixels[i].ln();
            let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
            for (u, v) in window(WINDOW).filter(inside) {
                let j = (u + v * w) as usize;
                if !plain(j) {
                    continue;
                }
                let d = photo.pixels[j].ln() - log_i;
                let r2 = ((u - x).pow(2) + (v - y).pow(2)) as f32;
                let trust = if seams.binary_search(&(j as u32)).is_ok() {
                    SEAM_TRUST
                } else {
                    1.0
                };
                let wt = trust
                    * (-d.length_squared() / (2.0 * SIGMA_PHOTO * SIGMA_PHOTO)
                        - r2 / (2.0 * SIGMA_SPACE * SIGMA_SPACE))
                        .exp();
                sum += gain(j) * wt;
                weight += wt;
            }
            // The pixel itself weighs SEAM_TRUST at least: the sum is never empty.
            Some((i, (photo.pixels[i] * sum / weight).max(Vec3::ZERO)))
        })
        .collect();
    let layers = out.change.pixels.len() == out.image.pixels.len();
    for (i, v) in filtered {
        if v.is_finite() {
            out.image.pixels[i - first] = v;
            if layers {
                out.change.pixels[i - first] = v - photo.pixels[i];
            }
        }
    }
}
