//! Lamps in view. A rect light's emitting face is seen in the photo (the
//! contract: an emitter is part of the photographed room), but it is not
//! geometry: the camera ray through such a pixel meets the wall behind it.
//! Left alone, the lamp's radiance would be taken for that wall's (its
//! reflectance estimated from a light source, a virtual object's gathered
//! light reading the lamp a second time) and would follow the wall's change
//! instead of the lamp's own scale.
//!
//! So, once per render: the pixels whose sub-pixel rays meet a lamp's
//! rectangle before any real surface are found analytically (only within
//! the lamp's projected box: nothing is done for a scene whose lamps are
//! out of view); the photo the stages read has them filled from the
//! surfaces around them; and after compositing, each such pixel is the
//! rendered background over the share the lamp leaves uncovered, plus the
//! lamp's emitted radiance times its scale over the share its front face
//! covers (its back is the black body), less what a virtual object in
//! front hides. The emitted radiance is the photo's own where a pixel is
//! all lamp, elsewhere the light's model calibrated on those pixels.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::composite::Composite;
use crate::image_io::Image;
use crate::light::{Emitter, LightSource};
use crate::trace::{Layer, TraceRay, Tracer};

/// One sub-pixel ray that meets a lamp before any real surface.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LampSample {
    /// Index into the lights.
    light: u16,
    /// Distance along the ray to the lamp.
    t: f32,
    /// The camera ray's unit direction.
    dir: Vec3,
    /// Radiance emitted towards the camera at scale 1 (zero for the back).
    emitted: Vec3,
}

/// A pixel that sees a lamp: its samples are `samples[start..start + count]`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LampPixel {
    index: u32,
    start: u32,
    count: u32,
}

/// The pixels that see a lamp, found once per render.
#[derive(Debug, Clone, PartialEq)]
pub struct LampPixels {
    /// The camera's centre, where every sample's ray starts.
    origin: Vec3,
    /// Sub-pixels per pixel (n × n).
    per_pixel: u32,
    pixels: Vec<LampPixel>,
    samples: Vec<LampSample>,
    /// Per light: whether it is in the photo.
    real: Vec<bool>,
}

/// The rectangle's parameters (a, b) of the point `p` in its plane, from
/// its centre along u and v (the rectangle is |a|, |b| ≤ ½), for u and v at
/// any angle.
fn rect_coordinates(p: DVec3, centre: DVec3, u: DVec3, v: DVec3) -> (f64, f64) {
    let d = p - centre;
    let (uu, uv, vv) = (u.dot(u), u.dot(v), v.dot(v));
    let (du, dv) = (d.dot(u), d.dot(v));
    let det = uu * vv - uv * uv;
    ((du * vv - dv * uv) / det, (dv * uu - du * uv) / det)
}

/// Where the ray meets the light's rectangle: distance and whether it
/// meets the emitting face.
fn meet(light: &LightSource, origin: DVec3, dir: DVec3) -> Option<(f64, bool)> {
    let Emitter::Rect { u, v, normal } = light.emitter else {
        return None;
    };
    let denom = dir.dot(normal);
    if denom.abs() < 1e-12 {
        return None;
    }
    let t = (light.position - origin).dot(normal) / denom;
    if t <= 0.0 || !t.is_finite() {
        return None;
    }
    let (a, b) = rect_coordinates(origin + dir * t, light.position, u, v);
    (a.abs() <= 0.5 && b.abs() <= 0.5).then_some((t, denom < 0.0))
}

/// The pixel box the light's rectangle projects into (the whole image when
/// part of it lies behind the camera), or `None` when it is out of view.
fn pixel_box(camera: &Camera, light: &LightSource) -> Option<(u32, u32, u32, u32)> {
    let corners = light.rect_corners()?;
    let (w, h) = (camera.width as f64, camera.height as f64);
    let Some(projected) = camera.project_hull(&corners) else {
        return Some((0, camera.width, 0, camera.height));
    };
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y) in projected {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let (x0, y0) = ((x0.floor() - 1.0).max(0.0), (y0.floor() - 1.0).max(0.0));
    let (x1, y1) = ((x1.ceil() + 1.0).min(w), (y1.ceil() + 1.0).min(h));
    (x0 < x1 && y0 < y1).then_some((x0 as u32, x1 as u32, y0 as u32, y1 as u32))
}

/// Radiance the light emits towards the camera along `dir` (from the
/// camera), at scale 1: its intensity over its projected area.
fn model_radiance(light: &LightSource, dir: DVec3) -> DVec3 {
    let Emitter::Rect { u, v, normal } = light.emitter else {
        return DVec3::ZERO;
    };
    let cos = dir.dot(normal).abs().max(1e-6);
    light.intensity(-dir) / (u.cross(v).length() * cos)
}

/// How far, in pixels, [`LampPixels::photo_without_lamps`] looks for the
/// surface around a lamp: beyond the ring of pixels at the lamp's outline,
/// which on a lamp seen edge-on may all lie in the lamp's own hot spot.
pub const FILL_REACH: i64 = 3;

/// Sub-pixels per side sampled for a lamp's coverage of a pixel, as a
/// multiple of the edge supersampling: a lamp is thousands of times
/// brighter than the wall beside it, so the share of a pixel it covers
/// must be known to a fraction of a percent (a thin lamp seen at a grazing
/// angle covers slivers of pixels that 4×4 rays miss altogether). The
/// pixels are few, and each ray meets the rectangle analytically.
pub const LAMP_SUPERSAMPLE_FACTOR: u32 = 4;

impl LampPixels {
    /// The pixels of `camera`'s image whose n×n sub-pixel rays meet a rect
    /// light (a real one, or a virtual one switched on) before any real
    /// surface; `None` when no lamp is in view.
    pub fn find(camera: &Camera, lights: &[LightSource], tracer: &Tracer, n: u32) -> Option<Self> {
        let shown = |l: &LightSource| l.real || l.is_on();
        let mut boxes: Vec<(usize, (u32, u32, u32, u32))> = lights
            .iter()
            .enumerate()
            .filter(|(_, l)| shown(l))
            .filter_map(|(i, l)| pixel_box(camera, l).map(|b| (i, b)))
            .collect();
        if boxes.is_empty() {
            return None;
        }
        boxes.sort_by_key(|(_, b)| (b.2, b.0));
        let mut candidates: Vec<u32> = boxes
            .iter()
            .flat_map(|&(_, (x0, x1, y0, y1))| {
                (y0..y1).flat_map(move |y| (x0..x1).map(move |x| y * camera.width + x))
            })
            .collect();
        candidates.sort_unstable();
        candidates.dedup();
        // Each pixel's sub-rays on their own (in parallel), then laid out in
        // pixel order: the same samples whatever the thread count.
        let sample_pixel = |index: u32| -> Vec<LampSample> {
            let (col, row) = (index % camera.width, index / camera.width);
            let mut out = Vec::new();
            for k in 0..n * n {
                let x = col as f64 + ((k % n) as f64 + 0.5) / n as f64;
                let y = row as f64 + ((k / n) as f64 + 0.5) / n as f64;
                let ray = camera.ray(x, y);
                let nearest = boxes
                    .iter()
                    .filter_map(|&(l, _)| {
                        meet(&lights[l], ray.origin, ray.direction).map(|m| (l, m))
                    })
                    .min_by(|a, b| a.1.0.total_cmp(&b.1.0));
                let Some((l, (t, front))) = nearest else {
                    continue;
                };
                let probe = TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3());
                let wall = tracer
                    .intersect(&probe, Layer::Real)
                    .map_or(f64::INFINITY, |h| h.t as f64);
                if t >= wall {
                    continue;
                }
                let emitted = if front {
                    model_radiance(&lights[l], ray.direction)
                } else {
                    DVec3::ZERO
                };
                out.push(LampSample {
                    light: l as u16,
                    t: t as f32,
                    dir: ray.direction.as_vec3(),
                    emitted: emitted.as_vec3(),
                });
            }
            out
        };
        let per_pixel: Vec<(u32, Vec<LampSample>)> = candidates
            .par_iter()
            .map(|&index| (index, sample_pixel(index)))
            .collect();
        let (mut pixels, mut samples) = (Vec::new(), Vec::new());
        for (index, found) in per_pixel {
            if found.is_empty() {
                continue;
            }
            pixels.push(LampPixel {
                index,
                start: samples.len() as u32,
                count: found.len() as u32,
            });
            samples.extend(found);
        }
        if pixels.is_empty() {
            return None;
        }
        Some(LampPixels {
            origin: camera.position.as_vec3(),
            per_pixel: n * n,
            pixels,
            samples,
            real: lights.iter().map(|l| l.real).collect(),
        })
    }

    /// Pixels that see a lamp.
    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }

    /// The indices (row-major) of the pixels that see a lamp.
    pub fn pixel_indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.pixels.iter().map(|p| p.index as usize)
    }

    fn samples_of(&self, p: &LampPixel) -> &[LampSample] {
        &self.samples[p.start as usize..(p.start + p.count) as usize]
    }

    /// The photo as the stages should read it: each pixel that sees a real
    /// lamp takes the darkest pixel (per channel) that sees none within
    /// [`FILL_REACH`] pixels, filled in from the lamp's outline inwards. The darkest, not the mean:
    /// what lies behind an emitting face is what the lamp itself does not
    /// light (its back is towards it), while the neighbours on the other
    /// side of its outline may lie in its brightest spot.
    pub fn photo_without_lamps(&self, photo: &Image) -> Image {
        let (w, h) = (photo.width as i64, photo.height as i64);
        let mut out = photo.clone();
        let mut unknown = vec![false; photo.pixels.len()];
        let mut todo: Vec<u32> = Vec::new();
        for p in &self.pixels {
            if self
                .samples_of(p)
                .iter()
                .any(|q| self.real[q.light as usize])
            {
                unknown[p.index as usize] = true;
                todo.push(p.index);
            }
        }
        while !todo.is_empty() {
            let mut filled: Vec<(u32, Vec3)> = Vec::new();
            for &i in &todo {
                let (x, y) = ((i as i64) % w, (i as i64) / w);
                let mut darkest: Option<Vec3> = None;
                let reach = -FILL_REACH..=FILL_REACH;
                for (dx, dy) in reach
                    .clone()
                    .flat_map(|dx| reach.clone().map(move |dy| (dx, dy)))
                {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= w || ny >= h {
                        continue;
                    }
                    let j = (ny * w + nx) as usize;
                    if !unknown[j] {
                        let v = out.pixels[j];
                        darkest = Some(darkest.map_or(v, |d| d.min(v)));
                    }
                }
                if let Some(d) = darkest {
                    filled.push((i, d));
                }
            }
            if filled.is_empty() {
                // The whole image is lamp: nothing to fill from.
                for &i in &todo {
                    out.pixels[i as usize] = Vec3::ZERO;
                }
                break;
            }
            for &(i, v) in &filled {
                out.pixels[i as usize] = v;
                unknown[i as usize] = false;
            }
            todo.retain(|&i| unknown[i as usize]);
        }
        out
    }

    /// Puts the lamps into a composite made from [`Self::photo_without_lamps`]
    /// (`filled`). A pixel shot as P = (1 − a)·B + E, a its share covered
    /// by real lamps, becomes (1 − a')·B' + Σ scale·E_l: B' the composite
    /// (the background as the change leaves it), E = P − (1 − a)·filled the
    /// lamps' part of the photo, split between the lamps by their modelled
    /// radiance, a' and E_l counting only the samples no virtual object
    /// hides; a virtual lamp switched on adds its modelled radiance. The
    /// lamps' part comes from the photo, so a lamp at scale 1 over an
    /// unchanged background gives back the photo's pixel (bit for bit).
    pub fn apply(
        &self,
        composite: &mut Composite,
        photo: &Image,
        filled: &Image,
        scales: &[f64],
        tracer: &Tracer,
    ) {
        let n = self.per_pixel as f32;
        // The composite holds some rows of the frame (a band or crop): `j` is `i` there.
        let first = composite.first_row as usize * composite.image.width as usize;
        for p in &self.pixels {
            let i = p.index as usize;
            let Some(j) = i
                .checked_sub(first)
                .filter(|j| *j < composite.image.pixels.len())
            else {
                continue;
            };
            let samples = self.samples_of(p);
            let on_real = samples.iter().filter(|q| self.real[q.light as usize]);
            let real_share = on_real.clone().count() as f32 / n;
            let real_model: Vec3 = on_real.map(|q| q.emitted).sum();
            // An object in front of a lamp shows in the composite's coverage
            // of the pixel; where that is zero no sample needs a ray (a
            // lamp's pixels are many, and this runs at every update). An
            // object thinner than one of the 4×4 edge sub-pixels could hide
            // a lamp sample and leave no coverage: it is not looked for.
            let may_be_hidden = composite.alpha.get(j).is_none_or(|a| *a > 0.0);
            let shot = photo.pixels[i].max(Vec3::ZERO);
            let lamps_shot = (shot - filled.pixels[i] * (1.0 - real_share)).max(Vec3::ZERO);
            let (mut lamp, mut visible, mut unchanged) = (Vec3::ZERO, 0u32, true);
            for q in samples {
                let scale = scales[q.light as usize] as f32;
                let real = self.real[q.light as usize];
                if !real && scale <= 0.0 {
                    continue;
                }
                if may_be_hidden && self.hidden(q, tracer) {
                    unchanged = false;
                    continue;
                }
                visible += 1;
                unchanged &= real && scale == 1.0;
                lamp += scale
                    * if !real {
                        q.emitted / n
                    } else if real_model.cmpgt(Vec3::ZERO).all() {
                        lamps_shot * q.emitted / real_model
                    } else {
                        // No modelled emission to split by (only the lamps' backs).
                        Vec3::ZERO
                    };
            }
            let background = composite.image.pixels[j];
            let value = if unchanged && background == filled.pixels[i] {
                photo.pixels[i]
            } else {
                let v = background * (1.0 - visible as f32 / n) + lamp;
                if v.is_finite() {
                    v.max(Vec3::ZERO)
                } else {
                    Vec3::ZERO
                }
            };
            composite.image.pixels[j] = value;
            if let Some(c) = composite.change.pixels.get_mut(j) {
                *c = value - photo.pixels[i];
            }
        }
    }

    /// Whether a virtual object stands between the camera and the lamp at
    /// sample `q`.
    fn hidden(&self, q: &LampSample, tracer: &Tracer) -> bool {
        if tracer.virtual_objects.is_none() {
            return false;
        }
        let probe = TraceRay {
            tfar: q.t,
            ..TraceRay::new(self.origin, q.dir)
        };
        tracer.occluded(&probe, Layer::Virtual)
    }
}

#[cfg(test)]
mod tests;
