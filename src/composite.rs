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
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
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

/// A real point's composite, affine in the indirect irradiance with the
/// changes H: value = offset + slope·H per channel — the ratio form
/// photo·(E_with + H)/D, or the additive photo + ρ(E_with + H − D)/π where
/// D (the "without" irradiance) is under the floor or the mode says so —
/// and the band of H within which the photo's pixel stands (only where the
/// direct light is unchanged). Everything but H is fixed while objects
/// move, and this is all a pixel reads (not the PDA's point and terms).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealPixel {
    affine: AffinePixel,
    keep: PhotoBand,
}

/// A [`RealPixel`]'s affine part: 44 bytes, read for every pixel of every
/// update's composite.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AffinePixel {
    offset: Vec3,
    slope: Vec3,
    /// The patch the point lies in, with [`FALLBACK`] set where the ratio
    /// fell back to the additive form.
    patch: u32,
    weights: [f32; 4],
}

/// A [`RealPixel`]'s band: read by an update only where its patch's
/// corners say the photo's pixel may be kept ([`RealPixels::may_keep`];
/// with an object in the room, nearly nowhere: its indirect light moves
/// everything).
#[derive(Debug, Clone, Copy, PartialEq)]
struct PhotoBand {
    h_without: Vec3,
    /// Negative: the direct light changed, never the photo's pixel.
    band: Vec3,
}

/// [`AffinePixel::patch`]'s flag bit (patch numbers stay below it).
const FALLBACK: u32 = 1 << 31;

/// [`RealPixel`] per real point of the PDA, kept by a session with its
/// affine parts and bands apart (an update's composite reads 44 bytes a
/// pixel instead of 68), what `RealPixels::may_keep` asks per patch, and
/// the floor under which a ratio is not trusted (a thousandth of the mean
/// "without" irradiance).
#[derive(Debug, Clone, PartialEq)]
pub struct RealPixels {
    affine: Vec<AffinePixel>,
    keep: Vec<PhotoBand>,
    /// Per patch, the widest band of its pixels per channel (negative
    /// where none has one).
    widest_band: Vec<Vec3>,
    /// Per patch, the corners of the indirect light without the changes.
    without: Vec<[Vec3A; 4]>,
    pub floor: DVec3,
}

impl RealPixels {
    pub fn of(input: &CompositeInput) -> RealPixels {
        let pda = input.pda;
        let lights = pda.light_count;
        let floor = RealPixels::floor_of(input);
        let pixel_of: Vec<u32> = (0..pda.real_index.len() as u32)
            .filter(|&i| pda.real_index[i as usize] != u32::MAX)
            .collect();
        // Straight into the two halves: no image-sized list of whole pixels.
        let (affine, keep): (Vec<AffinePixel>, Vec<PhotoBand>) = pixel_of
            .par_iter()
            .enumerate()
            .map(|(k, &i)| {
                let r = input.real_pixel(
                    &pda.real.points[k],
                    &pda.real.terms[k * lights..(k + 1) * lights],
                    input.photo.pixels[i as usize].as_dvec3(),
                    floor,
                );
                (r.affine, r.keep)
            })
            .unzip();
        let mut known = RealPixels {
            affine,
            keep,
            widest_band: vec![Vec3::splat(-1.0); input.patch_vertices.len()],
            without: patch_corners(input.indirect_without, input.patch_vertices),
            floor,
        };
        for k in 0..known.affine.len() {
            known.widen(&known.get(k));
        }
        known
    }

    /// The floor under which a ratio is not trusted: a thousandth of the
    /// mean "without" irradiance of the real points.
    pub fn floor_of(input: &CompositeInput) -> DVec3 {
        let pda = input.pda;
        let lights = pda.light_count;
        let sum: DVec3 = pda
            .real
            .points
            .par_iter()
            .enumerate()
            .map(|(k, p)| {
                input.irradiance(
                    &pda.real.terms[k * lights..(k + 1) * lights],
                    input.scales_without,
                    false,
                ) + input.interpolate(input.indirect_without, &p.location)
            })
            .sum();
        sum / pda.real.points.len().max(1) as f64 * 1e-3
    }

    /// Prepares again the real points of `pixels`, whose light terms changed.
    pub fn refresh(&mut self, input: &CompositeInput, pixels: &[u32]) {
        let pda = input.pda;
        let lights = pda.light_count;
        for &i in pixels {
            let k = pda.real_index[i as usize];
            if k != u32::MAX {
                let k = k as usize;
                let r = input.real_pixel(
                    &pda.real.points[k],
                    &pda.real.terms[k * lights..(k + 1) * lights],
                    input.photo.pixels[i as usize].as_dvec3(),
                    self.floor,
                );
                (self.affine[k], self.keep[k]) = (r.affine, r.keep);
                self.widen(&r);
            }
        }
    }

    /// Widens the widest band of `r`'s patch to hold its band. It only
    /// grows: a band an earlier placement had costs at most a band read
    /// where it could not keep the photo.
    fn widen(&mut self, r: &RealPixel) {
        if let Some(b) = self
            .widest_band
            .get_mut(r.affine.patch())
            .filter(|_| r.keep.band.x >= 0.0)
        {
            *b = b.max(r.keep.band);
        }
    }

    /// Per patch, whether a pixel of it may keep the photo under the
    /// indirect light `with` (its corners, as [`patch_corners`] gives
    /// them). A pixel's indirect light moved by the weighted mean of its
    /// corners' moves (weights ≥ 0, summing to 1): where, in a channel,
    /// every corner moved the same way by more than the patch's widest band
    /// (and single precision's rounding), none of its pixels is within its
    /// band, and their bands need not be read.
    fn may_keep(&self, with: &[[Vec3A; 4]], vertices: &[[u32; 4]]) -> Vec<bool> {
        with.iter()
            .zip(&self.without)
            .zip(&self.widest_band)
            .zip(vertices)
            .map(|(((with, without), band), ids)| {
                if band.x < 0.0 {
                    return false;
                }
                let corners = if ids[3] == u32::MAX { 3 } else { 4 };
                let (mut above, mut below, mut size) = (
                    Vec3A::splat(f32::INFINITY),
                    Vec3A::splat(f32::NEG_INFINITY),
                    Vec3A::ZERO,
                );
                for (w, wo) in with[..corners].iter().zip(&without[..corners]) {
                    let moved = *w - *wo;
                    above = above.min(moved);
                    below = below.max(moved);
                    size = size.max(w.abs() + wo.abs());
                }
                let beyond = Vec3A::from(*band) + size * 1e-5 + Vec3A::splat(f32::MIN_POSITIVE);
                // NaN compares false: such a patch reads its bands.
                !(above.cmpgt(beyond).any() || below.cmplt(-beyond).any())
            })
            .collect()
    }

    fn get(&self, k: usize) -> RealPixel {
        RealPixel {
            affine: self.affine[k],
            keep: self.keep[k],
        }
    }
}

impl PhotoBand {
    /// Whether the photo's pixel stands at indirect irradiance `h`.
    #[inline]
    fn holds(&self, h: Vec3) -> bool {
        self.band.x >= 0.0 && (h - self.h_without).abs().cmple(self.band).all()
    }
}

impl AffinePixel {
    fn fallback(&self) -> bool {
        self.patch & FALLBACK != 0
    }

    fn patch(&self) -> usize {
        (self.patch & !FALLBACK) as usize
    }

    /// The value in single precision, as the image takes it: (value,
    /// copied, clamped), where `keep` is the pixel's band when it may hold
    /// h. The photo's pixel is read only when kept.
    #[inline]
    fn value(&self, h: Vec3A, keep: Option<&PhotoBand>, photo: &Vec3) -> (Vec3, bool, bool) {
        if keep.is_some_and(|k| k.holds(h.into())) {
            return (*photo, true, false);
        }
        // Four lanes at once: lane by lane the same products and sums.
        let value = Vec3A::from(self.offset) + Vec3A::from(self.slope) * h;
        // Most pixels: positive and finite, nothing to clamp (NaN fails both).
        if (value.cmpgt(Vec3A::ZERO) & value.cmplt(Vec3A::INFINITY)).all() {
            return (value.into(), false, false);
        }
        let value = Vec3::from(value);
        let clamped = value.min_element() < 0.0 || !value.is_finite();
        (
            if value.is_finite() {
                value.max(Vec3::ZERO)
            } else {
                Vec3::ZERO
            },
            false,
            clamped,
        )
    }
}

impl RealPixel {
    fn patch(&self) -> usize {
        self.affine.patch()
    }

    /// The pixel's shade for indirect irradiance `h`, under direct irradiance `direct`.
    fn shade(&self, h: DVec3, photo: DVec3, direct: DVec3) -> Shade {
        let hf = h.as_vec3();
        if self.keep.holds(hf) {
            return Shade {
                value: photo,
                direct,
                indirect: h,
                copied: true,
                fallback: false,
                clamped: false,
            };
        }
        let value = (self.affine.offset + self.affine.slope * hf).as_dvec3();
        let clamped = value.min_element() < 0.0 || !value.is_finite();
        let value = if value.is_finite() {
            value.max(DVec3::ZERO)
        } else {
            DVec3::ZERO
        };
        Shade {
            value,
            direct,
            indirect: h,
            copied: false,
            fallback: self.affine.fallback(),
            clamped,
        }
    }

    /// [`AffinePixel::value`] with the layers (the direct one left to the caller).
    fn layers(&self, h: Vec3A, photo: &Vec3) -> PixelShade {
        let (value, copied, clamped) = self.affine.value(h, Some(&self.keep), photo);
        PixelShade {
            value,
            direct: Vec3::ZERO,
            indirect: h.into(),
            alpha: 0.0,
            object: Vec3::ZERO,
            copied,
            fallback: !copied && self.affine.fallback(),
            clamped,
        }
    }
}

/// Each patch's corner values of a vertex table, four lanes wide (a
/// triangle's fourth is zero): a pixel's interpolation then reads one
/// patch's row and multiplies four lanes at once, instead of looking up
/// four vertices one channel at a time (a third of the composite's work).
/// Zero beyond the table: the photo's model has no objects' vertices.
fn patch_corners(table: &[DVec3], patch_vertices: &[[u32; 4]]) -> Vec<[Vec3A; 4]> {
    patch_vertices
        .iter()
        .map(|ids| {
            ids.map(|v| {
                table
                    .get(v as usize)
                    .map_or(Vec3A::ZERO, |c| Vec3A::from(c.as_vec3()))
            })
        })
        .collect()
}

/// Corner values interpolated with weights `w` (a triangle's fourth weight
/// is zero). Lane by lane the same single-precision products and sums as
/// three scalar channels.
fn interpolate_single(corners: &[Vec3A; 4], w: [f32; 4]) -> Vec3A {
    corners[0] * w[0] + corners[1] * w[1] + corners[2] * w[2] + corners[3] * w[3]
}

/// What an update's image-only composite reads for its plain pixels
/// (a real point alone, prepared in [`RealPixels`]).
struct PlainTables<'a> {
    affine: &'a [AffinePixel],
    bands: &'a [PhotoBand],
    h_with: &'a [[Vec3A; 4]],
    may_keep: &'a [bool],
    any_keep: bool,
}

/// Pixels copied from the photo, ratios fallen back, values clamped.
#[derive(Default)]
struct Counts {
    copied: usize,
    fallbacks: usize,
    clamped: usize,
}

impl Counts {
    fn add(&mut self, copied: bool, fallback: bool, clamped: bool) {
        self.copied += copied as usize;
        self.fallbacks += fallback as usize;
        self.clamped += clamped as usize;
    }

    fn sum(self, other: Counts) -> Counts {
        Counts {
            copied: self.copied + other.copied,
            fallbacks: self.fallbacks + other.fallbacks,
            clamped: self.clamped + other.clamped,
        }
    }
}

impl PlainTables<'_> {
    /// The pixel of prepared real point `k`.
    #[inline(always)]
    fn pixel(
        &self,
        k: usize,
        photo: &Vec3,
        pixel: &mut Vec3,
        alpha: &mut f32,
        counts: &mut Counts,
    ) {
        let r = &self.affine[k];
        let patch = r.patch();
        let keep = (self.any_keep && self.may_keep[patch]).then(|| &self.bands[k]);
        let (value, copied, clamped) = r.value(
            interpolate_single(&self.h_with[patch], r.weights),
            keep,
            photo,
        );
        *pixel = value;
        // Most pixels showed no object the last time either: a read
        // instead of a write (and its line's fetch).
        if *alpha != 0.0 {
            *alpha = 0.0;
        }
        counts.add(copied, !copied && r.fallback(), clamped);
    }

    /// A run of pixels where no object shows: each a prepared real point,
    /// or nothing (the photo's pixel, as it is).
    fn run(
        &self,
        image: &mut [Vec3],
        alpha: &mut [f32],
        real: &[u32],
        photo: &[Vec3],
        counts: &mut Counts,
    ) {
        for (((pixel, a), &k), photo) in image.iter_mut().zip(alpha.iter_mut()).zip(real).zip(photo)
        {
            if k == u32::MAX {
                *pixel = *photo;
                *a = 0.0;
                counts.copied += 1;
                continue;
            }
            self.pixel(k as usize, photo, pixel, a, counts);
        }
    }
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

#[cfg(test)]
mod tests;
