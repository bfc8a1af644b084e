//! The objects' own pixels: their indirect irradiance gathered at the
//! pixel's point by cosine-distributed rays, and where the object has a
//! material, its radiance sampled over the pixel (the object shading's
//! `footprint_sample`).

use super::*;
use crate::light::offset_origin;
use crate::object_shading::{Footprint, Reading};
use crate::trace::{Layer, TraceRay};
use crate::util::rng::hash2;

/// Gather rays per object pixel and round.
pub(super) const ROUND_RAYS: u32 = 16;

/// Most samples of a material's radiance per pixel and round: each round
/// draws as many as a pixel does without rounds (4-24, by its lobes), so
/// that 4 rounds draw more than an outline's 16 sub-pixels of 4 each.
/// The Sobol sequences' indices stay below 2^16 over 1,024 rounds.
const ROUND_FOOTPRINT_MAX: u32 = 64;

/// Shadow rays per rect light at a point a gather ray meets: one (2^0),
/// since a pixel averages many rays.
pub(super) const HIT_LEVEL: usize = 0;

/// Where an object pixel's point is in the pixel data.
#[derive(Debug, Clone, Copy)]
pub(super) enum Source {
    /// A plain object pixel's virtual sample.
    Plain(u32),
    /// An outline pixel (its place in `edges`) and its first sub-pixel on
    /// an object, whose gather stands for all of them (a pixel apart).
    Edge(u32, u32),
}

/// An object pixel and its sums.
pub(super) struct Task {
    pub(super) pixel: u32,
    pub(super) source: Source,
    sums: Sums,
    /// The material's samples over the pixel (pixels whose surface has
    /// one): their own light, the sum of their diffuse factors, and how
    /// many a round draws (0: not known yet).
    radiance: Option<(Sums, DVec3, u32)>,
}

impl Task {
    fn point<'a>(&self, pda: &'a crate::pda::PixelDataArray) -> &'a crate::pda::SurfacePoint {
        match self.source {
            Source::Plain(k) => &pda.virtual_samples.points[k as usize],
            Source::Edge(_, k) => &pda.edge_samples.points[k as usize],
        }
    }

    /// The point's light terms.
    fn terms<'a>(&self, pda: &'a crate::pda::PixelDataArray) -> &'a [crate::pda::LightTerm] {
        let (terms, k) = match self.source {
            Source::Plain(k) => (&pda.virtual_samples.terms, k as usize),
            Source::Edge(_, k) => (&pda.edge_samples.terms, k as usize),
        };
        &terms[k * pda.light_count..(k + 1) * pda.light_count]
    }
}

/// Every pixel held that shows an object: alone, or along its outline.
pub(super) fn tasks(input: &ResidualInput) -> Vec<Task> {
    let pda = input.pda;
    let mut edges = pda.edges.iter().map(|e| e.pixel).peekable();
    let first = pda.first_pixel() as u32;
    let mut out: Vec<Task> = (pda.edges.iter().enumerate())
        .filter_map(|(k, e)| {
            let sub = (e.start..e.start + e.count)
                .find(|&j| pda.edge_samples.points[j as usize].is_virtual)?;
            Some(Task {
                pixel: e.pixel,
                source: Source::Edge(k as u32, sub),
                sums: Sums::default(),
                radiance: (input.shading.materials)
                    .has(pda.edge_samples.points[sub as usize].surface)
                    .then_some((Sums::default(), DVec3::ZERO, 0)),
            })
        })
        .collect();
    for slot in 0..pda.virtual_index.len() as u32 {
        let pixel = first + slot;
        let k = pda.virtual_index[slot as usize];
        while edges.peek().is_some_and(|&e| e < pixel) {
            edges.next();
        }
        if k == u32::MAX || edges.peek() == Some(&pixel) {
            continue;
        }
        out.push(Task {
            pixel,
            source: Source::Plain(k),
            sums: Sums::default(),
            radiance: (input.shading.materials)
                .has(pda.virtual_samples.points[k as usize].surface)
                .then_some((Sums::default(), DVec3::ZERO, 0)),
        });
    }
    out
}

/// Round `round` of task `t`'s gather; returns the rays traced.
pub(super) fn sample(input: &ResidualInput, t: &mut Task, (round, lamps): (u32, &Lamps)) -> u64 {
    let shading = input.shading;
    let p = t.point(input.pda);
    let (x, n) = (p.position.as_dvec3(), p.normal.as_dvec3());
    let o = offset_origin(x, n, x + n);
    let key = hash2(t.pixel as u64, 0x6A7E_0B1E);
    let mut rays = 0;
    for j in 0..ROUND_RAYS {
        let index = round * ROUND_RAYS + j;
        let [u1, u2, _, _] = sobol_burley::sample_4d(index, 0, key as u32).map(f64::from);
        let d = crate::radiosity::cosine_direction(n, u1, u2);
        let ray = TraceRay::new(o.as_vec3(), d.as_vec3());
        rays += 1;
        let l = match shading.tracer.intersect(&ray, Layer::All) {
            Some(h) => {
                rays += 1 + shading.lights.len() as u64;
                shading.arriving_at(
                    &h,
                    o,
                    d,
                    Reading::with_objects(hash2(key, index as u64), HIT_LEVEL),
                )
            }
            None => DVec3::ZERO,
        };
        // Cosine-distributed rays: irradiance = π × mean radiance.
        t.sums.add(l * std::f64::consts::PI);
    }
    rays + sample_radiance(input, t, round, lamps)
}

/// Round `round` of a material's samples over task `t`'s pixel; returns
/// the rays traced.
fn sample_radiance(input: &ResidualInput, t: &mut Task, round: u32, lamps: &Lamps) -> u64 {
    let p = *t.point(input.pda);
    // A plain pixel is the object's throughout; an outline's other part is
    // the room's or nothing's, which the edges' rounds measure.
    let centre = matches!(t.source, Source::Plain(_)).then_some(&p);
    let Some((own, diffuse, per_round)) = &mut t.radiance else {
        return 0;
    };
    let mut rays = 0;
    if *per_round == 0 {
        rays += 1;
        match input.shading.samples_per_pixel(&p) {
            Some(n) => *per_round = n.clamp(1, ROUND_FOOTPRINT_MAX),
            None => {
                t.radiance = None;
                return rays;
            }
        }
    }
    let width = input.pda.width;
    let corner = ((t.pixel % width) as f64, (t.pixel / width) as f64);
    let key = hash2(t.pixel as u64, 0xF007_9817) as u32;
    let per_round = *per_round;
    for j in 0..per_round {
        let index = round * per_round + j;
        let (found, n) = (input.shading).footprint_sample(lamps, centre, corner, index, key);
        rays += n;
        match found {
            Footprint::Shaded(split) => {
                own.add(split.own);
                *diffuse += split.diffuse;
            }
            Footprint::Elsewhere => {}
            Footprint::Unsampled => {
                t.radiance = None;
                return rays;
            }
        }
    }
    rays
}

/// Task `t`'s radiance from its samples, given its gathered irradiance `h`,
/// and that radiance's estimated noise (None: not sampled).
fn radiance(t: &Task, h: DVec3, h_deviation: f64) -> Option<(DVec3, f64)> {
    let (own, diffuse, _) = t.radiance.as_ref().filter(|(own, ..)| own.rays > 0)?;
    let n = own.rays as f64;
    let factor = *diffuse / (n * std::f64::consts::PI);
    let value = (own.mean() + factor * h).max(DVec3::ZERO);
    Some((
        value,
        own.deviation().hypot(luminance(factor) * h_deviation),
    ))
}

/// What a task's rounds found.
pub(super) struct Found {
    /// The gathered indirect irradiance.
    pub(super) irradiance: DVec3,
    /// The material's radiance sampled over the pixel (None: not sampled).
    pub(super) radiance: Option<DVec3>,
    /// The pixel's estimated noise (radiance).
    pub(super) noise: f64,
    /// The luminance of its radiance (diffuse, where not sampled).
    pub(super) value: f64,
}

/// Task `t`'s findings.
pub(super) fn result(input: &ResidualInput, t: &Task) -> Found {
    let pda = input.pda;
    let p = t.point(pda);
    let rho = (input.shading.reflectance.get(p.location.patch as usize))
        .copied()
        .unwrap_or(DVec3::ZERO);
    let h = t.sums.mean().max(DVec3::ZERO);
    if let Some((value, noise)) = radiance(t, h, t.sums.deviation()) {
        return Found {
            irradiance: h,
            radiance: Some(value),
            noise,
            value: luminance(value),
        };
    }
    let terms = t.terms(pda);
    let shading = input.shading;
    let mut e = DVec3::ZERO;
    for ((term, light), &s) in terms.iter().zip(shading.lights).zip(shading.scales_with) {
        if s > 0.0 && term.unoccluded > 0.0 {
            e += light.colour() * (s * term.unoccluded as f64 * term.visible(true));
        }
    }
    let pi = std::f64::consts::PI;
    Found {
        irradiance: h,
        radiance: None,
        noise: luminance(rho) / pi * t.sums.deviation(),
        value: luminance(rho * (e + h)) / pi,
    }
}
