//! The light arriving at a shaded point: direct from each light (MIS for
//! rect lights), reflected from the room, the lamps and the other objects.

use glam::DVec3;

use super::rounds::Split;
use super::*;
use crate::light::{Emitter, offset_origin, segment};
use crate::trace::Hit;

/// Rays through the room per reflected point when its change is measured:
/// the rect lights' shadow rays at grid level 0, one each. A pixel
/// averages 4 or more samples (the rounds' many more), each with its own
/// reflected point: four rays each (level 2) gave the same skill on every
/// `materials` variant (within 0.0005) and cost a 2 m glossy table's
/// update 14% more in the composite, in a room of four lights.
const ROOM_LEVEL: usize = 0;

/// A rect light's emitting rectangle, for rays that may meet it.
pub(super) struct Rect {
    light: usize,
    centre: DVec3,
    u: DVec3,
    v: DVec3,
    normal: DVec3,
    area: f64,
}

impl Rect {
    /// Distance along unit `d` from `o` to the emitting side, if the ray meets it.
    fn hit(&self, o: DVec3, d: DVec3) -> Option<f64> {
        let denom = d.dot(self.normal);
        if denom >= 0.0 || (o - self.centre).dot(self.normal) <= 0.0 {
            return None;
        }
        let t = (self.centre - o).dot(self.normal) / denom;
        let p = o + d * t - self.centre;
        let (s, r) = (
            p.dot(self.u) / self.u.length_squared(),
            p.dot(self.v) / self.v.length_squared(),
        );
        (t > 0.0 && s.abs() <= 0.5 && r.abs() <= 0.5).then_some(t)
    }

    /// Solid-angle pdf of a point drawn uniformly on the rectangle seen along `d` at `t`.
    fn pdf(&self, d: DVec3, t: f64) -> f64 {
        let cos = -d.dot(self.normal);
        if cos <= 0.0 {
            0.0
        } else {
            t * t / (self.area * cos)
        }
    }
}

impl ObjectShading<'_> {
    pub(super) fn rects(&self) -> Vec<Rect> {
        self.lights
            .iter()
            .enumerate()
            .filter(|(l, _)| self.scales_with[*l] > 0.0)
            .filter_map(|(l, light)| match light.emitter {
                Emitter::Rect { u, v, normal } => Some(Rect {
                    light: l,
                    centre: light.position,
                    u,
                    v,
                    normal,
                    area: u.cross(v).length(),
                }),
                Emitter::Point => None,
            })
            .collect()
    }

    /// Radiance of light `l` leaving its rectangle towards -`d` (scaled).
    fn emitted(&self, l: usize, d: DVec3, area: f64, normal: DVec3) -> DVec3 {
        let cos = -d.dot(normal);
        if cos <= 0.0 {
            return DVec3::ZERO;
        }
        self.lights[l].intensity(-d) * (self.scales_with[l] / (area * cos))
    }

    /// How many samples a point of these lobes draws for `share` of a
    /// pixel: most at the roughness whose lobe is both wide and peaked
    /// (0.5), fewer for mirrors and matte surfaces, half for dielectrics
    /// (their lobe carries 4-10% of the light); the rect lights' area
    /// samples set a floor; rounded up to a power of two.
    pub(super) fn sample_count(&self, lobes: &Lobes, share: f64) -> u32 {
        let r = lobes.roughness;
        let most = self.settings.specular_rays as f64;
        let need = (4.0 + 4.0 * (most - 4.0) * r * (1.0 - r)) * (0.5 + 0.5 * lobes.metallic);
        let need = need.max(self.settings.light_samples as f64);
        // A power of two: Owen-scrambled Sobol points are balanced there
        // (a rough metal's 24 left its highlights noisier than 32 did).
        ((need * share).round() as u32).max(4).next_power_of_two()
    }

    /// One sample of the light leaving point `p` towards the camera: its
    /// emission, each light once (rect lights by one area sample, weighted
    /// against the specular sampler), one specular ray; and the diffuse
    /// part's factor, which the indirect irradiance gathered there (the
    /// same for every sample of a pixel) multiplies once it is known.
    pub(super) fn split_sample(&self, p: &Point, rects: &[Rect], s: Sample) -> Split {
        let (base, reflected, diffuse) = self.sample_parts(p, rects, s);
        Split {
            own: base + reflected.0.value(self),
            diffuse,
        }
    }

    /// A sample's parts: emission plus direct light, what its lobe's ray
    /// met (with where that ray ended) and the diffuse part's factor.
    /// Their sum is [`ObjectShading::split_sample`]'s, summed alike.
    pub(super) fn sample_parts(
        &self,
        p: &Point,
        rects: &[Rect],
        s: Sample,
    ) -> (DVec3, (Reflected, DVec3), DVec3) {
        let n_dot_v = p.n.dot(p.v);
        if n_dot_v <= 0.0 {
            // One-sided (glTF): a shading normal turned from the viewer reflects nothing.
            return (
                p.emissive,
                (Reflected::Fixed(DVec3::ZERO), p.x),
                DVec3::ZERO,
            );
        }
        (
            p.emissive + self.direct(p, rects, s),
            self.reflected(p, rects, s),
            p.lobes.diffuse_mean(n_dot_v),
        )
    }

    /// Direct light through the BRDF: point lights by a shadow ray, rect
    /// lights by one area sample, weighted against the specular sampler
    /// (balance heuristic).
    fn direct(&self, p: &Point, rects: &[Rect], s: Sample) -> DVec3 {
        let mut out = DVec3::ZERO;
        for (l, light) in self.lights.iter().enumerate() {
            let scale = self.scales_with[l];
            if scale <= 0.0 {
                continue;
            }
            let y = match &light.grid {
                Some(_) => light.point_at(s.sobol.light(l)),
                None => light.position,
            };
            let to = y - p.x;
            let dist2 = to.length_squared();
            let d = to / dist2.sqrt();
            let (fd, fs) = p.lobes.eval(p.n, p.v, d);
            if fd + fs == DVec3::ZERO {
                continue;
            }
            let radiance = match rects.iter().find(|r| r.light == l) {
                Some(rect) => {
                    let pdf_l = rect.pdf(d, dist2.sqrt());
                    if pdf_l <= 0.0 {
                        continue;
                    }
                    let pdf_b = p.lobes.specular_pdf(p.n, p.v, d);
                    self.emitted(l, d, rect.area, rect.normal) / (pdf_l + pdf_b)
                }
                None => light.intensity(-d) * (scale / dist2),
            };
            if self.unblocked(p, y) {
                out += (fd + fs) * p.n.dot(d) * radiance;
            }
        }
        out
    }

    /// Whether nothing (real or virtual) lies between the point and `y`.
    fn unblocked(&self, p: &Point, y: DVec3) -> bool {
        let o = offset_origin(p.shadow_origin, p.ng, y);
        !self.tracer.occluded(&segment(o, y), Layer::All)
    }

    /// One ray drawn from the specular lobe: what it meets of the room,
    /// the lamps (weighted against their area samples) and the objects;
    /// and where the ray ended (far off where it met nothing).
    fn reflected(&self, p: &Point, rects: &[Rect], s: Sample) -> (Reflected, DVec3) {
        let [u1, u2] = s.sobol.lobe;
        let Some((d, pdf_b, weight)) = p.lobes.sample_specular(p.n, p.v, u1, u2) else {
            return (Reflected::Fixed(DVec3::ZERO), p.x);
        };
        let o = offset_origin(p.shadow_origin, p.ng, p.x + d);
        let ray = TraceRay::new(o.as_vec3(), d.as_vec3());
        let hit = self.tracer.intersect(&ray, Layer::All);
        let t_geo = hit.map_or(f64::INFINITY, |h| h.t as f64);
        let lamp = rects
            .iter()
            .filter_map(|r| r.hit(o, d).map(|t| (r, t)))
            .filter(|(_, t)| *t < t_geo)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((rect, t)) = lamp {
            let (fd, fs) = p.lobes.eval(p.n, p.v, d);
            let le = self.emitted(rect.light, d, rect.area, rect.normal);
            let value = (fd + fs) * p.n.dot(d) * le / (rect.pdf(d, t) + pdf_b);
            return (Reflected::Fixed(value), o + d * t);
        }
        match hit {
            Some(h) => {
                let reading = Reading::with_objects(hash2(s.seed, s.j as u64), ROOM_LEVEL);
                let end = o + d * h.t as f64;
                match self.measure(&h, o, d, reading) {
                    Some((m, _)) => (Reflected::Read(m.scaled(weight)), end),
                    None => (Reflected::Fixed(weight * DVec3::ZERO), end),
                }
            }
            None => (Reflected::Fixed(DVec3::ZERO), o + d * FAR),
        }
    }

    /// What shows through a point an alpha mask cuts away, along unit `d`
    /// from `x`: the next surface that is not cut away, as a reflection sees it.
    pub(super) fn behind(&self, x: DVec3, d: DVec3, seed: u64) -> DVec3 {
        let mut from = x;
        for _ in 0..16 {
            let o = from + d * crate::light::origin_lift(from) * 4.0;
            let Some(h) = self
                .tracer
                .intersect(&TraceRay::new(o.as_vec3(), d.as_vec3()), Layer::All)
            else {
                return DVec3::ZERO;
            };
            let y = o + d * h.t as f64;
            let masked = self
                .materials
                .surfaces
                .get(&h.surface)
                .is_some_and(|s| self.point(s, h.triangle, y, d, 0.0).is_none());
            if !masked {
                return self.arriving(&h, o, d, seed);
            }
            from = y;
        }
        DVec3::ZERO
    }

    /// Radiance arriving along `d` from the surface `h` (from origin `o`).
    fn arriving(&self, h: &Hit, o: DVec3, d: DVec3, seed: u64) -> DVec3 {
        self.arriving_at(h, o, d, Reading::with_objects(seed, ROOM_LEVEL))
    }

    /// [`ObjectShading::arriving_at`]: what is measured at the point met,
    /// then read against the solution's indirect light.
    pub(crate) fn arriving_at(&self, h: &Hit, o: DVec3, d: DVec3, reading: Reading) -> DVec3 {
        self.measure(h, o, d, reading)
            .map_or(DVec3::ZERO, |(m, extra)| m.radiance_plus(self, extra))
    }

    /// [`ObjectShading::arriving`] as `reading` says: 2^level shadow rays
    /// per rect light at the point met (a gather that averages many rays
    /// takes one), and whether the objects are there (the light a real
    /// point would send without them: what an object hides).
    fn measure(&self, h: &Hit, o: DVec3, d: DVec3, reading: Reading) -> Option<(Measured, DVec3)> {
        let Reading {
            seed,
            level,
            objects,
            seen_at,
            extra,
        } = reading;
        let y = o + d * h.t as f64;
        // The change is traced here rather than read from the Pixel Data
        // Array's terms at y's pixel: those exist only inside a crop, and
        // a tile must equal the whole frame bit for bit.
        let at = self.patches.locate(h.surface, h.triangle, y)?;
        let mut n = h.normal.as_dvec3().normalize_or_zero();
        if n.dot(d) > 0.0 {
            n = -n;
        }
        let rho = self
            .reflectance
            .get(at.patch as usize)
            .copied()
            .unwrap_or(DVec3::ZERO);
        let (mut e_with, mut e_without) = (DVec3::ZERO, DVec3::ZERO);
        for (l, light) in self.lights.iter().enumerate() {
            let (sw, swo) = (self.scales_with[l], self.scales_without[l]);
            if sw <= 0.0 && (swo <= 0.0 || h.is_virtual) {
                continue;
            }
            let seed = hash2(seed, l as u64);
            // The room's rays once: those it lets through are then traced
            // through the objects alone; the room's own blockers weigh what
            // the photo's light was there.
            let (mut targets, mut real_blocked) = (Vec::new(), Vec::new());
            let all = light.direct_by(y, n, level, seed, |at, rays, blocked| {
                self.tracer.occluded_batch(rays, Layer::Real, blocked);
                (targets, real_blocked) = (at.to_vec(), blocked.to_vec());
                for (ray, b) in rays.iter().zip(blocked.iter_mut()).filter(|_| objects) {
                    *b = *b || self.tracer.occluded(ray, Layer::Virtual);
                }
            });
            e_with += all.unoccluded * (sw * all.visibility);
            if !h.is_virtual && swo > 0.0 && all.rays > 0 {
                let real = light.visibility_of(y, n, &targets, &real_blocked);
                e_without += all.unoccluded * (swo * real);
            }
        }
        let photo = match (h.is_virtual, seen_at) {
            (true, _) => None,
            (false, Some((px, py))) => Some(self.photo.bilinear(px, py)),
            (false, None) => {
                crate::gather::photo_radiance_at(self.camera, self.tracer, self.photo, y)
            }
        };
        let without = match photo {
            Some(_) => e_without + self.patches.interpolate(self.indirect_without, &at),
            None => DVec3::ZERO,
        };
        let (p, q) = affine(photo, e_with, without, rho);
        let measured = Measured {
            p: single(p),
            q: single(q),
            patch: at.patch,
            weights: at.weights.map(|(_, w)| w as f32),
            is_virtual: h.is_virtual,
            surface: h.surface,
        };
        Some((measured, extra))
    }
}

/// Far along a ray that met nothing: where it is taken to end.
const FAR: f64 = 1e4;

/// What a sample's lobe ray met: a radiance fixed by the geometry (a
/// lamp, nothing), or a point whose light reads the solution (its
/// measures scaled by the lobe's weight).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Reflected {
    Fixed(DVec3),
    Read(Measured),
}

impl Reflected {
    pub(crate) fn value(&self, shading: &ObjectShading) -> DVec3 {
        match self {
            Reflected::Fixed(v) => *v,
            Reflected::Read(m) => m.radiance(shading),
        }
    }
}

/// What [`ObjectShading::arriving_at`] measures at the point met before
/// it reads the indirect light there: all that rays decide (where, the
/// lights' direct light with and without the objects, the photo there),
/// as the radiance it sends back, max(p + q·I, 0) per channel, for I the
/// indirect irradiance there with the changes. Stored in single precision
/// (a session keeps one per sample: [`super::kept`]); shading anew reads
/// the same numbers, so a kept sample gives what a fresh one does.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Measured {
    p: glam::Vec3,
    q: glam::Vec3,
    patch: u32,
    /// Interpolation weights on the patch's vertices.
    weights: [f32; 4],
    pub is_virtual: bool,
    pub surface: u32,
}

impl Measured {
    /// The part of its radiance the rays fixed, whatever the solution.
    pub(crate) fn fixed(&self) -> DVec3 {
        self.p.as_dvec3().max(DVec3::ZERO)
    }

    /// The radiance the point sends back, over the solution `shading` holds.
    pub(crate) fn radiance(&self, shading: &ObjectShading) -> DVec3 {
        self.radiance_plus(shading, DVec3::ZERO)
    }

    /// [`Measured::radiance`] with `extra` indirect irradiance added there.
    fn radiance_plus(&self, shading: &ObjectShading, extra: DVec3) -> DVec3 {
        let ids = shading.patches.patch_vertices[self.patch as usize];
        let mut i = extra;
        for (&v, &w) in ids.iter().zip(&self.weights).filter(|(_, w)| **w != 0.0) {
            i += shading
                .indirect_with
                .get(v as usize)
                .copied()
                .unwrap_or(DVec3::ZERO)
                * w as f64;
        }
        (self.p.as_dvec3() + self.q.as_dvec3() * i).max(DVec3::ZERO)
    }

    /// Scaled by the lobe's `weight` (not negative).
    fn scaled(self, weight: DVec3) -> Measured {
        Measured {
            p: single(self.p.as_dvec3() * weight),
            q: single(self.q.as_dvec3() * weight),
            ..self
        }
    }
}

/// `v` in single precision, held within ±1e30: a photo's pixel over a
/// light without the objects of 1e-36 (what the ratio's threshold admits)
/// would pass f32's range, and an infinite factor times no light is NaN.
fn single(v: DVec3) -> glam::Vec3 {
    v.clamp(DVec3::splat(-1e30), DVec3::splat(1e30)).as_vec3()
}

/// The radiance a point sends back as p + q·I per channel, I its indirect
/// irradiance with the changes, `e_with` its direct light with them: a
/// real point the camera sees, its `photo` changed as the compositor
/// changes it (× with ÷ `without`, or, without ≈ 0, plus ρ·Δ/π); any
/// other point its radiosity, ρ·with/π.
fn affine(photo: Option<DVec3>, e_with: DVec3, without: DVec3, rho: DVec3) -> (DVec3, DVec3) {
    let pi = std::f64::consts::PI;
    let Some(photo) = photo else {
        return (rho * e_with / pi, rho / pi);
    };
    let (mut p, mut q) = (DVec3::ZERO, DVec3::ZERO);
    for c in 0..3 {
        if without[c] > 1e-6 * without.max_element().max(1e-30) {
            q[c] = photo[c] / without[c];
            p[c] = q[c] * e_with[c];
        } else {
            q[c] = rho[c] / pi;
            p[c] = photo[c] + q[c] * (e_with[c] - without[c]);
        }
    }
    (p, q)
}

/// How [`ObjectShading::arriving_at`] reads a point.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Reading {
    pub seed: u64,
    pub level: usize,
    /// Whether the objects shadow the point.
    pub objects: bool,
    /// Where the camera sees the point, when the ray came from it: the
    /// photo there, between pixels.
    pub seen_at: Option<(f64, f64)>,
    /// Indirect irradiance to add to the interpolated one (a correction
    /// estimated at the point).
    pub extra: DVec3,
}

impl Reading {
    pub(crate) fn with_objects(seed: u64, level: usize) -> Reading {
        Reading {
            seed,
            level,
            objects: true,
            seen_at: None,
            extra: DVec3::ZERO,
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    /// A real point the photo shows lit where the model has nearly no
    /// light without the objects: its factor passes single precision's
    /// range, and must not come back infinite, nor NaN where no indirect
    /// light arrives.
    #[test]
    fn a_point_nearly_dark_without_the_objects_sends_back_finite_light() {
        let without = DVec3::splat(1e-35);
        let (p, q) = super::affine(Some(DVec3::splat(1e4)), DVec3::ZERO, without, DVec3::ONE);
        let (p, q) = (super::single(p), super::single(q));
        assert!(p.is_finite() && q.is_finite(), "{p} {q}");
        for i in [0.0, 1e-6, 10.0] {
            let v = (p.as_dvec3() + q.as_dvec3() * i).max(DVec3::ZERO);
            assert!(v.is_finite() && v.min_element() >= 0.0, "{i}: {v}");
        }
    }
}
