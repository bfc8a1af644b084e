//! [`PixelDataArray`] (Grosch §3.1, after Loscos et al.): per pixel the
//! real surface point the camera sees, with its patch and interpolation
//! weights, and per light the unoccluded irradiance (the geometry term) and
//! two visibilities — through real geometry only (the photo's world) and
//! through real and virtual geometry (the augmented one). Where a virtual
//! object is in front, the virtual point is kept too; where a pixel's
//! sub-pixels mix real and virtual surfaces, each sub-pixel is kept.
//!
//! Shadow rays go to the light's jittered grid, chosen by an oracle: 2^min
//! rays first, 2^penumbra only where they disagree (penumbra). Rays against
//! virtual geometry are cast only where the shaft from the point to the
//! light can meet a virtual object's bounds; elsewhere both visibilities are
//! the same numbers, so untouched pixels cost nothing more than the photo's.

use std::collections::{HashMap, HashSet};

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::geometry::box_corners;
use crate::light::{LightSource, offset_origin, segment};
pub use crate::objects::{CLEAR_TEST_LIMIT, VirtualBounds, own_blocks};
use crate::patches::Patches;
use crate::shaft::Shaft;
use crate::trace::{Hit, Layer, TraceRay, Tracer};
use crate::util::rng::hash2;

/// Ray budget of the visibility oracle and the edge supersampling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdaSettings {
    /// 2^min_level shadow rays per rect light everywhere.
    pub min_level: usize,
    /// 2^penumbra_level where the first rays disagree.
    pub penumbra_level: usize,
    /// n×n sub-pixels tested (and shaded where they mix real and virtual).
    pub supersample: u32,
}

impl Default for PdaSettings {
    fn default() -> Self {
        PdaSettings {
            min_level: 2,
            penumbra_level: 4,
            supersample: 4,
        }
    }
}

/// One light at one surface point (8 bytes).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LightTerm {
    /// Unoccluded irradiance before the light's scale, as a multiple of the light's colour.
    pub unoccluded: f32,
    /// Visible fraction through real geometry only, in 1/65535.
    visible_real: u16,
    /// Visible fraction through real and virtual geometry, in 1/65535.
    visible_all: u16,
}

impl LightTerm {
    pub fn new(unoccluded: f32, visible_real: f64, visible_all: f64) -> LightTerm {
        let q = |v: f64| (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
        LightTerm {
            unoccluded,
            visible_real: q(visible_real),
            visible_all: q(visible_all),
        }
    }

    /// The visible fraction through real geometry only, or through all.
    pub fn visible(&self, all: bool) -> f64 {
        (if all {
            self.visible_all
        } else {
            self.visible_real
        }) as f64
            / 65535.0
    }
}

/// Which of a real point's shadow rays to one light real geometry blocks,
/// bit k for sample k, at the oracle's first level and (once traced) at its
/// penumbra level: kept so that an update, which can only change what the
/// virtual objects block, traces no ray through the room again.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RealMask {
    first: u16,
    penumbra: u16,
    /// Bit 0: `first` is known; bit 1: `penumbra` is.
    known: u8,
}

impl RealMask {
    /// At most this many samples per level are kept.
    const MAX_SAMPLES: usize = 16;
    /// No sample blocked at either level: what a point whose light the
    /// room cannot block knows without a ray.
    const CLEAR: RealMask = RealMask {
        first: 0,
        penumbra: 0,
        known: 3,
    };

    fn get(&self, penumbra: bool) -> Option<u16> {
        let (bit, v) = if penumbra {
            (2, self.penumbra)
        } else {
            (1, self.first)
        };
        (self.known & bit != 0).then_some(v)
    }

    fn set(&mut self, penumbra: bool, v: u16) {
        if penumbra {
            self.penumbra = v;
            self.known |= 2;
        } else {
            self.first = v;
            self.known |= 1;
        }
    }
}

/// Where a point lies on its patch: the weights of the patch's corner
/// vertices (in `Patches::patch_vertices` order; triangles use three).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatchPoint {
    pub patch: u32,
    pub weights: [f32; 4],
}

/// A surface point seen through a pixel or sub-pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    pub position: Vec3,
    pub normal: Vec3,
    pub surface: u32,
    pub is_virtual: bool,
    /// An edge pixel's real sub-pixel on the plane of the pixel's own real
    /// point: it takes that point's light terms (the photo's pixel is one
    /// value for all of them; its light does not vary within it to speak of).
    pub pixel_terms: bool,
    /// A virtual point on a face its own surface lies wholly behind (see
    /// [`VirtualBounds`]): that surface cannot shadow it.
    pub clear_of_own: bool,
    /// Patch and interpolation weights on its vertices.
    pub location: PatchPoint,
}

/// Points with their light terms (`terms[i * lights + l]`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Samples {
    pub points: Vec<SurfacePoint>,
    pub terms: Vec<LightTerm>,
}

/// An edge pixel: its sub-pixel samples are `edge_samples[start..start+count]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgePixel {
    pub pixel: u32,
    pub start: u32,
    pub count: u32,
}

/// The Pixel Data Array.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelDataArray {
    pub width: u32,
    pub height: u32,
    pub light_count: usize,
    /// Sub-pixels per side of an edge pixel.
    pub supersample: u32,
    /// Per pixel, index into `real` (u32::MAX: no real surface).
    pub real_index: Vec<u32>,
    /// Per pixel, how far along its centre ray the real hit lies, as the
    /// tracer reported it (∞: none): an update traces that ray through the
    /// objects alone, only as far, instead of through the room again.
    pub real_t: Vec<f32>,
    pub real: Samples,
    /// Per real point and light (as `real.terms`), its shadow rays' real blockers.
    pub real_masks: Vec<RealMask>,
    /// Per pixel, index into `virtual_samples` (u32::MAX: no virtual surface in front).
    pub virtual_index: Vec<u32>,
    /// The pixels `virtual_index` holds, in pixel order.
    pub virtual_pixels: Vec<u32>,
    pub virtual_samples: Samples,
    /// Pixels whose sub-pixels mix real and virtual surfaces, in pixel order.
    pub edges: Vec<EdgePixel>,
    pub edge_samples: Samples,
    /// Shadow and sub-pixel rays traced.
    pub rays: u64,
}

const NONE: u32 = u32::MAX;

/// Everything the PDA is built from.
pub struct PdaInput<'a> {
    pub camera: &'a Camera,
    /// Real geometry and the virtual objects of the augmented scene.
    pub tracer: &'a Tracer,
    /// Real patches, then the virtual objects' patches (as the tracer numbers surfaces).
    pub patches: &'a Patches,
    pub lights: &'a [LightSource],
    /// Which lights matter (on in the photo or in the augmented scene).
    pub active: &'a [bool],
    pub bounds: &'a VirtualBounds,
    pub settings: PdaSettings,
    /// Keep each real point's real blockers ([`RealMask`]) for updates
    /// after objects move; a still image has no use for them.
    pub for_updates: bool,
}

impl PdaInput<'_> {
    /// The light terms of a surface point; returns rays cast. `masks`:
    /// where to keep each light's real blockers (real points only).
    fn terms(
        &self,
        p: &SurfacePoint,
        seed: u64,
        out: &mut Vec<LightTerm>,
        mut masks: Option<&mut Vec<RealMask>>,
    ) -> u64 {
        let (x, n) = (p.position.as_dvec3(), p.normal.as_dvec3());
        let own = self.bounds.own_clear(p.clear_of_own, p.surface);
        let mut rays = 0;
        for (l, light) in self.lights.iter().enumerate() {
            let mut mask = RealMask::default();
            if self.active[l] {
                let mut clear = RealMask::CLEAR;
                let keep = if masks.is_some() {
                    Some(&mut mask)
                } else {
                    self.bounds
                        .room_clear(p.is_virtual, p.surface, l)
                        .then_some(&mut clear)
                };
                let (term, r) = light_term(
                    self.tracer,
                    light,
                    self.bounds,
                    own,
                    x,
                    n,
                    hash2(seed, l as u64),
                    self.settings,
                    None,
                    keep,
                );
                out.push(term);
                rays += r;
            } else {
                out.push(LightTerm::default());
            }
            if let Some(m) = masks.as_deref_mut() {
                m.push(mask);
            }
        }
        rays
    }

    fn point(&self, hit: &Hit, origin: DVec3, direction: DVec3) -> Option<SurfacePoint> {
        let x = origin + direction * hit.t as f64;
        let at = self.patches.locate(hit.surface, hit.triangle, x)?;
        let location = PatchPoint {
            patch: at.patch,
            weights: at.weights.map(|(_, w)| w as f32),
        };
        let clear_of_own = hit.is_virtual && self.bounds.is_clear_of_own(hit);
        Some(SurfacePoint {
            position: x.as_vec3(),
            normal: hit.normal,
            surface: hit.surface,
            is_virtual: hit.is_virtual,
            pixel_terms: false,
            clear_of_own,
            location,
        })
    }
}

/// Visibility of one light from x through the two worlds, by the oracle.
/// `before`: for a term computed before, its geometry factor (when
/// positive) and whether the objects may shadow x now (the pixel-block
/// traversal's answer; where it differs from [`VirtualBounds::may_shadow`],
/// one of the two excludes the objects and their rays meet nothing);
/// `real`: the real blockers already known for these samples, where rays
/// traced through the room are kept (a real point's; samples beyond
/// [`RealMask::MAX_SAMPLES`] are always traced).
#[allow(clippy::too_many_arguments)]
fn light_term(
    tracer: &Tracer,
    light: &LightSource,
    bounds: &VirtualBounds,
    own: Option<usize>,
    x: DVec3,
    n: DVec3,
    seed: u64,
    settings: PdaSettings,
    before: Option<(f32, bool)>,
    mut real: Option<&mut RealMask>,
) -> (LightTerm, u64) {
    let unoccluded = match before {
        Some((u, _)) if u > 0.0 => u,
        _ => {
            let g = light.unoccluded_irradiance(x, n);
            let colour = light.colour().max_element();
            if g == DVec3::ZERO || colour <= 0.0 {
                return (LightTerm::default(), 0);
            }
            (g.max_element() / colour) as f32
        }
    };
    let check_virtual = before.map_or_else(|| bounds.may_shadow(x, light, own), |(_, may)| may);
    // On a face clear of its own solid (and no other object near), what
    // the solid blocks is known without tracing: whatever lies behind the
    // face, which a ray reaches only through the solid — and everything
    // when the light's centre is behind it, as the rays then leave from
    // the solid's side of the face ([`offset_origin`]).
    let own_blocks = |y: DVec3| own.is_some() && own_blocks(x, n, light.position, y);
    let origin = offset_origin(x, n, light.position);
    let Some(grid) = &light.grid else {
        let ray = segment(origin, light.position);
        let (real_visible, mut rays_cast) = match real.as_ref().and_then(|m| m.get(false)) {
            Some(bits) => (bits == 0, 0),
            None => {
                let blocked = tracer.occluded(&ray, Layer::Real);
                if let Some(m) = real {
                    m.set(false, blocked as u16);
                }
                (!blocked, 1)
            }
        };
        let all = real_visible
            && !if check_virtual {
                tracer.occluded(&ray, Layer::Virtual)
            } else {
                own_blocks(light.position)
            };
        rays_cast += (real_visible && check_virtual) as u64;
        let f = |b: bool| if b { 1.0 } else { 0.0 };
        return (
            LightTerm::new(unoccluded, f(real_visible), f(all)),
            rays_cast,
        );
    };
    // Buffers for the most rays one call may cast: on the stack for the
    // usual budgets (filling 256 entries per pixel and light, whatever the
    // budget, cost more than the shading around it), on the heap beyond.
    let most = 1usize
        << settings
            .min_level
            .max(settings.penumbra_level)
            .min(crate::light::MAX_GRID_LEVEL);
    const SMALL: usize = 16;
    let mut run = |targets: &mut [DVec3],
                   rays: &mut [TraceRay],
                   real_blocked: &mut [bool],
                   virt_blocked: &mut [bool]|
     -> (LightTerm, u64) {
        let mut level = settings.min_level;
        let mut rays_cast = 0u64;
        loop {
            let mut count = 0;
            for st in grid.samples(level, seed) {
                targets[count] = light.point_at(st);
                rays[count] = segment(origin, targets[count]);
                count += 1;
            }
            let penumbra = level != settings.min_level;
            let keep = real
                .as_deref_mut()
                .filter(|_| count <= RealMask::MAX_SAMPLES);
            match keep.as_ref().and_then(|m| m.get(penumbra)) {
                Some(bits) => (0..count).for_each(|k| real_blocked[k] = bits >> k & 1 == 1),
                None => {
                    tracer.occluded_batch(&rays[..count], Layer::Real, &mut real_blocked[..count]);
                    rays_cast += count as u64;
                    if let Some(m) = keep {
                        m.set(
                            penumbra,
                            (0..count).fold(0u16, |b, k| b | (real_blocked[k] as u16) << k),
                        );
                    }
                }
            }
            if check_virtual {
                tracer.occluded_batch(&rays[..count], Layer::Virtual, &mut virt_blocked[..count]);
                rays_cast += count as u64;
            } else {
                for k in 0..count {
                    virt_blocked[k] = own_blocks(targets[k]);
                }
            }
            // Which rays the room blocks, and which it or the objects block:
            // some, and some not, of each.
            let (mut real_some, mut real_none, mut all_some, mut all_none) =
                (false, false, false, false);
            for k in 0..count {
                let all = real_blocked[k] || virt_blocked[k];
                real_some |= real_blocked[k];
                real_none |= !real_blocked[k];
                all_some |= all;
                all_none |= !all;
            }
            let (real_mixed, all_mixed) = (real_some && real_none, all_some && all_none);
            if level < settings.penumbra_level && (real_mixed || all_mixed) {
                level = settings.penumbra_level;
                continue;
            }
            // Where no ray or every ray is blocked the fractions are 1 or 0
            // whatever the rays weigh: the weights (the light's intensity
            // towards x per sample) are needed only for the rest.
            if !real_mixed && !all_mixed {
                let settled = |some: bool| if some { 0.0 } else { 1.0 };
                return (
                    LightTerm::new(unoccluded, settled(real_some), settled(all_some)),
                    rays_cast,
                );
            }
            // Each ray weighs what its sample contributes at x.
            let (mut total, mut real, mut all) = (0.0, 0.0, 0.0);
            for k in 0..count {
                let w = crate::light::point_contribution(targets[k], x, n, |d| light.intensity(d))
                    .max_element();
                total += w;
                if !real_blocked[k] {
                    real += w;
                    if !virt_blocked[k] {
                        all += w;
                    }
                }
            }
            let frac = |v: f64| if total > 0.0 { v / total } else { 0.0 };
            return (LightTerm::new(unoccluded, frac(real), frac(all)), rays_cast);
        }
    };
    let blank = TraceRay::new(glam::Vec3::ZERO, glam::Vec3::Z);
    if most <= SMALL {
        run(
            &mut [DVec3::ZERO; SMALL],
            &mut [blank; SMALL],
            &mut [false; SMALL],
            &mut [false; SMALL],
        )
    } else {
        run(
            &mut vec![DVec3::ZERO; most],
            &mut vec![blank; most],
            &mut vec![false; most],
            &mut vec![false; most],
        )
    }
}

impl PixelDataArray {
    /// Builds the array for every pixel of the camera.
    pub fn build(input: &PdaInput) -> PixelDataArray {
        let cam = input.camera;
        let (w, h) = (cam.width, cam.height);
        let lights = input.lights.len();
        let has_virtual = input.tracer.virtual_objects.is_some();
        // Pixels near a virtual object's image are tested for mixed sub-pixels.
        let near_virtual = screen_boxes(cam, input.bounds);
        let candidates = if near_virtual.is_empty() {
            None
        } else {
            edge_candidates(input)
        };
        let candidate = |pixel: u32| candidates.as_ref().is_none_or(|m| m[pixel as usize]);

        struct Row {
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
        let rows: Vec<Row> = (0..h)
            .into_par_iter()
            .map(|row| {
                let mut r = Row {
                    real: vec![],
                    real_terms: vec![],
                    real_masks: vec![],
                    virt: vec![],
                    virt_terms: vec![],
                    edges: vec![],
                    edge_terms: vec![],
                    real_t: vec![],
                    rays: 0,
                };
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
                if has_virtual {
                    input
                        .tracer
                        .put_virtual_in_front(&rays, &real_t, &mut all_hits);
                }
                r.real_t = real_t;
                for col in 0..w {
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
                    if near_virtual.iter().any(|b| b.contains(col, row)) && candidate(pixel) {
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
            })
            .collect();

        let n = (w * h) as usize;
        let mut pda = PixelDataArray {
            width: w,
            height: h,
            light_count: lights,
            supersample: input.settings.supersample.max(1),
            real_index: vec![NONE; n],
            real_t: Vec::with_capacity(n),
            real: Samples::default(),
            real_masks: Vec::new(),
            virtual_index: vec![NONE; n],
            virtual_pixels: Vec::new(),
            virtual_samples: Samples::default(),
            edges: Vec::new(),
            edge_samples: Samples::default(),
            rays: 0,
        };
        for r in rows {
            for (pixel, p) in r.real {
                pda.real_index[pixel as usize] = pda.real.points.len() as u32;
                pda.real.points.push(p);
            }
            pda.real.terms.extend(r.real_terms);
            pda.real_masks.extend(r.real_masks);
            for (pixel, p) in r.virt {
                pda.virtual_index[pixel as usize] = pda.virtual_samples.points.len() as u32;
                pda.virtual_pixels.push(pixel);
                pda.virtual_samples.points.push(p);
            }
            pda.virtual_samples.terms.extend(r.virt_terms);
            for (pixel, subs) in r.edges {
                let start = pda.edge_samples.points.len() as u32;
                pda.edges.push(EdgePixel {
                    pixel,
                    start,
                    count: subs.len() as u32,
                });
                pda.edge_samples.points.extend(subs);
            }
            pda.edge_samples.terms.extend(r.edge_terms);
            pda.real_t.extend(r.real_t);
            pda.rays += r.rays;
        }
        pda
    }

    /// Recomputes the light terms of the real points at `pixels` for
    /// `light` (after the virtual objects moved), exactly as [`build`]
    /// computes them; returns rays cast. `now` (sorted): those of them
    /// whose shafts to the light may meet the objects where they are now,
    /// as the pixel-block traversal found them.
    ///
    /// [`build`]: PixelDataArray::build
    pub fn recompute_real_terms(
        &mut self,
        input: &PdaInput,
        pixels: &[u32],
        now: &[u32],
        light: usize,
    ) -> u64 {
        if !input.active[light] {
            return 0;
        }
        let lights = self.light_count;
        let (real_index, points, terms, masks) = (
            &self.real_index,
            &self.real.points,
            &self.real.terms,
            &self.real_masks,
        );
        // Only what the objects block can have changed: the geometry factor
        // and the room's blockers are taken as the full render found them.
        let fresh: Vec<(usize, LightTerm, Option<RealMask>, u64)> = pixels
            .par_iter()
            .with_min_len(64)
            .filter_map(|&pixel| {
                let k = real_index[pixel as usize];
                (k != NONE).then(|| {
                    let p = points[k as usize];
                    let at = k as usize * lights + light;
                    let seed = hash2(pixel as u64, 0x5A17);
                    let mut mask = masks.get(at).copied();
                    let (term, rays) = light_term(
                        input.tracer,
                        &input.lights[light],
                        input.bounds,
                        None,
                        p.position.as_dvec3(),
                        p.normal.as_dvec3(),
                        hash2(seed, light as u64),
                        input.settings,
                        Some((terms[at].unoccluded, now.binary_search(&pixel).is_ok())),
                        mask.as_mut(),
                    );
                    (at, term, mask, rays)
                })
            })
            .collect();
        let mut rays = 0;
        for (at, term, mask, r) in fresh {
            self.real.terms[at] = term;
            if let Some(mask) = mask {
                self.real_masks[at] = mask;
            }
            rays += r;
        }
        rays
    }

    /// Rebuilds the virtual points and edge pixels for the objects' current
    /// placement (`input.bounds`), as [`build`] would; returns rays cast and
    /// the pixels examined.
    ///
    /// [`build`]: PixelDataArray::build
    pub fn rebuild_virtual(&mut self, input: &PdaInput) -> (u64, u64) {
        let cam = input.camera;
        let n = (self.width * self.height) as usize;
        // Reset in place, where the last placement set it: a fresh 0.8 MB
        // each update faulted its pages in again, and filling it all
        // wrote 0.8 MB to clear a few thousand entries.
        self.virtual_index.resize(n, NONE);
        for &pixel in &self.virtual_pixels {
            self.virtual_index[pixel as usize] = NONE;
        }
        self.virtual_pixels.clear();
        // Emptied, their room kept: the next placement fills about as many.
        for samples in [&mut self.virtual_samples, &mut self.edge_samples] {
            samples.points.clear();
            samples.terms.clear();
        }
        self.edges.clear();
        let boxes = screen_boxes(cam, input.bounds);
        let candidates = if boxes.is_empty() {
            None
        } else {
            edge_candidates(input)
        };
        let candidate = |pixel: u32| candidates.as_ref().is_none_or(|m| m[pixel as usize]);
        // The nearest any object can be to the camera: a pixel whose real
        // surface (and its neighbours', which its sub-pixels may reach) is
        // nearer hides every object, and needs no ray.
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
                    let k = self.real_index[(yy * self.width + xx) as usize];
                    k != NONE
                        && (self.real.points[k as usize].position.as_dvec3() - cam.position)
                            .length()
                            < nearest
                })
            })
        };
        let mut pixels: Vec<u32> = Vec::new();
        for b in &boxes {
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
        type Found = (
            u32,
            Option<(SurfacePoint, Vec<LightTerm>)>,
            Option<(Vec<SurfacePoint>, Vec<LightTerm>)>,
            u64,
        );
        // Centre rays in packets of 16 (the kernel `build` traces with, so
        // the same bits), through the objects only as far as the real hit
        // `build` found; then each pixel's shading and edge test.
        let real_t = &self.real_t;
        let found: Vec<Found> = pixels
            .par_chunks(16)
            .flat_map_iter(|chunk| {
                let traced: Vec<TraceRay> = chunk
                    .iter()
                    .map(|&pixel| {
                        let ray = cam.pixel_ray(pixel % self.width, pixel / self.width);
                        TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3())
                    })
                    .collect();
                let before: Vec<f32> = chunk.iter().map(|&pixel| real_t[pixel as usize]).collect();
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
                let seen = hit.is_none() && real_t[pixel as usize].is_finite();
                let real = Some(self.real_index[pixel as usize])
                    .filter(|&k| k != NONE && seen)
                    .map(|k| &self.real.points[k as usize]);
                let (kept, r) = if candidate(pixel) {
                    edge_samples(input, col, row, seed, real, &mut edge_terms)
                } else {
                    (None, 0)
                };
                rays += r;
                let edge = kept.map(|kept| (kept, edge_terms));
                (pixel, virt, edge, rays)
            })
            .collect();
        let mut rays = 0;
        for (pixel, virt, edge, r) in found {
            rays += r;
            if let Some((p, terms)) = virt {
                self.virtual_index[pixel as usize] = self.virtual_samples.points.len() as u32;
                self.virtual_pixels.push(pixel);
                self.virtual_samples.points.push(p);
                self.virtual_samples.terms.extend(terms);
            }
            if let Some((kept, terms)) = edge {
                let start = self.edge_samples.points.len() as u32;
                self.edges.push(EdgePixel {
                    pixel,
                    start,
                    count: kept.len() as u32,
                });
                self.edge_samples.points.extend(kept);
                self.edge_samples.terms.extend(terms);
            }
        }
        (rays, pixels.len() as u64)
    }

    /// Bytes held, and per pixel.
    pub fn memory_bytes(&self) -> usize {
        let samples = |s: &Samples| {
            s.points.len() * std::mem::size_of::<SurfacePoint>()
                + s.terms.len() * std::mem::size_of::<LightTerm>()
        };
        (self.real_index.len()
            + self.real_t.len()
            + self.virtual_index.len()
            + self.virtual_pixels.len())
            * 4
            + samples(&self.real)
            + self.real_masks.len() * std::mem::size_of::<RealMask>()
            + samples(&self.virtual_samples)
            + samples(&self.edge_samples)
            + self.edges.len() * std::mem::size_of::<EdgePixel>()
    }
}

/// The sub-pixel samples of a pixel whose n×n sub-pixels mix real and
/// virtual surfaces, with their light terms appended to `terms`; `None`
/// where they do not mix. `real`: the pixel's own real point when its
/// centre sees it, whose light terms the real sub-pixels on its plane take
/// (no rays of their own; their terms here are left empty). Returns rays cast.
fn edge_samples(
    input: &PdaInput,
    col: u32,
    row: u32,
    seed: u64,
    real: Option<&SurfacePoint>,
    terms: &mut Vec<LightTerm>,
) -> (Option<Vec<SurfacePoint>>, u64) {
    let n = input.settings.supersample;
    if n <= 1 {
        return (None, 0);
    }
    let (mixed, visible, mut rays) = sub_pixels_mix(input, col, row, n);
    if !mixed {
        return (None, rays);
    }
    let (subs, traced) = sub_points(input, col, row, n, &visible);
    rays += traced;
    let mut kept: Vec<SurfacePoint> = Vec::new();
    let lights = input.lights.len();
    // Each kept sub-pixel holds `lights` terms from here on.
    let base = terms.len();
    for (k, s) in subs.into_iter().enumerate() {
        // A sub-pixel that sees nothing counts as the photo's background.
        if let Some(mut p) = s {
            p.pixel_terms = !p.is_virtual
                && real.is_some_and(|r| r.surface == p.surface && r.normal.dot(p.normal) > 0.999);
            // Sub-pixels on one plane share the light of the first of them:
            // within a pixel's footprint it differs by less than the shadow
            // rays' own noise, and each would cost a full set of rays.
            let first = kept.iter().position(|q| {
                !q.pixel_terms && q.surface == p.surface && q.normal.dot(p.normal) > 0.999
            });
            match first {
                _ if p.pixel_terms => {
                    terms.extend(std::iter::repeat_n(LightTerm::default(), lights))
                }
                Some(j) => terms.extend_from_within(base + j * lights..base + (j + 1) * lights),
                None => rays += input.terms(&p, hash2(seed, 100 + k as u64), terms, None),
            }
            kept.push(p);
        }
    }
    (Some(kept), rays)
}

/// Whether some of a pixel's n×n sub-pixels see a virtual object and some
/// do not. The sub-rays meet the objects alone first (a few triangles);
/// only those that hit one ask the room whether a real surface is nearer,
/// with an occlusion query that stops at the object. Most pixels near an
/// object's image are decided by the first step, or need only short rays.
/// Returns the answer, each sub-ray's object hit where no real surface
/// hides it (what [`sub_points`] takes as found), and the rays cast.
fn sub_pixels_mix(input: &PdaInput, col: u32, row: u32, n: u32) -> (bool, Vec<Option<Hit>>, u64) {
    // A packet's worth at a time: the arrays stay small whatever n is.
    const PACKET: usize = 16;
    let count = (n * n) as usize;
    let cam = input.camera;
    let (mut seen, mut rays_cast) = (0, 0u64);
    let mut visible = vec![None; count];
    for start in (0..count).step_by(PACKET) {
        let len = PACKET.min(count - start);
        let mut rays = [TraceRay::new(glam::Vec3::ZERO, glam::Vec3::Z); PACKET];
        for (k, ray) in (start..start + len).zip(rays.iter_mut()) {
            *ray = sub_ray(cam, col, row, n, k as u32).0;
        }
        let mut hits = [None; PACKET];
        input
            .tracer
            .intersect_batch(&rays[..len], Layer::Virtual, &mut hits[..len]);
        rays_cast += len as u64;
        // Of the sub-rays meeting an object, those a real surface hides before it.
        let mut short = [TraceRay::new(glam::Vec3::ZERO, glam::Vec3::Z); PACKET];
        let mut at = [0usize; PACKET];
        let mut m = 0;
        for (k, (ray, hit)) in rays[..len].iter().zip(&hits[..len]).enumerate() {
            if let Some(h) = hit {
                short[m] = TraceRay { tfar: h.t, ..*ray };
                at[m] = k;
                m += 1;
            }
        }
        if m > 0 {
            let mut hidden = [false; PACKET];
            input
                .tracer
                .occluded_batch(&short[..m], Layer::Real, &mut hidden[..m]);
            rays_cast += m as u64;
            for (&k, hidden) in at[..m].iter().zip(&hidden[..m]) {
                if !hidden {
                    visible[start + k] = hits[k];
                    seen += 1;
                }
            }
        }
    }
    (seen > 0 && seen < count, visible, rays_cast)
}

/// Sub-ray k of a pixel's n×n (row by row), for the tracer and in double precision.
fn sub_ray(cam: &Camera, col: u32, row: u32, n: u32, k: u32) -> (TraceRay, DVec3, DVec3) {
    let (i, j) = (k % n, k / n);
    let r = cam.ray(
        col as f64 + (i as f64 + 0.5) / n as f64,
        row as f64 + (j as f64 + 0.5) / n as f64,
    );
    (
        TraceRay::new(r.origin.as_vec3(), r.direction.as_vec3()),
        r.origin,
        r.direction,
    )
}

/// The pixels whose sub-pixels may mix real and virtual surfaces, as a
/// mask over the image, or `None` when every pixel near an object's image
/// must be tested. With no real surface between the camera and an object's
/// box, which of a pixel's sub-rays meet the object changes only across
/// the projected edges of the object's polygons: a pixel no edge comes
/// near sees the object through all its sub-pixels or through none. Real
/// geometry in front of the box (or cutting into it) draws boundaries of
/// its own, so then every pixel is tested, as is an object reaching behind
/// the camera.
fn edge_candidates(input: &PdaInput) -> Option<Vec<bool>> {
    let cam = input.camera;
    let patches = input.patches;
    let is_virtual = |r: &u32| patches.is_virtual_element(*r);
    for (lo, hi) in input.bounds.objects.iter().map(|o| &o.aabb) {
        let mut ends = vec![cam.position];
        ends.extend(box_corners(*lo, *hi));
        let hull = Shaft::hull(&ends);
        let (hlo, hhi) = (lo.min(cam.position), hi.max(cam.position));
        let in_front = patches.roots.iter().filter(|r| !is_virtual(r)).any(|&r| {
            let shape = &patches.elements[r as usize].shape;
            let (rlo, rhi) = shape.bounds();
            !(rlo.cmpgt(hhi).any() || rhi.cmplt(hlo).any() || hull.excludes(&shape.corners()))
        });
        if in_front {
            return None;
        }
    }
    let (w, h) = (cam.width, cam.height);
    let mut marks = vec![false; (w * h) as usize];
    // Within this many pixels of an edge a sub-ray may fall either side
    // once the tracer's single precision has rounded it.
    const MARGIN: f64 = 0.01;
    let roots: Vec<&crate::patches::Element> = patches
        .roots
        .iter()
        .filter(|r| is_virtual(r))
        .map(|&r| &patches.elements[r as usize])
        .collect();
    let edges = interior_edges(cam, &roots);
    for root in &roots {
        let corners = root.shape.corners();
        let projected: Option<Vec<(f64, f64)>> = corners
            .iter()
            .map(|c| cam.project(*c).map(|(x, y, _)| (x, y)))
            .collect();
        let projected = projected?;
        for (k, a) in projected.iter().enumerate() {
            if !edges.contains(&edge_key(corners[k], corners[(k + 1) % corners.len()])) {
                mark_segment(
                    &mut marks,
                    w,
                    h,
                    *a,
                    projected[(k + 1) % projected.len()],
                    MARGIN,
                );
            }
        }
    }
    Some(marks)
}

/// An edge by its two ends' bits, in either order.
type EdgeKey = [[u64; 3]; 2];

fn edge_key(a: DVec3, b: DVec3) -> EdgeKey {
    let bits = |v: DVec3| v.to_array().map(f64::to_bits);
    let (a, b) = (bits(a), bits(b));
    if a <= b { [a, b] } else { [b, a] }
}

/// The objects' polygon edges that are no silhouette for `cam`: whole
/// edges (the same ends, bit for bit) of exactly two polygons that lie on
/// either side of the edge in the image. A convex polygon lies wholly on
/// one side of each of its edges, so a sub-pixel on either side of such an
/// edge sees one of the two (or something nearer), and no pixel along it
/// mixes objects and room but where it meets an outline edge, which marks
/// those. Decided in the image, not by the polygons' normals: a fold of an
/// open surface can hide one side behind the other whichever way its
/// normals turn. A polygon seen edge-on, or behind the camera, is on
/// neither side; edges matched only in part count as outline.
fn interior_edges(cam: &Camera, roots: &[&crate::patches::Element]) -> HashSet<EdgeKey> {
    // Per edge: how many polygons hold it, and which sides of it they lie on.
    let mut sides: HashMap<EdgeKey, (u32, bool, bool)> = HashMap::new();
    let flat = |p: Option<(f64, f64, f64)>| p.map(|(x, y, _)| glam::DVec2::new(x, y));
    for e in roots {
        let centre = flat(cam.project(e.centre));
        let corners = e.shape.corners();
        for k in 0..corners.len() {
            let key = edge_key(corners[k], corners[(k + 1) % corners.len()]);
            let [a, b] = key.map(|v| flat(cam.project(DVec3::from_array(v.map(f64::from_bits)))));
            let side = match (a, b, centre) {
                (Some(a), Some(b), Some(c)) => {
                    let cross = (b - a).perp_dot(c - a);
                    // Within rounding of the line: edge-on.
                    let size = (b - a).length() * (c - a).length();
                    if cross.abs() <= 1e-9 * size {
                        0
                    } else {
                        cross.signum() as i32
                    }
                }
                _ => 0,
            };
            let entry = sides.entry(key).or_insert((0, false, false));
            entry.0 += 1;
            entry.1 |= side < 0;
            entry.2 |= side > 0;
        }
    }
    // Two polygons, one strictly on each side.
    sides
        .into_iter()
        .filter(|(_, (count, left, right))| *count == 2 && *left && *right)
        .map(|(edge, _)| edge)
        .collect()
}

/// Marks every pixel whose square comes within `margin` of segment a–b.
fn mark_segment(marks: &mut [bool], w: u32, h: u32, a: (f64, f64), b: (f64, f64), margin: f64) {
    let (y_lo, y_hi) = (a.1.min(b.1) - margin, a.1.max(b.1) + margin);
    let first = y_lo.floor().max(0.0);
    let last = y_hi.floor().min(h as f64 - 1.0);
    if first > last {
        return;
    }
    let at = |t: f64| (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
    for row in first as u32..=last as u32 {
        // The part of the segment within the row's band, margin included.
        let (band_lo, band_hi) = (row as f64 - margin, row as f64 + 1.0 + margin);
        let (t0, t1) = if b.1 == a.1 {
            (0.0, 1.0)
        } else {
            let (ta, tb) = ((band_lo - a.1) / (b.1 - a.1), (band_hi - a.1) / (b.1 - a.1));
            (ta.min(tb).max(0.0), ta.max(tb).min(1.0))
        };
        if t0 > t1 {
            continue;
        }
        let (x0, x1) = (at(t0).0, at(t1).0);
        let (x_lo, x_hi) = (x0.min(x1) - margin, x0.max(x1) + margin);
        if x_hi < 0.0 || x_lo > w as f64 - 1e-9 {
            continue;
        }
        let c0 = x_lo.floor().max(0.0) as u32;
        let c1 = (x_hi.floor().max(0.0) as u32).min(w - 1);
        for col in c0..=c1 {
            marks[(row * w + col) as usize] = true;
        }
    }
}

/// The n×n sub-pixel surface points of a pixel (None where a ray leaves
/// the scene), given the object each sub-ray sees ([`sub_pixels_mix`]):
/// only the others are traced, through the room. Returns the points and
/// the rays cast.
fn sub_points(
    input: &PdaInput,
    col: u32,
    row: u32,
    n: u32,
    visible: &[Option<Hit>],
) -> (Vec<Option<SurfacePoint>>, u64) {
    let cam = input.camera;
    let rays: Vec<(TraceRay, DVec3, DVec3)> =
        (0..n * n).map(|k| sub_ray(cam, col, row, n, k)).collect();
    let rest: Vec<usize> = (0..rays.len()).filter(|&k| visible[k].is_none()).collect();
    let traced: Vec<TraceRay> = rest.iter().map(|&k| rays[k].0).collect();
    let mut hits = visible.to_vec();
    let mut real = vec![None; traced.len()];
    input
        .tracer
        .intersect_batch(&traced, Layer::Real, &mut real);
    for (&k, h) in rest.iter().zip(real) {
        hits[k] = h;
    }
    let points = hits
        .iter()
        .zip(&rays)
        .map(|(h, r)| h.as_ref().and_then(|h| input.point(h, r.1, r.2)))
        .collect();
    (points, traced.len() as u64)
}

/// A pixel rectangle, inclusive.
#[derive(Debug, Clone, Copy)]
struct PixelBox {
    x0: u32,
    y0: u32,
    x1: u32,
    y1: u32,
}

impl PixelBox {
    fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && x <= self.x1 && y >= self.y0 && y <= self.y1
    }
}

/// The image boxes of the virtual objects' bounds, one pixel wider; a box
/// reaching behind the camera covers the whole image.
fn screen_boxes(cam: &Camera, bounds: &VirtualBounds) -> Vec<PixelBox> {
    bounds
        .objects
        .iter()
        .map(|o| {
            let (lo, hi) = &o.aabb;
            let projected: Option<Vec<(f64, f64)>> = box_corners(*lo, *hi)
                .iter()
                .map(|c| cam.project(*c).map(|(x, y, _)| (x, y)))
                .collect();
            let full = PixelBox {
                x0: 0,
                y0: 0,
                x1: cam.width - 1,
                y1: cam.height - 1,
            };
            let Some(pts) = projected else { return full };
            let (mut x0, mut y0, mut x1, mut y1) = (
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            );
            for (x, y) in pts {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
            }
            let clamp = |v: f64, max: u32| (v.floor().max(0.0) as u32).min(max);
            PixelBox {
                x0: clamp(x0 - 1.0, cam.width - 1),
                y0: clamp(y0 - 1.0, cam.height - 1),
                x1: clamp(x1 + 1.0, cam.width - 1),
                y1: clamp(y1 + 1.0, cam.height - 1),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests;
