//! Real pixels prepared once as affine functions of their indirect light,
//! kept by a session so that an update shades them without their terms.

use super::*;

/// A real point's composite, affine in the indirect irradiance with the
/// changes H: value = offset + slope·H per channel — the ratio form
/// photo·(E_with + H)/D, or the additive photo + ρ(E_with + H − D)/π where
/// D (the "without" irradiance) is under the floor or the mode says so —
/// and the band of H within which the photo's pixel stands (only where the
/// direct light is unchanged). Everything but H is fixed while objects
/// move, and this is all a pixel reads (not the PDA's point and terms).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealPixel {
    pub(super) affine: AffinePixel,
    pub(super) keep: PhotoBand,
}

/// A [`RealPixel`]'s affine part: 44 bytes, read for every pixel of every
/// update's composite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct AffinePixel {
    pub(super) offset: Vec3,
    pub(super) slope: Vec3,
    /// The patch the point lies in, with [`FALLBACK`] set where the ratio
    /// fell back to the additive form.
    pub(super) patch: u32,
    pub(super) weights: [f32; 4],
}

/// A [`RealPixel`]'s band: read by an update only where its patch's
/// corners say the photo's pixel may be kept ([`RealPixels::may_keep`];
/// with an object in the room, nearly nowhere: its indirect light moves
/// everything).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PhotoBand {
    pub(super) h_without: Vec3,
    /// Negative: the direct light changed, never the photo's pixel.
    pub(super) band: Vec3,
}

/// [`AffinePixel::patch`]'s flag bit (patch numbers stay below it).
pub(super) const FALLBACK: u32 = 1 << 31;

/// [`RealPixel`] per real point of the PDA, kept by a session with its
/// affine parts and bands apart (an update's composite reads 44 bytes a
/// pixel instead of 68), what `RealPixels::may_keep` asks per patch, and
/// the floor under which a ratio is not trusted (a thousandth of the mean
/// "without" irradiance).
#[derive(Debug, Clone, PartialEq)]
pub struct RealPixels {
    pub(super) affine: Vec<AffinePixel>,
    pub(super) keep: Vec<PhotoBand>,
    /// Per patch, the widest band of its pixels per channel (negative
    /// where none has one).
    pub(super) widest_band: Vec<Vec3>,
    /// Per patch, the corners of the indirect light without the changes.
    pub(super) without: Vec<[Vec3A; 4]>,
    pub floor: DVec3,
    /// The pixels on the real surfaces' seams ([`super::seams::seam_pixels`]).
    pub(super) seams: Vec<u32>,
    /// The lights' scales changed since these were prepared: every pixel
    /// is prepared again, the seams kept (see [`RealPixels::for_new_scales`]).
    pub(super) scales_changed: bool,
}

impl RealPixels {
    pub fn of(input: &CompositeInput) -> RealPixels {
        RealPixels::with_seams(input, super::seams::seam_pixels(input.pda))
    }

    /// What a change of the lights' scales keeps: every real pixel's terms
    /// read the scales, the seams only the real surfaces (finding them
    /// again was a fifth of a `lounge` relight's composite).
    pub(crate) fn for_new_scales(self) -> RealPixels {
        RealPixels {
            affine: Vec::new(),
            keep: Vec::new(),
            scales_changed: true,
            ..self
        }
    }

    /// The prepared pixels for `input`: prepared again, the seams kept,
    /// after [`RealPixels::for_new_scales`]; else refreshed where the
    /// pixels `recomputed` had their light terms changed.
    pub(crate) fn again(mut self, input: &CompositeInput, recomputed: &[u32]) -> RealPixels {
        if self.scales_changed {
            return RealPixels::with_seams(input, self.seams);
        }
        self.refresh(input, recomputed);
        self
    }

    /// [`RealPixels::of`] with the seams already found.
    fn with_seams(input: &CompositeInput, seams: Vec<u32>) -> RealPixels {
        let pda = input.pda;
        let lights = pda.light_count;
        let floor = input.floor;
        let first = pda.first_pixel() as u32;
        let pixel_of: Vec<u32> = (0..pda.real_index.len() as u32)
            .filter(|&i| pda.real_index[i as usize] != u32::MAX)
            .map(|i| first + i)
            .collect();
        // Straight into the two halves: no image-sized list of whole pixels.
        let (affine, keep): (Vec<AffinePixel>, Vec<PhotoBand>) = pixel_of
            .par_iter()
            .enumerate()
            .map(|(k, &i)| {
                let r = input.real_pixel(
                    &pda.real.points[k],
                    &pda.real.terms[k * lights..(k + 1) * lights],
                    input.photo_at(i as usize),
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
            seams,
            scales_changed: false,
        };
        for k in 0..known.affine.len() {
            known.widen(&known.get(k));
        }
        known
    }

    /// Prepares again the real points of `pixels`, whose light terms changed.
    pub(crate) fn refresh(&mut self, input: &CompositeInput, pixels: &[u32]) {
        let pda = input.pda;
        let lights = pda.light_count;
        for &i in pixels {
            let k = pda.real_at(i as usize);
            if k != u32::MAX {
                let k = k as usize;
                let r = input.real_pixel(
                    &pda.real.points[k],
                    &pda.real.terms[k * lights..(k + 1) * lights],
                    input.photo_at(i as usize),
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
    pub(super) fn widen(&mut self, r: &RealPixel) {
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
    pub(super) fn may_keep(&self, with: &[[Vec3A; 4]], vertices: &[[u32; 4]]) -> Vec<bool> {
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

    pub(super) fn get(&self, k: usize) -> RealPixel {
        RealPixel {
            affine: self.affine[k],
            keep: self.keep[k],
        }
    }
}

impl PhotoBand {
    /// Whether the photo's pixel stands at indirect irradiance `h`.
    #[inline]
    pub(super) fn holds(&self, h: Vec3) -> bool {
        self.band.x >= 0.0 && (h - self.h_without).abs().cmple(self.band).all()
    }
}

impl AffinePixel {
    pub(super) fn fallback(&self) -> bool {
        self.patch & FALLBACK != 0
    }

    pub(super) fn patch(&self) -> usize {
        (self.patch & !FALLBACK) as usize
    }

    /// The value in single precision, as the image takes it: (value,
    /// copied, clamped), where `keep` is the pixel's band when it may hold
    /// h. The photo's pixel is read only when kept.
    #[inline]
    pub(super) fn value(
        &self,
        h: Vec3A,
        keep: Option<&PhotoBand>,
        photo: &Vec3,
    ) -> (Vec3, bool, bool) {
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
    pub(super) fn patch(&self) -> usize {
        self.affine.patch()
    }

    /// The pixel's shade for indirect irradiance `h`, under direct irradiance `direct`.
    pub(super) fn shade(&self, h: DVec3, photo: DVec3, direct: DVec3) -> Shade {
        // Irradiance is not negative: an interpolated change can overshoot
        // where the light varies by orders of magnitude across a patch (a
        // lamp a millimetre from the floor).
        let h = h.max(DVec3::ZERO);
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
    pub(super) fn layers(&self, h: Vec3A, photo: &Vec3) -> PixelShade {
        // Not negative, as in [`RealPixel::shade`].
        let h = h.max(Vec3A::ZERO);
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
pub(super) fn patch_corners(table: &[DVec3], patch_vertices: &[[u32; 4]]) -> Vec<[Vec3A; 4]> {
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
pub(super) fn interpolate_single(corners: &[Vec3A; 4], w: [f32; 4]) -> Vec3A {
    corners[0] * w[0] + corners[1] * w[1] + corners[2] * w[2] + corners[3] * w[3]
}

/// What an update's image-only composite reads for its plain pixels
/// (a real point alone, prepared in [`RealPixels`]).
pub(super) struct PlainTables<'a> {
    pub(super) affine: &'a [AffinePixel],
    pub(super) bands: &'a [PhotoBand],
    pub(super) h_with: &'a [[Vec3A; 4]],
    pub(super) may_keep: &'a [bool],
    pub(super) any_keep: bool,
}

/// Pixels copied from the photo, ratios fallen back, values clamped.
#[derive(Default)]
pub(super) struct Counts {
    pub(super) copied: usize,
    pub(super) fallbacks: usize,
    pub(super) clamped: usize,
}

impl Counts {
    pub(super) fn add(&mut self, copied: bool, fallback: bool, clamped: bool) {
        self.copied += copied as usize;
        self.fallbacks += fallback as usize;
        self.clamped += clamped as usize;
    }

    pub(super) fn sum(self, other: Counts) -> Counts {
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
    pub(super) fn pixel(
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
    pub(super) fn run(
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
