//! Pixels along an object's outline: how much of each pixel the objects,
//! the room and nothing cover, from jittered camera rays over rounds. The
//! pixel data's n×n sub-pixels shade each part; their count alone sets
//! the parts' shares to within 1/n², which against a bright background
//! (a wall by a lamp) is most of such a pixel's error. The room's part is
//! shaded at each ray's own point too (the photo there, between pixels,
//! changed by the light that point gets): a shadow's edge or the dark of
//! an object's base crosses it, which the sub-pixels read at the pixel's
//! centre.

use super::objects::HIT_LEVEL;
use super::room;
use super::*;
use crate::object_shading::Reading;
use crate::trace::{Hit, Layer};
use crate::util::rng::hash2;

/// Camera rays per outline pixel and round.
pub(super) const ROUND_SUBPIXELS: u32 = 8;

/// An outline pixel and its counts.
pub(super) struct Task {
    /// Its place in the pixel data's edges.
    pub(super) edge: u32,
    pub(super) pixel: u32,
    /// Rays that met an object, a real surface, nothing.
    counts: [u32; 3],
    /// The radiance of the real surfaces met, summed.
    room: DVec3,
}

/// Every outline pixel held.
pub(super) fn tasks(input: &ResidualInput) -> Vec<Task> {
    (input.pda.edges.iter().enumerate())
        .map(|(k, e)| Task {
            edge: k as u32,
            pixel: e.pixel,
            counts: [0; 3],
            room: DVec3::ZERO,
        })
        .collect()
}

/// Round `round` of task `t`; returns the rays traced.
pub(super) fn sample(input: &ResidualInput, t: &mut Task, (round, lamps): (u32, &Lamps)) -> u64 {
    let shading = input.shading;
    let key = hash2(t.pixel as u64, 0xED6E_5A3B);
    let mut rays = 0;
    for sub in subpixels(input, t.pixel, key, round, ROUND_SUBPIXELS) {
        let SubPixel {
            index,
            at,
            ray,
            traced,
        } = sub;
        rays += 1;
        let part = match shading.tracer.intersect(&traced, Layer::All) {
            Some(h) if h.is_virtual => 0,
            Some(h) => {
                let y = ray.origin + ray.direction * h.t as f64;
                let seed = hash2(key, index as u64);
                let (extra, traced) = near_change(input, &h, y, (seed, round), lamps);
                let reading = Reading {
                    seed,
                    level: HIT_LEVEL,
                    objects: true,
                    seen_at: Some(at),
                    extra,
                };
                t.room += shading.arriving_at(&h, ray.origin, ray.direction, reading);
                rays += shading.lights.len() as u64 + traced;
                1
            }
            None => 2,
        };
        t.counts[part] += 1;
    }
    rays
}

/// Task `t`'s shares of the pixel (objects, room, nothing), counting the
/// pixel data's sub-pixels with the rays, and the shares' standard
/// deviation (of the objects' share).
pub(super) fn result(input: &ResidualInput, t: &Task) -> Shares {
    let pda = input.pda;
    let e = &pda.edges[t.edge as usize];
    let total = (pda.supersample * pda.supersample) as f64;
    let samples = &pda.edge_samples.points[e.start as usize..(e.start + e.count) as usize];
    let objects = samples.iter().filter(|p| p.is_virtual).count() as f64;
    let grid = [objects, e.count as f64 - objects, total - e.count as f64];
    let rays: u32 = t.counts.iter().sum();
    let n = total + rays as f64;
    let shares = [0, 1, 2].map(|c| ((grid[c] + t.counts[c] as f64) / n) as f32);
    let f = shares[0] as f64;
    let room = (t.counts[1] > 0).then(|| t.room / t.counts[1] as f64);
    Shares {
        shares,
        room: room
            .filter(|r| r.is_finite())
            .map(|r| r.max(DVec3::ZERO).as_vec3()),
        deviation: (f * (1.0 - f) / n).sqrt(),
    }
}

/// What the rounds found of an outline pixel.
pub(super) struct Shares {
    pub(super) shares: [f32; 3],
    /// The mean radiance of the room's part (None: no ray met it).
    pub(super) room: Option<Vec3>,
    /// The standard deviation of the objects' share.
    pub(super) deviation: f64,
}

/// The objects' change to the indirect light at real point `y` (hit `h`)
/// less what the patch means give, as the room's pixels near them take it
/// ([`super::room`]), from one round of the sampler's rays; and the rays.
fn near_change(
    input: &ResidualInput,
    h: &Hit,
    y: DVec3,
    key: (u64, u32),
    lamps: &Lamps,
) -> (DVec3, u64) {
    let Some(sampler) = input.room else {
        return (DVec3::ZERO, 0);
    };
    let Some(at) = input.shading.patches.locate(h.surface, h.triangle, y) else {
        return (DVec3::ZERO, 0);
    };
    let weight = sampler.weight(at.patch, y);
    if weight == 0.0 {
        return (DVec3::ZERO, 0);
    }
    let mut sums = Sums::default();
    let rays = sampler.sample(
        at.patch,
        y,
        key,
        &room::reader(input, key.1, lamps),
        &mut |v| sums.add(v),
    );
    let coarse: DVec3 = (at.weights.iter())
        .filter(|(_, w)| *w != 0.0)
        .map(|&(v, w)| input.coarse.get(v as usize).copied().unwrap_or(DVec3::ZERO) * w)
        .sum();
    ((sums.mean() - coarse) * weight, rays)
}
