//! The objects' own pixels: their indirect irradiance gathered at the
//! pixel's point by cosine-distributed rays.

use super::*;
use crate::light::offset_origin;
use crate::object_shading::Reading;
use crate::trace::{Layer, TraceRay};
use crate::util::rng::hash2;

/// Gather rays per object pixel and round.
pub(super) const ROUND_RAYS: u32 = 16;

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
        });
    }
    out
}

/// Round `round` of task `t`'s gather; returns the rays traced.
pub(super) fn sample(input: &ResidualInput, t: &mut Task, round: u32) -> u64 {
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
    rays
}

/// Task `t`'s gathered irradiance, its pixel's estimated noise (radiance)
/// and value (luminance of its diffuse radiance).
pub(super) fn result(input: &ResidualInput, t: &Task) -> (DVec3, f64, f64) {
    let pda = input.pda;
    let p = t.point(pda);
    let rho = (input.shading.reflectance.get(p.location.patch as usize))
        .copied()
        .unwrap_or(DVec3::ZERO);
    let h = t.sums.mean().max(DVec3::ZERO);
    let terms = t.terms(pda);
    let shading = input.shading;
    let mut e = DVec3::ZERO;
    for ((term, light), &s) in terms.iter().zip(shading.lights).zip(shading.scales_with) {
        if s > 0.0 && term.unoccluded > 0.0 {
            e += light.colour() * (s * term.unoccluded as f64 * term.visible(true));
        }
    }
    let pi = std::f64::consts::PI;
    let noise = luminance(rho) / pi * t.sums.deviation();
    (h, noise, luminance(rho * (e + h)) / pi)
}
