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

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::image_io::Image;
use crate::light::LightSource;
use crate::pda::{LightTerm, PatchPoint, PixelDataArray, SurfacePoint};

/// Relative change of a pixel's irradiance below which only indirect
/// light moved and the photo's pixel is kept: 1e-3, a tenth of the ~1%
/// noise of a photograph.
pub const UNCHANGED_INDIRECT: f64 = 1e-3;

/// How real pixels take the change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CompositeMode {
    Additive,
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
    /// The irradiance of every real point that a moved object leaves alone,
    /// kept between updates; None: computed here.
    pub known: Option<&'a PointIrradiance>,
}

/// Per real point of the PDA: E_without and H_without (nothing a moved
/// object changes), E_with (an update refreshes the points it recomputed),
/// and the floor under which a ratio is not trusted (a thousandth of the
/// mean "without" irradiance).
#[derive(Debug, Clone, PartialEq)]
pub struct PointIrradiance {
    pub without: Vec<(DVec3, DVec3)>,
    pub direct_with: Vec<DVec3>,
    pub floor: DVec3,
}

impl PointIrradiance {
    pub fn of(input: &CompositeInput) -> PointIrradiance {
        let pda = input.pda;
        let lights = pda.light_count;
        let (without, direct_with): (Vec<(DVec3, DVec3)>, Vec<DVec3>) = pda
            .real
            .points
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                let terms = &pda.real.terms[i * lights..(i + 1) * lights];
                let without = (input.irradiance(terms, input.scales_without, false), input.interpolate(input.indirect_without, &p.location));
                (without, input.irradiance(terms, input.scales_with, true))
            })
            .unzip();
        let floor = without.iter().map(|(e, h)| *e + *h).sum::<DVec3>() / without.len().max(1) as f64 * 1e-3;
        PointIrradiance { without, direct_with, floor }
    }

    /// Recomputes E_with of real points `points` (indices into the PDA's real samples).
    pub fn refresh_direct(&mut self, input: &CompositeInput, points: &[u32]) {
        let lights = input.pda.light_count;
        for &k in points {
            let k = k as usize;
            self.direct_with[k] = input.irradiance(&input.pda.real.terms[k * lights..(k + 1) * lights], input.scales_with, true);
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
        vertices.iter().zip(at.weights).filter(|(_, w)| *w != 0.0).map(|(&v, w)| values[v as usize] * w as f64).sum()
    }

    /// A real surface point under the photo pixel `photo`; `floor` is the
    /// irradiance below which a ratio is not trusted.
    /// `known`: E_without, H_without and E_with there, when already known.
    fn shade_real(&self, p: &SurfacePoint, terms: &[LightTerm], photo: DVec3, floor: DVec3, known: Option<((DVec3, DVec3), DVec3)>) -> Shade {
        let ((e_wo, h_wo), e_w) = known.unwrap_or_else(|| {
            let without = (self.irradiance(terms, self.scales_without, false), self.interpolate(self.indirect_without, &p.location));
            (without, self.irradiance(terms, self.scales_with, true))
        });
        let h_w = self.interpolate(self.indirect_with, &p.location);
        let (without, with) = (e_wo + h_wo, e_w + h_w);
        if e_w == e_wo && (h_w - h_wo).abs().cmple(without * UNCHANGED_INDIRECT).all() {
            return Shade { value: photo, direct: e_w, indirect: h_w, copied: true, fallback: false, clamped: false };
        }
        let rho = self.reflectance[p.location.patch as usize];
        let additive = photo + rho * (with - without) / std::f64::consts::PI;
        let (mut value, mut fallback) = (DVec3::ZERO, false);
        for c in 0..3 {
            value[c] = match self.mode {
                CompositeMode::Ratio if without[c] > floor[c] => photo[c] * with[c] / without[c],
                CompositeMode::Ratio => {
                    fallback = true;
                    additive[c]
                }
                CompositeMode::Additive => additive[c],
            };
        }
        let clamped = value.min_element() < 0.0 || !value.is_finite();
        let value = if value.is_finite() { value.max(DVec3::ZERO) } else { DVec3::ZERO };
        Shade { value, direct: e_w, indirect: h_w, copied: false, fallback, clamped }
    }

    fn shade_virtual(&self, p: &SurfacePoint, terms: &[LightTerm]) -> Shade {
        let e_w = self.irradiance(terms, self.scales_with, true);
        let h_w = self.interpolate(self.indirect_with, &p.location);
        let rho = self.reflectance[p.location.patch as usize];
        let value = rho * (e_w + h_w) / std::f64::consts::PI;
        Shade { value, direct: e_w, indirect: h_w, copied: false, fallback: false, clamped: false }
    }
}

/// One pixel's layers for [`Composite::fill`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelShade {
    pub value: Vec3,
    pub direct: Vec3,
    pub indirect: Vec3,
    pub alpha: f32,
    pub copied: bool,
    pub fallback: bool,
    pub clamped: bool,
}

impl Composite {
    /// Sets every pixel, in parallel, to `shade(pixel)` (the change layer
    /// is value − photo) and counts the copied, fallen-back and clamped ones.
    pub fn fill(&mut self, photo: &Image, shade: impl Fn(usize) -> PixelShade + Sync + Send) {
        let (copied, fallbacks, clamped) = self
            .image
            .pixels
            .par_iter_mut()
            .zip(self.direct.pixels.par_iter_mut())
            .zip(self.indirect.pixels.par_iter_mut())
            .zip(self.change.pixels.par_iter_mut())
            .zip(self.alpha.par_iter_mut())
            .enumerate()
            .map(|(i, ((((image, direct), indirect), change), alpha))| {
                let s = shade(i);
                *image = s.value;
                *direct = s.direct;
                *indirect = s.indirect;
                *change = s.value - photo.pixels[i];
                *alpha = s.alpha;
                (s.copied as usize, s.fallback as usize, s.clamped as usize)
            })
            .reduce(|| (0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
        self.copied = copied;
        self.ratio_fallbacks = fallbacks;
        self.clamped = clamped;
    }

    /// No pixels yet.
    pub fn empty() -> Composite {
        Composite {
            image: Image::new(0, 0),
            direct: Image::new(0, 0),
            indirect: Image::new(0, 0),
            change: Image::new(0, 0),
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
    let computed;
    let known = match input.known {
        Some(k) => k,
        None => {
            computed = PointIrradiance::of(input);
            &computed
        }
    };
    let floor = known.floor;
    let mut edge_of = vec![u32::MAX; n];
    for (k, e) in pda.edges.iter().enumerate() {
        edge_of[e.pixel as usize] = k as u32;
    }
    if out.image.pixels.len() != n || out.alpha.len() != n {
        *out = Composite {
            image: Image::new(w, h),
            direct: Image::new(w, h),
            indirect: Image::new(w, h),
            change: Image::new(w, h),
            alpha: vec![0.0; n],
            copied: 0,
            ratio_fallbacks: 0,
            clamped: 0,
        };
    }
    let shade = |i: usize| -> (Shade, f32) {
        let photo = input.photo.pixels[i].as_dvec3();
        if edge_of[i] != u32::MAX {
            let e = pda.edges[edge_of[i] as usize];
            let mut sum = Shade { value: DVec3::ZERO, direct: DVec3::ZERO, indirect: DVec3::ZERO, copied: false, fallback: false, clamped: false };
            let mut virtual_count = 0;
            for k in e.start..e.start + e.count {
                let p = &pda.edge_samples.points[k as usize];
                let terms = &pda.edge_samples.terms[k as usize * lights..(k as usize + 1) * lights];
                let s = if p.is_virtual {
                    virtual_count += 1;
                    input.shade_virtual(p, terms)
                } else {
                    input.shade_real(p, terms, photo, floor, None)
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
                Shade { value: sum.value / total, direct: sum.direct / total, indirect: sum.indirect / total, ..sum },
                virtual_count as f32 / total as f32,
            );
        }
        if pda.virtual_index[i] != u32::MAX {
            let k = pda.virtual_index[i] as usize;
            return (input.shade_virtual(&pda.virtual_samples.points[k], &pda.virtual_samples.terms[k * lights..(k + 1) * lights]), 1.0);
        }
        if pda.real_index[i] != u32::MAX {
            let k = pda.real_index[i] as usize;
            return (input.shade_real(&pda.real.points[k], &pda.real.terms[k * lights..(k + 1) * lights], photo, floor, Some((known.without[k], known.direct_with[k]))), 0.0);
        }
        (Shade { value: photo, direct: DVec3::ZERO, indirect: DVec3::ZERO, copied: true, fallback: false, clamped: false }, 0.0)
    };
    let photo = &input.photo.pixels;
    out.fill(input.photo, |i| {
        let (s, a) = shade(i);
        // Copied pixels keep the photo's exact bits.
        let value: Vec3 = if s.copied { photo[i] } else { s.value.as_vec3() };
        PixelShade { value, direct: s.direct.as_vec3(), indirect: s.indirect.as_vec3(), alpha: a, copied: s.copied, fallback: s.fallback, clamped: s.clamped }
    });
}
