//! Real pixels near the objects: the objects' change at the pixel's own
//! point ([`ChangeSampler`]), replacing the near grid's interpolation.

use super::objects::HIT_LEVEL;
use super::*;
use crate::object_shading::Reading;
use crate::trace::Hit;

/// A real pixel near an object and its sums.
pub(super) struct Task {
    pub(super) pixel: u32,
    /// Its real point in the pixel data.
    pub(super) point: u32,
    weight: f64,
    sums: Sums,
}

/// Every pixel held that shows a real point alone within the sampler's
/// reach (none without objects).
pub(super) fn tasks(input: &ResidualInput) -> Vec<Task> {
    let Some(sampler) = input.room else {
        return Vec::new();
    };
    let pda = input.pda;
    let first = pda.first_pixel() as u32;
    let edges: Vec<u32> = pda.edges.iter().map(|e| e.pixel).collect();
    (0..pda.real_index.len() as u32)
        .into_par_iter()
        .filter_map(|slot| {
            let k = pda.real_index[slot as usize];
            let pixel = first + slot;
            if k == u32::MAX
                || pda.virtual_index[slot as usize] != u32::MAX
                || edges.binary_search(&pixel).is_ok()
            {
                return None;
            }
            let p = &pda.real.points[k as usize];
            let weight = sampler.weight(p.location.patch, p.position.as_dvec3());
            (weight > 0.0).then_some(Task {
                pixel,
                point: k,
                weight,
                sums: Sums::default(),
            })
        })
        .collect()
}

/// Round `round` of task `t`; returns the rays traced.
pub(super) fn sample(input: &ResidualInput, t: &mut Task, (round, lamps): (u32, &Lamps)) -> u64 {
    let Some(sampler) = input.room else {
        return 0;
    };
    let p = &input.pda.real.points[t.point as usize];
    let seed = crate::util::rng::hash2(t.pixel as u64, 0xC4A9_6E37);
    let sums = &mut t.sums;
    let x = p.position.as_dvec3();
    sampler.sample(
        p.location.patch,
        x,
        (seed, round),
        &reader(input, round, lamps),
        &mut |v| sums.add(v),
    )
}

/// How the sampler reads what its rays meet: an object's radiance with
/// the objects there, a real surface's without them.
pub(super) fn reader<'a>(
    input: &'a ResidualInput,
    round: u32,
    lamps: &'a Lamps,
) -> impl Fn(&Hit, DVec3, DVec3, u64) -> (DVec3, u64) + 'a {
    let shading = input.shading;
    let lights = shading.lights.len() as u64;
    move |h: &Hit, o: DVec3, d: DVec3, seed: u64| {
        // An object with a material: its radiance towards the point.
        let leaving = || shading.leaving(lamps, h, (o, d), seed, round);
        if let Some(out) = h.is_virtual.then(leaving).flatten() {
            return out;
        }
        let reading = Reading {
            seed,
            level: HIT_LEVEL,
            objects: h.is_virtual,
            seen_at: None,
            extra: DVec3::ZERO,
        };
        // Shadow rays (twice through a real point's room), and the
        // camera's ray to a real point.
        let rays = if h.is_virtual { lights } else { 2 * lights + 1 };
        (shading.arriving_at(h, o, d, reading), rays)
    }
}

/// Task `t`'s correction to its interpolated indirect irradiance (its
/// point's change less the patch means' interpolation, tapered) and its
/// pixel's estimated noise (radiance).
pub(super) fn result(input: &ResidualInput, t: &Task) -> (DVec3, f64) {
    let p = &input.pda.real.points[t.point as usize];
    let weights = p.location.weights.map(f64::from);
    let coarse = coarse_at(input, p.location.patch, weights);
    let rho = (input.shading.reflectance.get(p.location.patch as usize))
        .copied()
        .unwrap_or(DVec3::ZERO);
    let correction = (t.sums.mean() - coarse) * t.weight;
    let noise = luminance(rho) / std::f64::consts::PI * t.sums.deviation() * t.weight;
    (correction, noise)
}

/// The patch means' change to the indirect irradiance, interpolated at
/// the point of room patch `patch` with vertex `weights`.
fn coarse_at(input: &ResidualInput, patch: u32, weights: [f64; 4]) -> DVec3 {
    let vertices = input.shading.patches.patch_vertices[patch as usize];
    (vertices.iter().zip(weights))
        .filter(|(_, w)| *w != 0.0)
        .map(|(&v, w)| input.coarse.get(v as usize).copied().unwrap_or(DVec3::ZERO) * w)
        .sum()
}
