//! Differential rendering: the photo changed by what the model says the
//! change does ([`composite`]). Real pixels: `Additive`, photo + ρ·(L_with −
//! L_without) in irradiance terms (Debevec, Grosch §4), or `Ratio`, photo ×
//! L_with / L_without (the shadow catcher's form: a shadow darkens light and
//! dark texture by the same factor, not the same amount). Virtual pixels:
//! the virtual surface's radiance ρ·(E + H)/π. Pixels whose sub-pixels mix
//! real and virtual surfaces average their sub-pixels.
//!
//! A pixel whose direct light is unchanged and whose indirect light moved by
//! less than [`UNCHANGED_INDIRECT`] of its irradiance is the photo's pixel,
//! bit for bit. No negative or non-finite value leaves: a ratio whose
//! "without" irradiance is nearly zero (D ≈ 0) falls back to the additive
//! form, and additive results are clamped at zero (both counted).

use glam::{DVec3, Vec3, Vec3A};
use rayon::prelude::*;

use crate::image_io::Image;
use crate::light::LightSource;
use crate::pda::{LightTerm, PatchPoint, PixelDataArray, SurfacePoint};

/// Relative change of a pixel's irradiance below which only indirect
/// light moved and the photo's pixel is kept: 1e-3, a tenth of the ~1%
/// noise of a photograph.
pub const UNCHANGED_INDIRECT: f64 = 1e-3;

/// How real pixels take the change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CompositeMode {
    /// photo + ρ·(Δ irradiance)/π.
    Additive,
    /// photo × (light with) / (light without).
    Ratio,
}

/// What the compositor needs besides the PDA.
pub struct CompositeInput<'a> {
    pub pda: &'a PixelDataArray,
    pub photo: &'a Image,
    pub lights: &'a [LightSource],
    /// Each light's scale in the photo, and in the augmented scene.
    pub scales_without: &'a [f64],
    pub scales_with: &'a [f64],
    /// Indirect irradiance at the vertices of the photo's model, and of the
    /// augmented model (real vertices are numbered alike in both).
    pub indirect_without: &'a [DVec3],
    pub indirect_with: &'a [DVec3],
    /// Reflectance per patch of the augmented model, and each patch's vertices.
    pub reflectance: &'a [DVec3],
    pub patch_vertices: &'a [[u32; 4]],
    pub mode: CompositeMode,
    /// Every real point's composite as prepared before (see
    /// [`RealPixels`]), kept between updates; None: prepared here.
    pub known: Option<&'a RealPixels>,
    /// Fill the direct, indirect and change layers too; without them the
    /// composite holds them empty (a motion writes its images only, and
    /// filling them is a tenth to a fifth of an update's composite).
    pub layers: bool,
}

/// The augmented photo and its layers.
#[derive(Debug, Clone, PartialEq)]
pub struct Composite {
    pub image: Image,
    /// Direct and indirect irradiance of the surface seen, in the augmented scene.
    pub direct: Image,
    pub indirect: Image,
    /// image − photo (may be negative: a shadow).
    pub change: Image,
    /// The virtual objects alone, premultiplied by their coverage (zero
    /// where only real surfaces show): what a compositor merges "over".
    pub object: Image,
    /// Coverage of virtual surfaces per pixel, in [0, 1].
    pub alpha: Vec<f32>,
    /// Pixels copied from the photo unchanged.
    pub copied: usize,
    /// Real samples where the ratio fell back to the additive form (D ≈ 0).
    pub ratio_fallbacks: usize,
    /// Samples clamped at zero.
    pub clamped: usize,
}

/// One sample's shading.
struct Shade {
    value: DVec3,
    direct: DVec3,
    indirect: DVec3,
    copied: bool,
    fallback: bool,
    clamped: bool,
}

impl CompositeInput<'_> {
    fn irradiance(&self, terms: &[LightTerm], scales: &[f64], all: bool) -> DVec3 {
        let mut e = DVec3::ZERO;
        for ((t, light), &s) in terms.iter().zip(self.lights).zip(scales) {
            if s > 0.0 && t.unoccluded > 0.0 {
                e += light.colour() * (s * t.unoccluded as f64 * t.visible(all));
            }
        }
        e
    }

    fn interpolate(&self, values: &[DVec3], at: &PatchPoint) -> DVec3 {
        let vertices = &self.patch_vertices[at.patch as usize];
        vertices
            .iter()
            .zip(at.weights)
            .filter(|(_, w)| *w != 0.0)
            .map(|(&v, w)| values[v as usize] * w as f64)
            .sum()
    }

    /// A real surface point under the photo pixel `photo`, prepared for any
    /// indirect light; `floor` is the irradiance below which a ratio is not trusted.
    fn real_pixel(
        &self,
        p: &SurfacePoint,
        terms: &[LightTerm],
        photo: DVec3,
        floor: DVec3,
    ) -> RealPixel {
        let e_wo = self.irradiance(terms, self.scales_without, false);
        let h_wo = self.interpolate(self.indirect_without, &p.location);
        let e_w = self.irradiance(terms, self.scales_with, true);
        let without = e_wo + h_wo;
        let rho = self.reflectance[p.location.patch as usize];
        let pi = std::f64::consts::PI;
        let (mut offset, mut slope, mut fallback) = (DVec3::ZERO, DVec3::ZERO, false);
        for c in 0..3 {
            let ratio = self.mode == CompositeMode::Ratio;
            if ratio && without[c] > floor[c] {
                offset[c] = photo[c] * e_w[c] / without[c];
                slope[c] = photo[c] / without[c];
            } else {
                fallback |= ratio;
                offset[c] = photo[c] + rho[c] * (e_w[c] - without[c]) / pi;
                slope[c] = rho[c] / pi;
            }
        }
        let band = if e_w == e_wo {
            (without * UNCHANGED_INDIRECT).as_vec3()
        } else {
            Vec3::splat(-1.0)
        };
        debug_assert!(p.location.patch < FALLBACK);
        let patch = p.location.patch | if fallback { FALLBACK } else { 0 };
        RealPixel {
            affine: AffinePixel {
                offset: offset.as_vec3(),
                slope: slope.as_vec3(),
                patch,
                weights: p.location.weights,
            },
            keep: PhotoBand {
                h_without: h_wo.as_vec3(),
                band,
            },
        }
    }

    fn shade_virtual(&self, p: &SurfacePoint, terms: &[LightTerm]) -> Shade {
        let e_w = self.irradiance(terms, self.scales_with, true);
        let h_w = self.interpolate(self.indirect_with, &p.location);
        let rho = self.reflectance[p.location.patch as usize];
        let value = rho * (e_w + h_w) / std::f64::consts::PI;
        Shade {
            value,
            direct: e_w,
            indirect: h_w,
            copied: false,
            fallback: false,
            clamped: false,
        }
    }
}

/// One pixel's layers for [`Composite::fill`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelShade {
    pub value: Vec3,
    pub direct: Vec3,
    pub indirect: Vec3,
    pub alpha: f32,
    /// The virtual objects' part of `value`, premultiplied by `alpha`.
    pub object: Vec3,
    pub copied: bool,
    pub fallback: bool,
    pub clamped: bool,
}

impl Composite {
    /// Sets every pixel, in parallel, to `shade(pixel)` (the change layer
    /// is value − photo) and counts the copied, fallen-back and clamped
    /// ones. The direct, indirect and change layers are filled when the
    /// composite holds them (see [`CompositeInput::layers`]).
    pub fn fill(&mut self, photo: &Image, shade: impl Fn(usize) -> PixelShade + Sync + Send) {
        // By rows: a plain loop per row, rather than five zipped parallel
        // iterators per pixel (whose bookkeeping cost as much as the shading).
        let w = (self.image.width as usize).max(1);
        let count = |counts: &mut (usize, usize, usize), s: &PixelShade| {
            counts.0 += s.copied as usize;
            counts.1 += s.fallback as usize;
            counts.2 += s.clamped as usize;
        };
        let sum =
            |a: (usize, usize, usize), b: (usize, usize, usize)| (a.0 + b.0, a.1 + b.1, a.2 + b.2);
        let layers = self.direct.pixels.len() == self.image.pixels.len();
        let rows = self
            .image
            .pixels
            .par_chunks_mut(w)
            .zip(self.alpha.par_chunks_mut(w))
            .enumerate();
        let (copied, fallbacks, clamped) = if !layers {
            rows.map(|(row, (image, alpha))| {
                let mut counts = (0, 0, 0);
                for x in 0..image.len() {
                    let s = shade(row * w + x);
                    image[x] = s.value;
                    alpha[x] = s.alpha;
                    count(&mut counts, &s);
                }
                counts
            })
            .reduce(|| (0, 0, 0), sum)
        } else {
            rows.zip(self.direct.pixels.par_chunks_mut(w))
                .zip(self.indirect.pixels.par_chunks_mut(w))
                .zip(self.change.pixels.par_chunks_mut(w))
                .zip(self.object.pixels.par_chunks_mut(w))
                .map(
                    |(((((row, (image, alpha)), direct), indirect), change), object)| {
                        let mut counts = (0, 0, 0);
                        for x in 0..image.len() {
                            let i = row * w + x;
                            let s = shade(i);
                            image[x] = s.value;
                            direct[x] = s.direct;
                            indirect[x] = s.indirect;
                            change[x] = s.value - photo.pixels[i];
                            object[x] = s.object;
                            alpha[x] = s.alpha;
                            count(&mut counts, &s);
                        }
                        counts
                    },
                )
                .reduce(|| (0, 0, 0), sum)
        };
        self.copied = copied;
        self.ratio_fallbacks = fallbacks;
        self.clamped = clamped;
    }

    /// The shadow-catcher layer: what the change did to the real surfaces,
    /// as a factor on the photo, (image − object) / photo, 1 where nothing
    /// changed (and where the photo is black), 0 under an opaque object.
    /// A compositor rebuilds the image as photo × shadow + object.
    pub fn shadow(&self, photo: &Image) -> Image {
        let mut out = Image::new(self.image.width, self.image.height);
        let object = |i: usize| self.object.pixels.get(i).copied().unwrap_or(Vec3::ZERO);
        for (i, s) in out.pixels.iter_mut().enumerate() {
            let (value, p) = (self.image.pixels[i] - object(i), photo.pixels[i]);
            *s = Vec3::select(p.cmpgt(Vec3::ZERO), value / p, Vec3::ONE);
            if !s.is_finite() {
                *s = Vec3::ONE;
            }
        }
        out
    }

    /// No pixels yet.
    pub fn empty() -> Composite {
        Composite {
            image: Image::new(0, 0),
            direct: Image::new(0, 0),
            indirect: Image::new(0, 0),
            change: Image::new(0, 0),
            object: Image::new(0, 0),
            alpha: Vec::new(),
            copied: 0,
            ratio_fallbacks: 0,
            clamped: 0,
        }
    }
}

/// Composites every pixel.
pub fn composite(input: &CompositeInput) -> Composite {
    let mut out = Composite::empty();
    composite_into(input, &mut out);
    out
}

/// [`composite`] into `out`, reusing its buffers when they have the
/// image's size (an update rewrites the same image: no new pages to fault in).
pub fn composite_into(input: &CompositeInput, out: &mut Composite) {
    let pda = input.pda;
    let lights = pda.light_count;
    let (w, h) = (pda.width, pda.height);
    let n = (w * h) as usize;
    // Without prepared pixels (a still image) each is prepared as it is shaded.
    let floor = input
        .known
        .map_or_else(|| RealPixels::floor_of(input), |k| k.floor);
    // Per row, the columns from the first to past the last pixel showing
    // an object or mixing real and virtual sub-pixels (none: start ≥ end).
    // Outside them a pixel shows a real point alone, or nothing: most
    // pixels need neither the virtual index nor the edge list.
    let mut spans = vec![(u32::MAX, 0u32); h as usize];
    for &p in pda
        .virtual_pixels
        .iter()
        .chain(pda.edges.iter().map(|e| &e.pixel))
    {
        let (x, y) = (p % w, (p / w) as usize);
        spans[y] = (spans[y].0.min(x), spans[y].1.max(x + 1));
    }
    let in_span = |i: usize| {
        let (x0, x1) = spans[i / w as usize];
        (x0..x1).contains(&((i % w as usize) as u32))
    };
    // Edge pixels are in pixel order.
    let edge_at = |i: usize| {
        in_span(i)
            .then(|| {
                pda.edges
                    .binary_search_by_key(&(i as u32), |e| e.pixel)
                    .ok()
            })
            .flatten()
            .map(|k| pda.edges[k])
    };
    if out.image.pixels.len() != n || out.alpha.len() != n {
        *out = Composite {
            image: Image::new(w, h),
            alpha: vec![0.0; n],
            ..Composite::empty()
        };
    }
    let layer = || {
        if input.layers {
            Image::new(w, h)
        } else {
            Image::new(0, 0)
        }
    };
    if (out.direct.pixels.len() == n) != input.layers {
        (out.direct, out.indirect, out.change, out.object) = (layer(), layer(), layer(), layer());
    }
    // A pixel's shade, its virtual coverage and the objects' part of it.
    let shade = |i: usize| -> (Shade, f32, DVec3) {
        let photo = input.photo.pixels[i].as_dvec3();
        if let Some(e) = edge_at(i) {
            let mut sum = Shade {
                value: DVec3::ZERO,
                direct: DVec3::ZERO,
                indirect: DVec3::ZERO,
                copied: false,
                fallback: false,
                clamped: false,
            };
            let mut virtual_count = 0;
            let mut object = DVec3::ZERO;
            for k in e.start..e.start + e.count {
                let p = &pda.edge_samples.points[k as usize];
                let terms = match pda.real_index[i] {
                    r if p.pixel_terms && r != u32::MAX => {
                        &pda.real.terms[r as usize * lights..(r as usize + 1) * lights]
                    }
                    _ => &pda.edge_samples.terms[k as usize * lights..(k as usize + 1) * lights],
                };
                let s = if p.is_virtual {
                    virtual_count += 1;
                    let s = input.shade_virtual(p, terms);
                    object += s.value;
                    s
                } else {
                    let direct = input.irradiance(terms, input.scales_with, true);
                    input.real_pixel(p, terms, photo, floor).shade(
                        input.interpolate(input.indirect_with, &p.location),
                        photo,
                        direct,
                    )
                };
                sum.value += s.value;
                sum.direct += s.direct;
                sum.indirect += s.indirect;
                sum.fallback |= s.fallback;
                sum.clamped |= s.clamped;
            }
            // Sub-pixels that see no surface keep the photo's background.
            let total = (pda.supersample * pda.supersample) as f64;
            sum.value += photo * (total - e.count as f64);
            return (
                Shade {
                    value: sum.value / total,
                    direct: sum.direct / total,
                    indirect: sum.indirect / total,
                    ..sum
                },
                virtual_count as f32 / total as f32,
                object / total,
            );
        }
        if pda.virtual_index[i] != u32::MAX {
            let k = pda.virtual_index[i] as usize;
            let s = input.shade_virtual(
                &pda.virtual_samples.points[k],
                &pda.virtual_samples.terms[k * lights..(k + 1) * lights],
            );
            let object = s.value;
            return (s, 1.0, object);
        }
        (
            Shade {
                value: photo,
                direct: DVec3::ZERO,
                indirect: DVec3::ZERO,
                copied: true,
                fallback: false,
                clamped: false,
            },
            0.0,
            DVec3::ZERO,
        )
    };
    let photo = &input.photo.pixels;
    // Most pixels show a real point alone: their indirect light is
    // interpolated in single precision, which the layers keep anyway (in
    // double precision, through an iterator, it took a third of the time).
    let h_with = patch_corners(input.indirect_with, input.patch_vertices);
    let plain = |i: usize| -> Option<PixelShade> {
        let k = pda.real_index[i];
        if k == u32::MAX || in_span(i) && (pda.virtual_index[i] != u32::MAX || edge_at(i).is_some())
        {
            return None;
        }
        let k = k as usize;
        let r = match input.known {
            Some(known) => known.get(k),
            None => input.real_pixel(
                &pda.real.points[k],
                &pda.real.terms[k * lights..(k + 1) * lights],
                photo[i].as_dvec3(),
                floor,
            ),
        };
        let mut s = r.layers(
            interpolate_single(&h_with[r.patch()], r.affine.weights),
            &photo[i],
        );
        if input.layers {
            s.direct = input
                .irradiance(
                    &pda.real.terms[k * lights..(k + 1) * lights],
                    input.scales_with,
                    true,
                )
                .as_vec3();
        }
        Some(s)
    };
    let other = |i: usize| -> PixelShade {
        let (s, a, object) = shade(i);
        // Copied pixels keep the photo's exact bits.
        let value: Vec3 = if s.copied {
            photo[i]
        } else {
            s.value.as_vec3()
        };
        PixelShade {
            value,
            direct: s.direct.as_vec3(),
            indirect: s.indirect.as_vec3(),
            alpha: a,
            object: object.as_vec3(),
            copied: s.copied,
            fallback: s.fallback,
            clamped: s.clamped,
        }
    };
    match input.known {
        // An update's image alone: a row at a time over plain slices, the
        // prepared real pixels shaded in place (what `plain` does, without
        // a pixel's layers passed back).
        Some(known) if !input.layers => {
            let may_keep = known.may_keep(&h_with, input.patch_vertices);
            let tables = PlainTables {
                affine: &known.affine,
                bands: &known.keep,
                h_with: &h_with,
                may_keep: &may_keep,
                // With an object in the room nearly no patch may keep the
                // photo: then no pixel looks its patch up.
                any_keep: may_keep.iter().any(|k| *k),
            };
            let w = (w as usize).max(1);
            let rows = out
                .image
                .pixels
                .par_chunks_mut(w)
                .zip(out.alpha.par_chunks_mut(w))
                .enumerate();
            let counts = rows
                .map(|(row, (image, alpha))| {
                    let at = row * w..row * w + image.len();
                    let (real, virt, photo_row) = (
                        &pda.real_index[at.clone()],
                        &pda.virtual_index[at.clone()],
                        &photo[at],
                    );
                    // Outside the columns where objects or edges may show,
                    // every pixel is plain: a loop that asks nothing else.
                    let (x0, x1) = match spans[row] {
                        (a, b) if a < b => (a as usize, b as usize),
                        _ => (image.len(), image.len()),
                    };
                    let mut counts = Counts::default();
                    tables.run(
                        &mut image[..x0],
                        &mut alpha[..x0],
                        &real[..x0],
                        &photo_row[..x0],
                        &mut counts,
                    );
                    tables.run(
                        &mut image[x1..],
                        &mut alpha[x1..],
                        &real[x1..],
                        &photo_row[x1..],
                        &mut counts,
                    );
                    for x in x0..x1 {
                        let k = real[x];
                        if k == u32::MAX || virt[x] != u32::MAX || edge_at(row * w + x).is_some() {
                            let s = other(row * w + x);
                            image[x] = s.value;
                            alpha[x] = s.alpha;
                            counts.add(s.copied, s.fallback, s.clamped);
                            continue;
                        }
                        tables.pixel(
                            k as usize,
                            &photo_row[x],
                            &mut image[x],
                            &mut alpha[x],
                            &mut counts,
                        );
                    }
                    counts
                })
                .reduce(Counts::default, Counts::sum);
            (out.copied, out.ratio_fallbacks, out.clamped) =
                (counts.copied, counts.fallbacks, counts.clamped);
        }
        _ => out.fill(input.photo, |i| plain(i).unwrap_or_else(|| other(i))),
    }
}

mod real_pixels;

use real_pixels::*;
pub use real_pixels::{RealPixel, RealPixels};

#[cfg(test)]
mod tests;
