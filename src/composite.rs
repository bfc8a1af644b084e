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
    pub camera: &'a crate::camera::Camera,
    pub photo: &'a Image,
    /// The photo with its grain smoothed out ([`grain::smoothed`]): where
    /// a change adds direct light, the added part is this times the ratio,
    /// so the photo's grain is not scaled up with it. None: the photo.
    pub photo_base: Option<&'a Image>,
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
    /// The "without" irradiance under which a ratio is not trusted (and
    /// the additive form is taken): one value for the whole frame, so that
    /// a crop or a band composites as the frame does.
    pub floor: DVec3,
    /// Every real point's composite as prepared before (see
    /// [`RealPixels`]), kept between updates; None: prepared here.
    pub known: Option<&'a RealPixels>,
    /// Objects with materials, shaded per pixel by their BRDF (None: every
    /// object is diffuse clay, `reflectance × (E + H) / π`).
    pub objects: Option<&'a crate::object_shading::ObjectShading<'a>>,
    /// The objects' change near them, finer than the patches (see
    /// [`crate::radiosity::NearField`]; None: none).
    pub near: Option<&'a crate::radiosity::NearField>,
    /// What rounds of per-pixel samples found ([`crate::residual`]): the
    /// objects' pixels' gathered light and the room's per-pixel change,
    /// in place of the interpolated ones (None: none ran).
    pub residual: Option<&'a crate::residual::PixelResidual>,
    /// The objects' points shaded before the composite (a session's, some
    /// read again over kept samples); None: shaded here.
    pub shaded: Option<&'a crate::object_shading::kept::ShadedPoints>,
    /// Which layers to fill beside the image and its alpha.
    pub layers: Layers,
}

/// The layers a composite fills beside the image and its alpha: those left
/// out are held empty. Filling them all is a tenth to a fifth of an
/// update's composite (a sixth of a desk box's drag step).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layers {
    /// Direct, indirect, change and the objects' own light: what `render`
    /// writes.
    All,
    /// The objects' own light alone: what the shadow-catcher factor
    /// ([`Composite::shadow`]) needs, as a session in `serve` shows it.
    Object,
    /// None: what a motion writes.
    None,
}

/// The augmented photo and its layers: rows `first_row..first_row +
/// image.height` of the frame (all of them, but for a crop or a band).
#[derive(Debug, Clone, PartialEq)]
pub struct Composite {
    /// The frame's row that the layers' first row is.
    pub first_row: u32,
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
    /// Per pixel, the estimated standard deviation of its radiance's
    /// luminance left by the rounds of per-pixel samples (empty: none ran).
    pub noise: Vec<f32>,
}

/// One sample's shading.
#[derive(Clone, Copy)]
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
    /// Pixel `i`'s photo value and the base a brightening scales.
    fn photo_at(&self, i: usize) -> (DVec3, DVec3) {
        let photo = self.photo.pixels[i].as_dvec3();
        (
            photo,
            self.photo_base.map_or(photo, |b| b.pixels[i].as_dvec3()),
        )
    }

    /// [`CompositeInput::photo_at`] where the camera sees `x` within pixel
    /// `i`, bilinear between the pixels' centres: a sub-pixel along an
    /// object's outline sees its part of the pixel, not the pixel's mean
    /// (against a wall's steep gradient by a lamp they differ by a third).
    fn photo_at_point(&self, i: usize, x: DVec3) -> (DVec3, DVec3) {
        let Some((px, py, _)) = self.camera.project(x) else {
            return self.photo_at(i);
        };
        if !(px.is_finite() && py.is_finite()) {
            return self.photo_at(i);
        }
        let photo = self.photo.bilinear(px, py);
        let out = (photo, self.photo_base.map_or(photo, |b| b.bilinear(px, py)));
        if out.0.is_finite() && out.1.is_finite() {
            out
        } else {
            self.photo_at(i)
        }
    }

    /// A real point's composite, from its pixel's photo value and base ([`CompositeInput::photo_at`]).
    fn real_pixel(
        &self,
        p: &SurfacePoint,
        terms: &[LightTerm],
        (photo, base): (DVec3, DVec3),
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
            if ratio && without[c] > floor[c] && e_w[c] > e_wo[c] {
                // Light added here: photo + base·(with / without − 1).
                offset[c] = photo[c] + base[c] * (e_w[c] / without[c] - 1.0);
                slope[c] = base[c] / without[c];
            } else if ratio && without[c] > floor[c] {
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

    /// A virtual point's shade; `share`: the fraction of its pixel it
    /// stands for; what the rounds found there (none: interpolated from
    /// the vertices, the material sampled here).
    fn shade_virtual(
        &self,
        p: &SurfacePoint,
        terms: &[LightTerm],
        share: f64,
        rounds: Rounds,
    ) -> Shade {
        let gathered = rounds.irradiance;
        let e_w = self.irradiance(terms, self.scales_with, true);
        // Not negative (see `RealPixel::shade`).
        let h_w = (gathered.unwrap_or_else(|| self.interpolate(self.indirect_with, &p.location)))
            .max(DVec3::ZERO);
        let rho = self.reflectance[p.location.patch as usize];
        let value = rounds
            .radiance
            .or_else(|| (self.objects).and_then(|o| o.radiance_with(p, share, gathered)))
            .unwrap_or_else(|| rho * (e_w + h_w) / std::f64::consts::PI);
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

/// What the residual's rounds found at an object's point.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Rounds {
    /// Its indirect irradiance gathered at the pixel.
    pub irradiance: Option<DVec3>,
    /// Its material's radiance sampled over the pixel.
    pub radiance: Option<DVec3>,
}

/// One pixel's layers for [`Composite::fill`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PixelShade {
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
    pub(crate) fn fill(
        &mut self,
        photo: &Image,
        counted: crate::image_io::PixelRect,
        shade: impl Fn(usize) -> PixelShade + Sync + Send,
    ) {
        // By rows: a plain loop per row, rather than five zipped parallel
        // iterators per pixel (whose bookkeeping cost as much as the shading).
        let w = (self.image.width as usize).max(1);
        let first = self.first_row as usize * w;
        let first_row = self.first_row as usize;
        // Only `counted`'s pixels: a crop's or a band's margin is another's.
        let count = |counts: &mut (usize, usize, usize), s: &PixelShade, row: usize, x: usize| {
            if counted.contains(x as u32, (first_row + row) as u32) {
                counts.0 += s.copied as usize;
                counts.1 += s.fallback as usize;
                counts.2 += s.clamped as usize;
            }
        };
        let sum =
            |a: (usize, usize, usize), b: (usize, usize, usize)| (a.0 + b.0, a.1 + b.1, a.2 + b.2);
        let layers = self.direct.pixels.len() == self.image.pixels.len();
        let object_held = self.object.pixels.len() == self.image.pixels.len();
        let rows = self
            .image
            .pixels
            .par_chunks_mut(w)
            .zip(self.alpha.par_chunks_mut(w))
            .enumerate();
        let (copied, fallbacks, clamped) = if !layers {
            // The object layer alone may be held (see [`Layers::Object`]).
            let objects = object_held.then(|| self.object.pixels.par_chunks_mut(w));
            let row = |(row, (image, alpha)): (usize, (&mut [Vec3], &mut [f32])),
                       mut object: Option<&mut [Vec3]>| {
                let mut counts = (0, 0, 0);
                for x in 0..image.len() {
                    let s = shade(first + row * w + x);
                    image[x] = s.value;
                    alpha[x] = s.alpha;
                    if let Some(o) = object.as_deref_mut() {
                        o[x] = s.object;
                    }
                    count(&mut counts, &s, row, x);
                }
                counts
            };
            match objects {
                Some(objects) => rows
                    .zip(objects)
                    .map(|(r, o)| row(r, Some(o)))
                    .reduce(|| (0, 0, 0), sum),
                None => rows.map(|r| row(r, None)).reduce(|| (0, 0, 0), sum),
            }
        } else {
            rows.zip(self.direct.pixels.par_chunks_mut(w))
                .zip(self.indirect.pixels.par_chunks_mut(w))
                .zip(self.change.pixels.par_chunks_mut(w))
                .zip(self.object.pixels.par_chunks_mut(w))
                .map(
                    |(((((row, (image, alpha)), direct), indirect), change), object)| {
                        let mut counts = (0, 0, 0);
                        for x in 0..image.len() {
                            let i = first + row * w + x;
                            let s = shade(i);
                            image[x] = s.value;
                            direct[x] = s.direct;
                            indirect[x] = s.indirect;
                            change[x] = s.value - photo.pixels[i];
                            object[x] = s.object;
                            alpha[x] = s.alpha;
                            count(&mut counts, &s, row, x);
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
        let first = self.first_row as usize * self.image.width as usize;
        for (i, s) in out.pixels.iter_mut().enumerate() {
            *s = self.shadow_at(i, photo.pixels[first + i]);
        }
        out
    }

    /// How many of `rect`'s pixels (rows within this composite's) are the
    /// photo's, bit for bit: a tile's count where the composite counted
    /// the whole frame (the texture path's).
    pub fn unchanged_in(&self, rect: crate::image_io::PixelRect, photo: &Image) -> usize {
        let w = self.image.width as usize;
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        (rect.y0..rect.y1)
            .flat_map(|y| (rect.x0..rect.x1).map(move |x| (x as usize, y as usize)))
            .filter(|&(x, y)| {
                let local = (y - self.first_row as usize) * w + x;
                bits(self.image.pixels[local]) == bits(photo.pixels[y * w + x])
            })
            .count()
    }

    /// [`Composite::shadow`] at its pixel `i`, whose photo value is `photo`.
    pub fn shadow_at(&self, i: usize, photo: Vec3) -> Vec3 {
        let object = self.object.pixels.get(i).copied().unwrap_or(Vec3::ZERO);
        let value = self.image.pixels[i] - object;
        let s = Vec3::select(photo.cmpgt(Vec3::ZERO), value / photo, Vec3::ONE);
        if s.is_finite() { s } else { Vec3::ONE }
    }

    /// The photo itself, with its layers: no change anywhere.
    pub fn unchanged(photo: &Image) -> Composite {
        let (w, h, n) = (photo.width, photo.height, photo.pixels.len());
        Composite {
            first_row: 0,
            image: photo.clone(),
            direct: Image::new(w, h),
            indirect: Image::new(w, h),
            change: Image::new(w, h),
            object: Image::new(w, h),
            alpha: vec![0.0; n],
            copied: n,
            ratio_fallbacks: 0,
            clamped: 0,
            noise: Vec::new(),
        }
    }

    /// No pixels yet.
    pub fn empty() -> Composite {
        Composite {
            first_row: 0,
            image: Image::new(0, 0),
            direct: Image::new(0, 0),
            indirect: Image::new(0, 0),
            change: Image::new(0, 0),
            object: Image::new(0, 0),
            alpha: Vec::new(),
            copied: 0,
            ratio_fallbacks: 0,
            clamped: 0,
            noise: Vec::new(),
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
pub(crate) fn composite_into(input: &CompositeInput, out: &mut Composite) {
    let shader = Shader::new(input);
    let (first_row, end) = input.pda.rows;
    let (w, h) = (input.pda.width, end - first_row);
    let n = (w * h) as usize;
    if out.image.pixels.len() != n || out.alpha.len() != n || out.first_row != first_row {
        *out = Composite {
            first_row,
            image: Image::new(w, h),
            alpha: vec![0.0; n],
            ..Composite::empty()
        };
    }
    let all = input.layers == Layers::All;
    let object = input.layers != Layers::None;
    let layer = |kept: bool| match kept {
        true => Image::new(w, h),
        false => Image::new(0, 0),
    };
    if (out.direct.pixels.len() == n) != all {
        (out.direct, out.indirect, out.change) = (layer(all), layer(all), layer(all));
    }
    if (out.object.pixels.len() == n) != object {
        out.object = layer(object);
    }
    // Most pixels show a real point alone: their indirect light is
    // interpolated in single precision, which the layers keep anyway (in
    // double precision, through an iterator, it took a third of the time).
    let h_with = patch_corners(input.indirect_with, input.patch_vertices);
    match input.known {
        Some(known) if !all => shader.image_only(known, &h_with, out),
        _ => out.fill(input.photo, input.pda.own, |i| {
            shader.plain(i, &h_with).unwrap_or_else(|| shader.other(i))
        }),
    }
    if input.near.is_some() || input.residual.is_some() {
        near::refine(&shader, input.near, input.residual, &h_with, out);
    }
    let found;
    let seams = match input.known {
        Some(known) => &known.seams,
        None => {
            found = seams::seam_pixels(input.pda);
            &found
        }
    };
    let no_object = |i: usize| shader.shows_no_object(i);
    seams::smooth_seams(input.pda, input.photo, seams, &no_object, out);
}

pub mod grain;
mod near;
mod real_pixels;
pub(crate) mod seams;
mod shader;

use real_pixels::*;
pub use real_pixels::{RealPixel, RealPixels};
use shader::Shader;

#[cfg(test)]
mod tests;
