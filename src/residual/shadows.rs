//! Real pixels an object's shadow edge crosses: the light each light
//! leaves there averaged over the pixel's footprint, as a photograph
//! averages it, rather than read at its centre. A hard edge (a point
//! light's, a small lamp's) otherwise leaves such a pixel wholly lit or
//! wholly dark where the photo would show it in between.

use super::*;
use crate::pda::LightTerm;
use crate::trace::Layer;
use crate::util::rng::hash2;

/// Sub-pixel samples per boundary pixel and round.
pub(super) const ROUND_SUBPIXELS: u32 = 4;

/// Rounds a boundary pixel takes in every render, with or without rounds
/// of samples: 16 points of its footprint. At the centre alone, the 131
/// pixels the edges of `materials` `trio`'s shadows cross held 24% of its
/// squared error.
pub const LEAST_ROUNDS: u32 = 4;

/// The change in a light's occlusion by the objects between neighbouring
/// pixels above which an edge crosses between them: a soft penumbra, which
/// the centre's 2^level shadow rays resolve, changes less from one pixel
/// to the next.
const EDGE_STEP: f64 = 0.25;

/// A boundary pixel and, per light whose edge crosses it, its sums.
pub(super) struct Task {
    pub(super) pixel: u32,
    pub(super) point: u32,
    lights: Vec<u8>,
    /// Per light of `lights`, the visible fraction summed over sub-samples.
    seen: Vec<f64>,
    /// Per light, the sum of squares (for the noise).
    squares: Vec<f64>,
    /// Sub-samples that met a real surface.
    samples: u32,
}

/// The objects' occlusion of light `l` at real point `k`.
fn occlusion(terms: &[LightTerm], k: usize, lights: usize, l: usize) -> f64 {
    let t = &terms[k * lights + l];
    t.visible(false) - t.visible(true)
}

/// Every plain real pixel next to another across which an object's shadow
/// of some light steps by more than [`EDGE_STEP`].
pub(super) fn tasks(input: &ResidualInput) -> Vec<Task> {
    let pda = input.pda;
    if input.room.is_none() || pda.light_count > u8::MAX as usize {
        return Vec::new();
    }
    let (w, first) = (pda.width as i64, pda.first_pixel() as u32);
    let slots = pda.real_index.len();
    let lights = pda.light_count;
    // Without rounds, the point lights' edges alone: an area light's
    // penumbra is resolved at the centre by its stratified shadow rays,
    // which 16 single rays over the footprint would make noisier.
    let rounds = input.settings.enabled();
    let on: Vec<usize> = (0..lights)
        .filter(|&l| input.shading.scales_with.get(l).is_some_and(|&s| s > 0.0))
        .filter(|&l| rounds || input.shading.lights[l].grid.is_none())
        .collect();
    if on.is_empty() {
        return Vec::new();
    }
    // Only a plain real pixel the objects shade, or one beside it, can be
    // crossed by an edge: those found first in one pass over the frame,
    // their neighbours then read directly (a search of the outlines per
    // neighbour of every pixel took most of an update's time).
    let mut outline = vec![false; slots];
    for e in &pda.edges {
        if let Some(s) = (e.pixel.checked_sub(first)).and_then(|s| outline.get_mut(s as usize)) {
            *s = true;
        }
    }
    let terms = &pda.real.terms;
    let plain = |slot: i64| -> Option<usize> {
        let s = usize::try_from(slot).ok().filter(|&s| s < slots)?;
        let k = pda.real_index[s];
        (k != u32::MAX && pda.virtual_index[s] == u32::MAX && !outline[s]).then_some(k as usize)
    };
    let shaded: Vec<i64> = (0..slots as i64)
        .into_par_iter()
        .filter(|&slot| {
            plain(slot).is_some_and(|k| on.iter().any(|&l| occlusion(terms, k, lights, l) != 0.0))
        })
        .collect();
    let mut candidates: Vec<i64> = (shaded.iter())
        .flat_map(|&slot| {
            let x = slot % w;
            (-1..=1).flat_map(move |dy| {
                (-1..=1)
                    .filter(move |dx| (0..w).contains(&(x + dx)))
                    .map(move |dx| slot + dx + dy * w)
            })
        })
        .collect();
    candidates.sort_unstable();
    candidates.dedup();
    candidates
        .into_par_iter()
        .filter_map(|slot| {
            let k = plain(slot)?;
            let x = slot % w;
            let crossing: Vec<u8> = (on.iter().copied())
                .filter(|&l| {
                    let here = occlusion(terms, k, lights, l);
                    [
                        (-1, -1),
                        (0, -1),
                        (1, -1),
                        (-1, 0),
                        (1, 0),
                        (-1, 1),
                        (0, 1),
                        (1, 1),
                    ]
                    .iter()
                    .filter(|(dx, _)| (0..w).contains(&(x + dx)))
                    .filter_map(|(dx, dy)| plain(slot + dx + dy * w))
                    .any(|j| (occlusion(terms, j, lights, l) - here).abs() > EDGE_STEP)
                })
                .map(|l| l as u8)
                .collect();
            (!crossing.is_empty()).then(|| Task {
                pixel: first + slot as u32,
                point: k as u32,
                seen: vec![0.0; crossing.len()],
                squares: vec![0.0; crossing.len()],
                lights: crossing,
                samples: 0,
            })
        })
        .collect()
}

/// Round `round` of task `t`; returns the rays traced.
pub(super) fn sample(input: &ResidualInput, t: &mut Task, round: u32) -> u64 {
    let shading = input.shading;
    let key = hash2(t.pixel as u64, 0x5AD0_11E5);
    let mut rays = 0;
    for sub in subpixels(input, t.pixel, key, round, ROUND_SUBPIXELS) {
        let SubPixel {
            index, ray, traced, ..
        } = sub;
        rays += 1;
        // A sub-sample that shows an object is the object's pixel's
        // business: this one's light is the room's around it.
        let Some(hit) = shading
            .tracer
            .intersect(&traced, Layer::All)
            .filter(|h| !h.is_virtual)
        else {
            continue;
        };
        let x = ray.origin + ray.direction * hit.t as f64;
        let n = hit.normal.as_dvec3();
        t.samples += 1;
        for (s, &l) in t.lights.iter().enumerate() {
            let light = &shading.lights[l as usize];
            // One shadow ray (to a point of a rect light's grid picked by
            // the sub-sample): over rounds, the footprint and the light's
            // area together.
            let seed = hash2(key, ((index as u64) << 8) | l as u64);
            let d = light.direct(shading.tracer, Layer::All, x, n, 0, seed);
            rays += d.rays as u64;
            let v = if d.unoccluded == DVec3::ZERO {
                0.0
            } else {
                d.visibility
            };
            t.seen[s] += v;
            t.squares[s] += v * v;
        }
    }
    rays
}

/// Task `t`'s footprint-averaged visibility per light (None: no
/// sub-sample met the room) and its pixel's estimated noise (radiance).
pub(super) fn result(input: &ResidualInput, t: &Task) -> (Option<Vec<(u8, f32)>>, f64) {
    if t.samples == 0 {
        return (None, 0.0);
    }
    let pda = input.pda;
    let shading = input.shading;
    let lights = pda.light_count;
    let n = t.samples as f64;
    let k = t.point as usize;
    let p = &pda.real.points[k];
    let rho = (shading.reflectance.get(p.location.patch as usize))
        .copied()
        .unwrap_or(DVec3::ZERO);
    let mut variance = 0.0;
    let out = (t.lights.iter().enumerate())
        .map(|(s, &l)| {
            let mean = t.seen[s] / n;
            let term = &pda.real.terms[k * lights + l as usize];
            let e = shading.lights[l as usize].colour()
                * (shading.scales_with[l as usize] * term.unoccluded as f64);
            let spread = (t.squares[s] / n - mean * mean).max(0.0) / (n - 1.0).max(1.0);
            variance += spread * luminance(rho * e / std::f64::consts::PI).powi(2);
            (l, mean.min(term.visible(false)) as f32)
        })
        .collect();
    (Some(out), variance.sqrt())
}
