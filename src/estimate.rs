//! Diffuse reflectances of the real surfaces estimated from the photograph
//! ([`estimate_reflectances`]), given the lights and the geometry.
//!
//! Per patch, the photo's mean radiance over the pixels where the patch is
//! seen gives its radiosity B̂ = π·L̂ ([`PhotoPatches`]). The first guess is
//! Loscos Eq. 1, ρ = (B̂_i / B̂_A)·ρ̂; then Grosch EQ2, ρ = B̂ / (E + Σ F·B),
//! is iterated with the radiosity solution to a fixed point: the indirect
//! light is gathered from the photo's radiosity where a patch is seen and
//! from the model where it is not. Known reflectances are kept; estimates
//! are clamped to [0, 0.99]; patches the photo does not see take their
//! surface's area-weighted mean.

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use crate::camera::Camera;
use crate::image_io::Image;
use crate::patches::Patches;
use crate::radiosity::{Solution, Transport, solve_from};
use crate::surface_ids::row_hits;
use crate::trace::{Layer, Tracer};

/// The most a reflectance estimate may be: at 1 a surface would give back
/// all light it receives, and the system would have no solution.
pub const MAX_REFLECTANCE: f64 = 0.99;

/// Photo radiance per patch.
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoPatches {
    /// Mean photo radiance over the pixels whose centre sees the patch.
    pub radiance: Vec<DVec3>,
    /// Those pixels' count (0: the photo does not see the patch).
    pub pixels: Vec<u32>,
    /// Mean photo radiance over every pixel that sees a real surface.
    pub image_mean: DVec3,
}

impl PhotoPatches {
    /// Traces each pixel centre into the real geometry and averages the photo per patch.
    pub fn measure(
        camera: &Camera,
        tracer: &Tracer,
        patches: &Patches,
        photo: &Image,
    ) -> PhotoPatches {
        let n = patches.patch_count();
        let w = camera.width as usize;
        // Each pixel's patch (u32::MAX: none), 4 bytes a pixel rather than a
        // (patch, colour) pair's 32: the sums below read the photo again, in
        // the same order, so they are the same to the bit.
        let mut patch_of = vec![u32::MAX; w * camera.height as usize];
        patch_of
            .par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(row, out)| {
                let hits = row_hits(camera, tracer, Layer::Real, row as u32);
                for (col, (o, h)) in out.iter_mut().zip(&hits).enumerate() {
                    let Some(h) = h.as_ref() else { continue };
                    let x = camera.position
                        + camera.pixel_ray(col as u32, row as u32).direction * h.t as f64;
                    if let Some(at) = patches.locate(h.surface, h.triangle, x) {
                        *o = at.patch;
                    }
                }
            });
        let mut sum = vec![DVec3::ZERO; n];
        let mut pixels = vec![0u32; n];
        let (mut total, mut count) = (DVec3::ZERO, 0usize);
        for (i, &patch) in patch_of.iter().enumerate() {
            if patch == u32::MAX {
                continue;
            }
            let value = photo.pixels[i].as_dvec3();
            sum[patch as usize] += value;
            pixels[patch as usize] += 1;
            total += value;
            count += 1;
        }
        let radiance = sum
            .iter()
            .zip(&pixels)
            .map(|(s, &c)| if c > 0 { *s / c as f64 } else { DVec3::ZERO })
            .collect();
        PhotoPatches {
            radiance,
            pixels,
            image_mean: total / count.max(1) as f64,
        }
    }
}

/// The result of estimation.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Reflectance per patch.
    pub reflectance: Vec<DVec3>,
    /// The forward radiosity solution with these reflectances.
    pub solution: Solution,
    /// Patches whose estimate was clamped to [0, MAX_REFLECTANCE] in some channel.
    pub clamped: usize,
    /// Patches the photo does not see (or that receive no light), filled by surface means.
    pub unseen: usize,
    /// Fixed-point iterations run, and the last largest change of a reflectance.
    pub iterations: usize,
    pub change: f64,
    /// The share of the photo's pixels on estimated patches whose estimate
    /// hit the upper clamp, and by how much (the pixel-weighted median of
    /// raw ρ / the clamp): when the lights given are too weak for the photo
    /// the estimates pile up there, by about the lights' shortfall.
    pub pinned_share: f64,
    pub pinned_factor: f64,
}

/// Settings of the estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateSettings {
    /// Stop when no reflectance changes by more than this.
    pub tolerance: f64,
    pub max_iterations: usize,
    /// Relative residual of each radiosity solve.
    pub solve_tolerance: f64,
}

impl Default for EstimateSettings {
    fn default() -> Self {
        EstimateSettings {
            tolerance: 1e-4,
            max_iterations: 30,
            solve_tolerance: 1e-7,
        }
    }
}

/// The step after one of length `step` asked for `ask` where the round
/// before asked for `last`: were each round's ask the last one's times c,
/// c = 1 − step·(1 − λ) for the map's gain λ, and the step that cancels
/// it is step / (1 − c). An ask that does not shrink along the last keeps
/// the step.
fn secant_step(step: f64, ask: &[DVec3], last: &[DVec3]) -> f64 {
    let dot = |a: &[DVec3], b: &[DVec3]| a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum::<f64>();
    let norm = dot(last, last);
    let c = if norm > 0.0 {
        dot(ask, last) / norm
    } else {
        1.0
    };
    if c < 1.0 { step / (1.0 - c) } else { step }
}

/// Estimates a reflectance per patch. `direct` is the total direct
/// irradiance per patch; `known` maps surface ids to known reflectances.
pub fn estimate_reflectances(
    patches: &Patches,
    transport: &Transport,
    direct: &[DVec3],
    photo: &PhotoPatches,
    known: &HashMap<u32, DVec3>,
    settings: EstimateSettings,
) -> Estimate {
    let n = patches.patch_count();
    let surface = |k: usize| patches.patch(k).surface;
    let eq2 = Eq2 {
        patches,
        transport,
        direct,
        photo,
        known,
        seen: (0..n)
            .map(|k| photo.pixels[k] > 0 && !known.contains_key(&surface(k)))
            .collect(),
    };
    let mut rho = eq2.first_guess();
    let mut estimated = eq2.seen.clone();
    fill_unseen(patches, &mut rho, &estimated, known);

    let (mut iterations, mut change, mut clamped) = (0, f64::INFINITY, 0);
    // Per pinned patch of the last round: its pixels and raw ρ / clamp.
    let mut pinned: Vec<(u32, f64)> = Vec::new();
    let mut previous: Option<Vec<DVec3>> = None;
    // Each step moves the reflectances by `step` of the way EQ2 asks. In a
    // white room the unseen patches (which take their surface's mean) feed
    // back on the seen ones' indirect light with a gain above one, and the
    // full step oscillates for ever: the step halves whenever the largest
    // change grows instead of shrinking, and is otherwise set by the secant
    // rule (Irons & Tuck's form of Aitken's Δ², one step length for every
    // patch) from how far this round's ask goes along the last one's.
    let mut step = 1.0f64;
    let mut last_ask: Option<Vec<DVec3>> = None;
    while iterations < settings.max_iterations && change > settings.tolerance {
        iterations += 1;
        // A forward solve finer than a hundredth of the last round's change
        // moves no reflectance; the final solve meets the full tolerance.
        let tolerance = (change * 1e-2).clamp(settings.solve_tolerance, 1e-3);
        let model = eq2.solve(&rho, previous.as_deref(), tolerance);
        let mixed: Vec<DVec3> = (0..n)
            .map(|k| {
                if photo.pixels[k] > 0 {
                    photo.radiance[k] * std::f64::consts::PI
                } else {
                    model.radiosity[k]
                }
            })
            .collect();
        previous = Some(model.radiosity);
        let mut next = rho.clone();
        (clamped, pinned) = eq2.round(&mixed, &mut next, &mut estimated);
        fill_unseen(patches, &mut next, &estimated, known);
        let ask: Vec<DVec3> = next.iter().zip(&rho).map(|(a, b)| *a - *b).collect();
        let asked = ask
            .iter()
            .map(|d| d.abs().max_element())
            .fold(0.0, f64::max);
        step = if asked > change {
            step * 0.5
        } else {
            last_ask.map_or(step, |last| secant_step(step, &ask, &last))
        }
        .clamp(1.0 / 64.0, 1.0);
        last_ask = Some(ask);
        change = asked;
        if step < 1.0 {
            for (n, r) in next.iter_mut().zip(&rho) {
                *n = *r + (*n - *r) * step;
            }
        }
        rho = next;
    }
    let solution = eq2.solve(&rho, previous.as_deref(), settings.solve_tolerance);
    let unseen = (0..n)
        .filter(|&k| !estimated[k] && !known.contains_key(&surface(k)))
        .count();
    let seen_pixels: u64 = (0..n)
        .filter(|&k| eq2.seen[k])
        .map(|k| photo.pixels[k] as u64)
        .sum();
    let (pinned_share, pinned_factor) = pinned_median(pinned, seen_pixels);
    Estimate {
        reflectance: rho,
        solution,
        clamped,
        unseen,
        iterations,
        change,
        pinned_share,
        pinned_factor,
    }
}

/// What EQ2's fixed point reads.
struct Eq2<'a> {
    patches: &'a Patches,
    transport: &'a Transport,
    direct: &'a [DVec3],
    photo: &'a PhotoPatches,
    known: &'a HashMap<u32, DVec3>,
    /// Patches the photo sees whose reflectance is not known.
    seen: Vec<bool>,
}

impl Eq2<'_> {
    /// Loscos Eq. 1 with ρ̂ the mean known reflectance (0.5 when none is
    /// known); zero where unseen.
    fn first_guess(&self) -> Vec<DVec3> {
        let (photo, known) = (self.photo, self.known);
        let rho_hat = if known.is_empty() {
            DVec3::splat(0.5)
        } else {
            known.values().copied().sum::<DVec3>() / known.len() as f64
        };
        let mean = photo.image_mean.max(DVec3::splat(1e-30));
        (0..self.patches.patch_count())
            .map(|k| match known.get(&self.patches.patch(k).surface) {
                Some(r) => *r,
                None if self.seen[k] => (photo.radiance[k] / mean * rho_hat)
                    .clamp(DVec3::ZERO, DVec3::splat(MAX_REFLECTANCE)),
                None => DVec3::ZERO,
            })
            .collect()
    }

    /// The forward solution with reflectances `rho`.
    fn solve(&self, rho: &[DVec3], previous: Option<&[DVec3]>, tolerance: f64) -> Solution {
        let emission: Vec<DVec3> = rho.iter().zip(self.direct).map(|(r, e)| *r * *e).collect();
        solve_from(
            self.patches,
            self.transport,
            rho,
            &emission,
            previous,
            tolerance,
            500,
        )
    }

    /// One round of EQ2 into `next`: each seen patch's reflectance from its
    /// photo radiance over its irradiance (direct, and gathered from
    /// `mixed`: the photo's radiosity where it sees a patch, the model's
    /// elsewhere); `estimated` marks the patches it set. Returns the
    /// patches clamped, and the pinned ones (pixels, raw ρ / clamp).
    fn round(
        &self,
        mixed: &[DVec3],
        next: &mut [DVec3],
        estimated: &mut [bool],
    ) -> (usize, Vec<(u32, f64)>) {
        let (n, photo, direct) = (self.patches.patch_count(), self.photo, self.direct);
        let gathered = self.transport.gather_rgb(self.patches, mixed);
        // A patch must receive light for EQ2 to say anything: a hundred-
        // thousandth of the scene's mean irradiance, per channel.
        let floor = direct.iter().copied().sum::<DVec3>() / n.max(1) as f64 * 1e-5;
        let mut clamped = 0;
        let mut pinned = Vec::new();
        for k in 0..n {
            estimated[k] = false;
            if !self.seen[k] {
                continue;
            }
            let irradiance = direct[k] + gathered[k];
            if irradiance.cmplt(floor.max(DVec3::splat(1e-300))).any() {
                continue;
            }
            let raw = photo.radiance[k] * std::f64::consts::PI / irradiance;
            let r = raw.clamp(DVec3::ZERO, DVec3::splat(MAX_REFLECTANCE));
            if r != raw {
                clamped += 1;
                if raw.max_element() > MAX_REFLECTANCE {
                    pinned.push((photo.pixels[k], raw.max_element() / MAX_REFLECTANCE));
                }
            }
            next[k] = r;
            estimated[k] = true;
        }
        (clamped, pinned)
    }
}

/// The share of the seen pixels on pinned patches, and the pixel-weighted
/// median of their raw ρ / clamp.
fn pinned_median(mut pinned: Vec<(u32, f64)>, seen_pixels: u64) -> (f64, f64) {
    let pinned_pixels: u64 = pinned.iter().map(|p| p.0 as u64).sum();
    pinned.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut below = 0u64;
    let factor = pinned
        .iter()
        .find(|p| {
            below += p.0 as u64;
            2 * below >= pinned_pixels
        })
        .map_or(1.0, |p| p.1);
    (pinned_pixels as f64 / seen_pixels.max(1) as f64, factor)
}

/// Gives every patch that has no estimate (and no known value) the
/// area-weighted mean of its surface's estimated patches, or of all
/// estimated patches when its surface has none.
fn fill_unseen(
    patches: &Patches,
    rho: &mut [DVec3],
    estimated: &[bool],
    known: &HashMap<u32, DVec3>,
) {
    let mut by_surface: HashMap<u32, (DVec3, f64)> = HashMap::new();
    let (mut all, mut all_area) = (DVec3::ZERO, 0.0);
    for k in 0..rho.len() {
        if estimated[k] {
            let el = patches.patch(k);
            let e = by_surface.entry(el.surface).or_insert((DVec3::ZERO, 0.0));
            e.0 += rho[k] * el.area;
            e.1 += el.area;
            all += rho[k] * el.area;
            all_area += el.area;
        }
    }
    let global = if all_area > 0.0 {
        all / all_area
    } else {
        DVec3::splat(0.5)
    };
    for k in 0..rho.len() {
        let s = patches.patch(k).surface;
        if let Some(r) = known.get(&s) {
            rho[k] = *r;
        } else if !estimated[k] {
            rho[k] = match by_surface.get(&s) {
                Some((sum, area)) if *area > 0.0 => *sum / *area,
                _ => global,
            };
        }
    }
}

/// Area-weighted mean reflectance of a surface's patches.
pub fn surface_mean(patches: &Patches, reflectance: &[DVec3], surface: u32) -> Option<DVec3> {
    let (mut sum, mut area) = (DVec3::ZERO, 0.0);
    for (k, r) in reflectance.iter().enumerate().take(patches.patch_count()) {
        let el = patches.patch(k);
        if el.surface == surface {
            sum += *r * el.area;
            area += el.area;
        }
    }
    (area > 0.0).then(|| sum / area)
}
