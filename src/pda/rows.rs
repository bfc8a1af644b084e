//! Tracing the Pixel Data Array: a row at a time for a full build, and the
//! pixels near the objects' image after they move.

use super::*;

/// One row's part of the Pixel Data Array.
#[derive(Default)]
pub(super) struct Row {
    real: Vec<(u32, SurfacePoint)>,
    real_terms: Vec<LightTerm>,
    real_masks: Vec<RealMask>,
    virt: Vec<(u32, SurfacePoint)>,
    virt_terms: Vec<LightTerm>,
    edges: Vec<(u32, Vec<SurfacePoint>)>,
    edge_terms: Vec<LightTerm>,
    real_t: Vec<f32>,
    rays: u64,
}

/// What tracing a row reads.
pub(super) struct RowTracer<'a> {
    pub(super) input: &'a PdaInput<'a>,
    /// The objects' image on screen: its pixels are tested for mixed sub-pixels.
    pub(super) near_virtual: Vec<PixelBox>,
    /// Pixels that may mix sub-pixels (None: any near the objects).
    pub(super) candidates: Option<Vec<bool>>,
    /// The pixels computed (a crop's, or the whole image).
    pub(super) window: PixelRect,
}

impl RowTracer<'_> {
    /// Row `row`'s centre rays through the room and the objects, each hit's
    /// light terms, and its edge pixels' sub-pixels.
    pub(super) fn row(&self, row: u32) -> Row {
        let (input, window) = (self.input, self.window);
        let cam = input.camera;
        let w = cam.width;
        let mut r = Row::default();
        let rays: Vec<TraceRay> = (0..w)
            .map(|col| {
                let ray = cam.pixel_ray(col, row);
                TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3())
            })
            .collect();
        let mut real_hits = vec![None; w as usize];
        input
            .tracer
            .intersect_batch(&rays, Layer::Real, &mut real_hits);
        let real_t: Vec<f32> = rays
            .iter()
            .zip(&real_hits)
            .map(|(r, h)| h.map_or(r.tfar, |h| h.t))
            .collect();
        // What a query through both layers gives, its real half kept from above.
        let mut all_hits = real_hits.clone();
        if input.tracer.virtual_objects.is_some() {
            input
                .tracer
                .put_virtual_in_front(&rays, &real_t, &mut all_hits);
        }
        if input.for_updates {
            r.real_t = real_t;
        }
        let candidate = |pixel: u32| self.candidates.as_ref().is_none_or(|m| m[pixel as usize]);
        for col in window.x0..window.x1 {
            let pixel = row * w + col;
            let seed = hash2(pixel as u64, 0x5A17);
            let ray = cam.pixel_ray(col, row);
            let real = real_hits[col as usize]
                .as_ref()
                .and_then(|hit| input.point(hit, ray.origin, ray.direction));
            if let Some(p) = real {
                r.rays += input.terms(
                    &p,
                    seed,
                    &mut r.real_terms,
                    input.for_updates.then_some(&mut r.real_masks),
                );
                r.real.push((pixel, p));
            }
            if let Some(hit) = all_hits[col as usize].as_ref().filter(|h| h.is_virtual)
                && let Some(p) = input.point(hit, ray.origin, ray.direction)
            {
                r.rays += input.terms(&p, hash2(seed, 1), &mut r.virt_terms, None);
                r.virt.push((pixel, p));
            }
            if self.near_virtual.iter().any(|b| b.contains(col, row)) && candidate(pixel) {
                // Only a real point the pixel's centre sees: one behind an object may be in its shadow.
                let seen = all_hits[col as usize]
                    .as_ref()
                    .is_some_and(|h| !h.is_virtual);
                let (kept, rays) = edge_samples(
                    input,
                    col,
                    row,
                    seed,
                    real.as_ref().filter(|_| seen),
                    &mut r.edge_terms,
                );
                r.rays += rays;
                if let Some(kept) = kept {
                    r.edges.push((pixel, kept));
                }
            }
        }
        r
    }
}

/// A re-traced pixel: its virtual point with its terms, its edge
/// sub-pixels with theirs, and the rays cast.
pub(super) type Retraced = (
    u32,
    Option<(SurfacePoint, Vec<LightTerm>)>,
    Option<(Vec<SurfacePoint>, Vec<LightTerm>)>,
    u64,
);

impl PixelDataArray {
    /// The array from its rows, in order.
    pub(super) fn assemble(input: &PdaInput, held: (u32, u32), rows: Vec<Row>) -> PixelDataArray {
        let (w, h) = (input.camera.width, input.camera.height);
        let n = ((held.1 - held.0) * w) as usize;
        let mut pda = PixelDataArray {
            width: w,
            height: h,
            light_count: input.lights.len(),
            supersample: input.settings.supersample.max(1),
            rows: held,
            own: PixelRect::full(w, h),
            real_index: vec![NONE; n],
            real_t: Vec::with_capacity(if input.for_updates { n } else { 0 }),
            real: Samples::default(),
            real_masks: Vec::new(),
            virtual_index: vec![NONE; n],
            virtual_pixels: Vec::new(),
            virtual_samples: Samples::default(),
            edges: Vec::new(),
            edge_samples: Samples::default(),
            rays: 0,
            examined: None,
            by_patch: Default::default(),
        };
        let first = pda.first_pixel();
        for r in rows {
            for (pixel, p) in r.real {
                pda.real_index[pixel as usize - first] = pda.real.points.len() as u32;
                pda.real.points.push(p);
            }
            pda.real.terms.extend(r.real_terms);
            pda.real_masks.extend(r.real_masks);
            for (pixel, p) in r.virt {
                pda.push_virtual(pixel, p, &[]);
            }
            pda.virtual_samples.terms.extend(r.virt_terms);
            for (pixel, subs) in r.edges {
                pda.push_edge(pixel, &subs, &[]);
            }
            pda.edge_samples.terms.extend(r.edge_terms);
            pda.real_t.extend(r.real_t);
            pda.rays += r.rays;
        }
        pda
    }

    /// Adds pixel `pixel`'s virtual point, and its terms.
    pub(super) fn push_virtual(&mut self, pixel: u32, p: SurfacePoint, terms: &[LightTerm]) {
        let first = self.first_pixel();
        self.virtual_index[pixel as usize - first] = self.virtual_samples.points.len() as u32;
        self.virtual_pixels.push(pixel);
        self.virtual_samples.points.push(p);
        self.virtual_samples.terms.extend_from_slice(terms);
    }

    /// Adds edge pixel `pixel`'s sub-pixel points, and their terms.
    pub(super) fn push_edge(&mut self, pixel: u32, subs: &[SurfacePoint], terms: &[LightTerm]) {
        let start = self.edge_samples.points.len() as u32;
        self.edges.push(EdgePixel {
            pixel,
            start,
            count: subs.len() as u32,
        });
        self.edge_samples.points.extend_from_slice(subs);
        self.edge_samples.terms.extend_from_slice(terms);
    }

    /// The pixels in the objects' screen boxes that an object may show in,
    /// sorted: the nearest any object can be to the camera decides, as a
    /// pixel whose real surface (and its neighbours', which its sub-pixels
    /// may reach) is nearer hides every object, and needs no ray.
    pub(super) fn pixels_to_retrace(&self, input: &PdaInput, boxes: &[PixelBox]) -> Vec<u32> {
        let cam = input.camera;
        let nearest = input
            .bounds
            .objects
            .iter()
            .map(|o| (cam.position.clamp(o.aabb.0, o.aabb.1) - cam.position).length())
            .fold(f64::INFINITY, f64::min);
        let hidden = |x: u32, y: u32| {
            let (x0, x1, y0, y1) = (
                x.saturating_sub(1),
                (x + 1).min(self.width - 1),
                y.saturating_sub(1),
                (y + 1).min(self.height - 1),
            );
            (y0..=y1).all(|yy| {
                (x0..=x1).all(|xx| {
                    let k = self.real_at((yy * self.width + xx) as usize);
                    k != NONE
                        && (self.real.points[k as usize].position.as_dvec3() - cam.position)
                            .length()
                            < nearest
                })
            })
        };
        let mut pixels: Vec<u32> = Vec::new();
        for b in boxes {
            for y in b.y0..=b.y1 {
                for x in b.x0..=b.x1 {
                    if !hidden(x, y) {
                        pixels.push(y * self.width + x);
                    }
                }
            }
        }
        pixels.sort_unstable();
        pixels.dedup();
        pixels
    }

    /// Re-traces `pixels` against the objects: centre rays in packets of 16
    /// (the kernel `build` traces with, so the same bits), through the
    /// objects only as far as the real hit `build` found; then each pixel's
    /// shading and edge test.
    pub(super) fn retrace(
        &self,
        input: &PdaInput,
        pixels: &[u32],
        candidates: Option<&[bool]>,
    ) -> Vec<Retraced> {
        let cam = input.camera;
        let (real_t, first) = (&self.real_t, self.first_pixel());
        pixels
            .par_chunks(16)
            .flat_map_iter(|chunk| {
                let traced: Vec<TraceRay> = chunk
                    .iter()
                    .map(|&pixel| {
                        let ray = cam.pixel_ray(pixel % self.width, pixel / self.width);
                        TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3())
                    })
                    .collect();
                let before: Vec<f32> = chunk
                    .iter()
                    .map(|&pixel| real_t[pixel as usize - first])
                    .collect();
                let mut hits = vec![None; chunk.len()];
                input
                    .tracer
                    .intersect_virtual_before(&traced, &before, &mut hits);
                chunk.iter().copied().zip(hits).collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(pixel, hit)| {
                let (col, row) = (pixel % self.width, pixel / self.width);
                let seed = hash2(pixel as u64, 0x5A17);
                let ray = cam.pixel_ray(col, row);
                let mut rays = 0;
                let virt = hit
                    .filter(|h| h.is_virtual)
                    .and_then(|h| input.point(&h, ray.origin, ray.direction))
                    .map(|p| {
                        let mut terms = Vec::with_capacity(input.lights.len());
                        rays += input.terms(&p, hash2(seed, 1), &mut terms, None);
                        (p, terms)
                    });
                let mut edge_terms = Vec::new();
                // No object in front: the centre sees the real hit, if there is one.
                let seen = hit.is_none() && real_t[pixel as usize - first].is_finite();
                let real = Some(self.real_at(pixel as usize))
                    .filter(|&k| k != NONE && seen)
                    .map(|k| &self.real.points[k as usize]);
                let (kept, r) = if candidates.is_none_or(|m| m[pixel as usize]) {
                    edge_samples(input, col, row, seed, real, &mut edge_terms)
                } else {
                    (None, 0)
                };
                rays += r;
                let edge = kept.map(|kept| (kept, edge_terms));
                (pixel, virt, edge, rays)
            })
            .collect()
    }
}

/// The last placement's virtual points and edge pixels, for the pixels an
/// update keeps.
pub(super) struct Placed {
    pixels: Vec<u32>,
    samples: Samples,
    edges: Vec<EdgePixel>,
    edge_samples: Samples,
    lights: usize,
}

/// A pixel's virtual point and its edge's sub-pixel points, with their light terms.
type PixelPoints<'a> = (
    Option<(SurfacePoint, &'a [LightTerm])>,
    Option<(&'a [SurfacePoint], &'a [LightTerm])>,
);

/// What testing a pixel against the moved objects reads, the same for
/// every pixel of a placement.
pub(super) struct Reach {
    /// The widest angle between a pixel's centre ray and a ray through one
    /// of its corners, over pixels spread across the image (every 16th row
    /// and column), twice over: a lens's distortion changes it smoothly.
    widest: f64,
    /// The active lights' balls.
    lights: Vec<(DVec3, f64)>,
}

impl Reach {
    pub(super) fn of(input: &PdaInput) -> Reach {
        let cam = input.camera;
        let (w, h) = (cam.width, cam.height);
        let step = |n: u32| (0..n).step_by(16).chain([n.saturating_sub(1)]);
        let mut widest: f64 = 0.0;
        for row in step(h) {
            for col in step(w) {
                let d = cam.pixel_ray(col, row).direction.normalize_or_zero();
                for (x, y) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    let c = cam.ray(col as f64 + x, row as f64 + y).direction;
                    widest = widest.max(c.normalize_or_zero().dot(d).clamp(-1.0, 1.0).acos());
                }
            }
        }
        let lights = (input.lights.iter().zip(input.active))
            .filter(|(_, a)| **a)
            .map(|(l, _)| l.ball())
            .collect();
        Reach {
            widest: 2.0 * widest,
            lights,
        }
    }
}

impl Placed {
    /// Takes them from `pda`, which is left without any.
    pub(super) fn take(pda: &mut PixelDataArray) -> Placed {
        Placed {
            pixels: std::mem::take(&mut pda.virtual_pixels),
            samples: std::mem::take(&mut pda.virtual_samples),
            edges: std::mem::take(&mut pda.edges),
            edge_samples: std::mem::take(&mut pda.edge_samples),
            lights: pda.light_count,
        }
    }

    /// None, `pda`'s emptied in place (their room kept).
    pub(super) fn cleared(pda: &mut PixelDataArray) -> Placed {
        pda.virtual_pixels.clear();
        for samples in [&mut pda.virtual_samples, &mut pda.edge_samples] {
            samples.points.clear();
            samples.terms.clear();
        }
        pda.edges.clear();
        Placed {
            pixels: Vec::new(),
            samples: Samples::default(),
            edges: Vec::new(),
            edge_samples: Samples::default(),
            lights: pda.light_count,
        }
    }

    /// Pixel `pixel`'s points.
    pub(super) fn at(&self, pixel: u32) -> PixelPoints<'_> {
        let l = self.lights;
        let virt = self.pixels.binary_search(&pixel).ok().map(|k| {
            let terms = &self.samples.terms[k * l..(k + 1) * l];
            (self.samples.points[k], terms)
        });
        let edge = (self.edges.binary_search_by_key(&pixel, |e| e.pixel).ok()).map(|k| {
            let e = self.edges[k];
            let (a, b) = (e.start as usize, (e.start + e.count) as usize);
            (
                &self.edge_samples.points[a..b],
                &self.edge_samples.terms[a * l..b * l],
            )
        });
        (virt, edge)
    }

    /// Whether no moved object comes near pixel `pixel`'s camera rays (a
    /// cone from the camera around its centre ray, `reach.widest` its
    /// half-angle in radians) nor the shadow rays of its points to the
    /// active lights, and its virtual point's surface stood still.
    pub(super) fn clear(
        &self,
        input: &PdaInput,
        movers: &dyn crate::objects::Movers,
        (pixel, reach): (u32, &Reach),
    ) -> bool {
        let cam = input.camera;
        let centre = cam.pixel_ray(pixel % cam.width, pixel / cam.width);
        let d = centre.direction.normalize_or_zero();
        const FAR: f64 = 1e4;
        let radius = FAR * reach.widest.min(1.0).tan();
        if !movers.clear_towards(centre.origin, centre.origin + d * FAR, radius, 0.0) {
            return false;
        }
        let (virt, edge) = self.at(pixel);
        let mut points = virt.iter().map(|(p, _)| p);
        let mut subs = edge.iter().flat_map(|(ps, _)| ps.iter());
        let clear = |p: &SurfacePoint| {
            let x = p.position.as_dvec3();
            (!p.is_virtual || movers.unmoved(p.surface))
                && (reach.lights.iter()).all(|&(c, r)| movers.clear_towards(x, c, r, 1e-3))
        };
        points.all(clear) && subs.all(clear)
    }
}
