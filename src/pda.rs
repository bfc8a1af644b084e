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

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::geometry::box_corners;
use crate::image_io::{CropWindow, PixelRect};
use crate::light::{LightSource, offset_origin, segment};
pub(crate) use crate::objects::CLEAR_TEST_LIMIT;
pub use crate::objects::{VirtualBounds, own_blocks};
use crate::patches::Patches;
use crate::shaft::Shaft;
use crate::trace::{Hit, Layer, TraceRay, Tracer};
use crate::util::rng::hash2;
pub use by_patch::RealByPatch;

/// Ray budget of the visibility oracle and the edge supersampling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdaSettings {
    /// 2^min_level shadow rays per rect light everywhere.
    pub min_level: usize,
    /// 2^penumbra_level where the first rays disagree.
    pub penumbra_level: usize,
    /// n×n sub-pixels tested (and shaded where they mix real and virtual).
    pub supersample: u32,
    /// Only the pixels of this window get data (`render --crop`); every
    /// pixel's data is what the whole frame gives it, bit for bit.
    pub crop: Option<CropWindow>,
}

impl Default for PdaSettings {
    fn default() -> Self {
        PdaSettings {
            min_level: 2,
            penumbra_level: 4,
            supersample: 4,
            crop: None,
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
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PixelDataArray {
    pub width: u32,
    pub height: u32,
    pub light_count: usize,
    /// Sub-pixels per side of an edge pixel.
    pub supersample: u32,
    /// The pixels it is for (the whole image, a crop, a band): the
    /// composite counts these.
    pub own: PixelRect,
    /// The rows the per-pixel arrays hold (the whole image, or a band or
    /// crop with its margin): pixel `i`'s entry is at `i − rows.0 × width`.
    pub rows: (u32, u32),
    /// Per pixel held, index into `real` (u32::MAX: no real surface);
    /// read through [`PixelDataArray::real_at`].
    pub real_index: Vec<u32>,
    /// Per pixel held, how far along its centre ray the real hit lies, as
    /// the tracer reported it (∞: none): an update traces that ray through
    /// the objects alone, only as far, instead of through the room again.
    /// Kept for updates only (empty for a still).
    pub real_t: Vec<f32>,
    pub real: Samples,
    /// Per real point and light (as `real.terms`), its shadow rays' real blockers.
    pub real_masks: Vec<RealMask>,
    /// Per pixel held, index into `virtual_samples` (u32::MAX: no virtual
    /// surface in front); read through [`PixelDataArray::virtual_at`].
    pub virtual_index: Vec<u32>,
    /// The pixels `virtual_index` holds, in pixel order.
    pub virtual_pixels: Vec<u32>,
    pub virtual_samples: Samples,
    /// Pixels whose sub-pixels mix real and virtual surfaces, in pixel order.
    pub edges: Vec<EdgePixel>,
    pub edge_samples: Samples,
    /// Shadow and sub-pixel rays traced.
    pub rays: u64,
    /// The pixels the last update re-traced (sorted), and whether every
    /// pixel was a candidate for an edge then; None before the first.
    pub examined: Option<(Vec<u32>, bool)>,
    /// The real points by patch, made when first asked for
    /// ([`PixelDataArray::real_by_patch`]; derived, so equality ignores it).
    by_patch: by_patch::ByPatchCache,
}

const NONE: u32 = u32::MAX;

/// Surface points or polygons whose normals' cosine exceeds this lie on
/// one plane, and share their light within a pixel; beyond it (2.6°,
/// finer than the facets of any tessellated curve worth meshing: a
/// 48-segment cylinder turns 7.5° per facet; coarser than rounding) they
/// are shaded apart.
pub const SAME_PLANE_COS: f32 = 0.999;

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
    /// Keep each real point's real blockers ([`RealMask`]) and centre
    /// rays' lengths for updates after objects move; a still image has no
    /// use for them.
    pub for_updates: bool,
    /// Only these rows (of the crop, if any): a band of a still rendered
    /// band by band. Its data reaches the seams' neighbourhood beyond.
    pub band: Option<(u32, u32)>,
    /// The object surfaces (sorted ids) whose pixels are shaded per pixel
    /// by their material ([`crate::object_shading`]): its samples spread
    /// over the pixel, each at its own point, so a pixel that sees only
    /// these needs no sub-pixels of its own however many facets cross it.
    pub shaded_per_pixel: &'a [u32],
}

/// How far past the pixels it is for the pixel data reaches, in pixels:
/// a later stage that reads a pixel's neighbours (the composite's seam
/// filter) reads no farther, so a tile's or a band's pixels are the whole
/// frame's. The stage checks its own reach against it.
pub const MARGIN: u32 = 5;

impl PdaInput<'_> {
    /// Whether surface `surface`'s pixels are shaded per pixel by a material.
    pub(crate) fn shades_per_pixel(&self, surface: u32) -> bool {
        self.shaded_per_pixel.binary_search(&surface).is_ok()
    }

    /// The pixels computed: [`PdaInput::own`]'s, and a margin beyond
    /// (their pixels read their neighbours' data in the seams' filter:
    /// computed that far beyond, they are the whole frame's).
    pub(crate) fn window(&self) -> PixelRect {
        let (w, h) = (self.camera.width, self.camera.height);
        self.own().grown(MARGIN, w, h)
    }

    /// The pixels the array is for: the crop's within the band, or all.
    pub(crate) fn own(&self) -> PixelRect {
        let (w, h) = (self.camera.width, self.camera.height);
        let mut r = self
            .settings
            .crop
            .and_then(|c| c.pixels(w, h))
            .unwrap_or(PixelRect::full(w, h));
        if let Some((y0, y1)) = self.band {
            (r.y0, r.y1) = (r.y0.max(y0), r.y1.min(y1).max(r.y0.max(y0)));
        }
        r
    }

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
                let query = LightQuery {
                    tracer: self.tracer,
                    light,
                    bounds: self.bounds,
                    settings: self.settings,
                };
                let point = TermPoint {
                    x,
                    n,
                    own,
                    seed: hash2(seed, l as u64),
                };
                let (term, r) = light_term(query, point, None, keep);
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

impl PixelDataArray {
    /// Builds the array for its crop's and band's pixels (all, without
    /// either), and a margin of the seams filter's reach beyond them.
    pub fn build(input: &PdaInput) -> PixelDataArray {
        let cam = input.camera;
        // Pixels near a virtual object's image are tested for mixed sub-pixels.
        let near_virtual = screen_boxes(cam, input.bounds);
        let candidates = if near_virtual.is_empty() {
            None
        } else {
            edge_candidates(input)
        };
        let tracer = RowTracer {
            input,
            near_virtual,
            candidates,
            window: input.window(),
        };
        let window = tracer.window;
        let rows: Vec<Row> = (window.y0..window.y1)
            .into_par_iter()
            .map(|row| tracer.row(row))
            .collect();
        let mut pda = PixelDataArray::assemble(input, (window.y0, window.y1), rows);
        pda.own = input.own();
        pda
    }

    /// Pixel `pixel`'s index into `real` (u32::MAX: none, or not held).
    pub fn real_at(&self, pixel: usize) -> u32 {
        self.slot(pixel)
            .and_then(|k| self.real_index.get(k))
            .copied()
            .unwrap_or(NONE)
    }

    /// Pixel `pixel`'s index into `virtual_samples` (u32::MAX: none, or not held).
    pub fn virtual_at(&self, pixel: usize) -> u32 {
        self.slot(pixel)
            .and_then(|k| self.virtual_index.get(k))
            .copied()
            .unwrap_or(NONE)
    }

    /// Where pixel `pixel`'s entries lie in the per-pixel arrays.
    fn slot(&self, pixel: usize) -> Option<usize> {
        pixel.checked_sub(self.first_pixel())
    }

    /// The frame's index of the first pixel held.
    pub fn first_pixel(&self) -> usize {
        self.rows.0 as usize * self.width as usize
    }

    /// Recomputes the light terms of the real points at `pixels` for
    /// `light` (after the virtual objects moved), exactly as [`build`]
    /// computes them; returns rays cast. `now` (sorted lists): the pixels
    /// whose shafts to the light may meet the objects where they are now,
    /// as the pixel-block traversals found them.
    ///
    /// [`build`]: PixelDataArray::build
    pub(crate) fn recompute_real_terms(
        &mut self,
        input: &PdaInput,
        pixels: &[u32],
        now: &[&[u32]],
        light: usize,
    ) -> u64 {
        if !input.active[light] {
            return 0;
        }
        let lights = self.light_count;
        let first = self.first_pixel();
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
                let k = real_index[pixel as usize - first];
                (k != NONE).then(|| {
                    let p = points[k as usize];
                    let at = k as usize * lights + light;
                    let seed = hash2(pixel as u64, 0x5A17);
                    let mut mask = masks.get(at).copied();
                    let query = LightQuery {
                        tracer: input.tracer,
                        light: &input.lights[light],
                        bounds: input.bounds,
                        settings: input.settings,
                    };
                    let point = TermPoint {
                        x: p.position.as_dvec3(),
                        n: p.normal.as_dvec3(),
                        own: None,
                        seed: hash2(seed, light as u64),
                    };
                    let before = (
                        terms[at].unoccluded,
                        now.iter().any(|n| n.binary_search(&pixel).is_ok()),
                    );
                    let (term, rays) = light_term(query, point, Some(before), mask.as_mut());
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
    /// the pixels examined. With `movers` (what moved since the last
    /// update), a pixel that update re-traced keeps its points and their
    /// light where no moved object comes near its camera rays or their
    /// shadow rays: what it would trace again is what it traced then.
    ///
    /// [`build`]: PixelDataArray::build
    pub(crate) fn rebuild_virtual(
        &mut self,
        input: &PdaInput,
        movers: Option<&dyn crate::objects::Movers>,
    ) -> (u64, u64) {
        let n = self.real_index.len();
        let first = self.first_pixel();
        // Reset in place, where the last placement set it: a fresh 0.8 MB
        // each update faulted its pages in again, and filling it all
        // wrote 0.8 MB to clear a few thousand entries.
        self.virtual_index.resize(n, NONE);
        for &pixel in &self.virtual_pixels {
            self.virtual_index[pixel as usize - first] = NONE;
        }
        // With nothing standing still nothing is kept: the arrays are
        // emptied in place, their room kept for the next placement.
        let movers = movers.filter(|m| m.any_unmoved());
        let old = match movers {
            Some(_) => Placed::take(self),
            None => Placed::cleared(self),
        };
        let boxes = screen_boxes(input.camera, input.bounds);
        let candidates = if boxes.is_empty() {
            None
        } else {
            edge_candidates(input)
        };
        let pixels = self.pixels_to_retrace(input, &boxes);
        let examined = self.examined.take();
        let keep: Vec<bool> = match (movers, &examined) {
            (Some(m), Some((before, all))) if *all == candidates.is_none() => {
                let reach = Reach::of(input);
                (pixels.par_iter())
                    .map(|&p| before.binary_search(&p).is_ok() && old.clear(input, m, (p, &reach)))
                    .collect()
            }
            _ => vec![false; pixels.len()],
        };
        let fresh: Vec<u32> = (pixels.iter().zip(&keep))
            .filter(|(_, k)| !**k)
            .map(|(p, _)| *p)
            .collect();
        let mut found = self
            .retrace(input, &fresh, candidates.as_deref())
            .into_iter();
        let mut rays = 0;
        for (&pixel, &kept) in pixels.iter().zip(&keep) {
            if kept {
                let (virt, edge) = old.at(pixel);
                if let Some((p, terms)) = virt {
                    self.push_virtual(pixel, p, terms);
                }
                if let Some((subs, terms)) = edge {
                    self.push_edge(pixel, subs, terms);
                }
                continue;
            }
            let (_, virt, edge, r) = found.next().expect("one per pixel traced");
            rays += r;
            if let Some((p, terms)) = virt {
                self.push_virtual(pixel, p, &terms);
            }
            if let Some((subs, terms)) = edge {
                self.push_edge(pixel, &subs, &terms);
            }
        }
        let examined = pixels.len() as u64;
        self.examined = Some((pixels, candidates.is_none()));
        (rays, examined)
    }

    /// How many of `window`'s pixels have a centre that sees a real surface.
    pub fn covered(&self, window: PixelRect) -> usize {
        (window.y0..window.y1)
            .flat_map(|y| (window.x0..window.x1).map(move |x| (x, y)))
            .filter(|&(x, y)| self.real_at((y * self.width + x) as usize) != NONE)
            .count()
    }

    /// Bytes held.
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
            + self.by_patch.memory_bytes()
            + samples(&self.virtual_samples)
            + samples(&self.edge_samples)
            + self.edges.len() * std::mem::size_of::<EdgePixel>()
    }
}

mod by_patch;
mod edges;
mod rows;
mod terms;

use edges::*;
use rows::*;
use terms::*;

#[cfg(test)]
mod tests;
