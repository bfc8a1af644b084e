//! Goniometric reconstruction (Grosch §2.3): a real light whose intensity
//! is `"reconstruct"` gets its distribution I(θ,φ) back from the photo,
//! with one known reflectance fixing the scale of light against reflectance.
//!
//! EQ1 turns what a surface of known reflectance shows into the intensity
//! towards it: I = (π·L/ρ − E_other − H)·d²/cosθ, where E_other is the
//! direct light of the other (known) lights and H the indirect light of the
//! current radiosity solution. Grosch averages each patch's pixels; arlux
//! keeps each pixel as a sample of its direction and fits the table by
//! least squares per direction node, which averages a texture the same way
//! while resolving the distribution as finely as the photo does.
//!
//! Before that, each surface's texture is divided out (`remove_texture`:
//! a `[[reflectance]]` is a surface's mean, and a checkerboard breaks "one
//! reflectance per polygon" at every pixel), pixels that mix surfaces or
//! shadow sides are left out, and each pixel's indirect light is gathered
//! from the photo itself ([`crate::gather`]). From the second round on, the
//! light found so far models what the texture solve could not read before:
//! steps across known lights' penumbrae, and across gaps (an occluder, the
//! unknown light's own shadow) between clean pixels of one plane; pixels in
//! a penumbra the photo resolves then join EQ1.
//!
//! Surfaces of unknown reflectance are taken in order of the smallest
//! angle to a known direction (EQ2 with the nearby intensity assumed; its
//! samples ranked by that angle times the share of their light the
//! unknown light gives, so a sample lit mostly by known lights is trusted
//! whatever the angle); each surface's reflectance is the median of its
//! best samples, after which its samples add their directions by EQ1.
//! The whole is iterated with the radiosity solution until table and
//! reflectances stop changing. Directions no sample reaches stay unknown
//! (zero in the table, marked in [`Reconstruction::known`]).

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::estimate::{EstimateSettings, PhotoPatches, estimate_reflectances};
use crate::ies::{IesProfile, PhotometricType};
use crate::image_io::Image;
use crate::light::{Distribution, LightSource};
use crate::patches::Patches;
use crate::radiosity::{DEFAULT_LINK_EPSILON, Transport, direct_irradiance};
use crate::scene::{Intensity, Scene};
use crate::surface_ids::row_hits;
use crate::trace::{Layer, Tracer};
use crate::util::rng::hash2;

mod evidence;
mod grid;
mod plot;
mod poisson;
mod propagate;
mod texture;

use evidence::Evidence;
use grid::{Fit, Grid, nearby_intensity};
pub use plot::polar_plot;
use propagate::propagate;
use texture::{PenumbraModel, Texture, mixed_pixels, sharp_pixels, textured, unreadable_pixels};

/// Bumped whenever the reconstruction's results change, so that a cached
/// light from an earlier arlux is not taken for a current one.
pub(crate) const ALGORITHM_VERSION: u32 = 12;

/// Photometric zero of the reconstructed table (type C nadir) and the
/// direction of horizontal angle 0: world down and world +x.
pub const AXIS: DVec3 = DVec3::NEG_Y;
pub(crate) const REFERENCE: DVec3 = DVec3::X;

/// Settings of the reconstruction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GonioSettings {
    /// Spacing of the table's vertical angles, degrees.
    pub vertical_step_deg: f64,
    /// Spacing of its horizontal angles, degrees.
    pub horizontal_step_deg: f64,
    /// Patch size of the radiosity solution that gives the indirect light.
    pub patch_size: f64,
    /// 2^level shadow rays per point towards rect lights.
    pub light_level: usize,
    /// Rounds of (reconstruct, re-solve radiosity) at most.
    pub max_rounds: usize,
    /// Stop when no table value changes by more than this fraction of the peak.
    pub tolerance: f64,
    /// Rays per pixel gathering its indirect light.
    pub gather_rays: u32,
    /// A jump of ln radiance between neighbouring pixels of one surface
    /// larger than this, where no light's visibility changes, is an edge
    /// of the surface's texture.
    pub texture_edge: f64,
}

impl Default for GonioSettings {
    fn default() -> Self {
        // 1° × 2.5° resolves a spot's beam edge (a few degrees wide) while
        // each node still averages many pixels on the desk's surfaces.
        GonioSettings {
            vertical_step_deg: 1.0,
            horizontal_step_deg: 2.5,
            patch_size: 0.25,
            light_level: 4,
            max_rounds: 12,
            tolerance: 2e-3,
            gather_rays: 64,
            texture_edge: 0.1,
        }
    }
}

/// How a surface's reflectance was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReflectanceSource {
    /// Given in the scene.
    Known,
    /// EQ2 with the intensity of directions at most `angle_deg` away.
    Propagated {
        step: usize,
        angle_deg: f64,
        samples: usize,
    },
    /// No sample: the photo shows no lit pixel of it.
    Unreached,
}

/// A surface's reflectance as the reconstruction found it.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceReflectance {
    pub surface: u32,
    pub name: String,
    pub rgb: Option<DVec3>,
    pub source: ReflectanceSource,
}

/// The recovered light.
#[derive(Debug, Clone, PartialEq)]
pub struct Reconstruction {
    /// Index of the light in the scene.
    pub light: usize,
    pub position: DVec3,
    /// Colour: the table holds I(d) / colour (a lamp's spectrum does not
    /// change with direction; arlux's renderer keeps one colour per light).
    pub colour: DVec3,
    /// Relative candela table, type C, vertical 0 along [`AXIS`].
    pub profile: IesProfile,
    /// Per table node (horizontal-major like `profile.candela`): whether any
    /// sample constrains it.
    pub known: Vec<bool>,
    /// Fraction of the sphere's solid angle the known nodes cover.
    pub coverage: f64,
    /// Largest relative difference between the full RGB fit and colour × table.
    pub colour_residual: f64,
    pub reflectances: Vec<SurfaceReflectance>,
    pub rounds: usize,
    /// Last round's largest table change, relative to the peak.
    pub change: f64,
    pub samples: usize,
    /// Pixel pairs taken as texture edges.
    pub texture_edges: usize,
    pub patches: usize,
    pub seconds: f64,
}

impl Reconstruction {
    /// The recovered intensity towards unit `d` (W/sr per channel).
    pub fn intensity(&self, d: DVec3) -> DVec3 {
        self.colour * self.profile.candela_towards(d, AXIS, REFERENCE)
    }

    /// The light as a distribution the renderer uses.
    pub fn distribution(&self) -> Distribution {
        Distribution::Ies {
            profile: Box::new(self.profile.clone()),
            axis: AXIS,
            reference: REFERENCE,
            rgb: self.colour,
        }
    }

    /// Whether direction `d` was constrained by the photo (its nearest node is known).
    pub fn is_known(&self, d: DVec3) -> bool {
        let (v, h) = angles(d);
        let nv = self.profile.vertical.len();
        let vi = ((v / self.profile.vertical[1]).round() as usize).min(nv - 1);
        let hi =
            ((h / self.profile.horizontal[1]).round() as usize) % self.profile.horizontal.len();
        self.known[hi * nv + vi]
    }

    /// `scene` with the light's intensity replaced by the recovered table.
    pub fn apply(&self, scene: &Scene) -> Scene {
        apply_profile(scene, self.light, &self.profile, self.colour)
    }

    /// The recovered light as an IES file that also records its colour
    /// (keyword `_ARLUX_RGB`) and light index (`_ARLUX_LIGHT`), for a cache.
    pub(crate) fn to_cache_text(&self) -> String {
        let mut profile = self.profile.clone();
        profile.keywords.push((
            "_ARLUX_RGB".to_string(),
            format!("{} {} {}", self.colour.x, self.colour.y, self.colour.z),
        ));
        profile
            .keywords
            .push(("_ARLUX_LIGHT".to_string(), self.light.to_string()));
        profile.to_lm63()
    }
}

/// Reads what [`Reconstruction::to_cache_text`] wrote: (light, table, colour).
pub(crate) fn from_cache_text(
    text: &str,
    path: &std::path::Path,
) -> Option<(usize, IesProfile, DVec3)> {
    let profile = IesProfile::parse(text, path).ok()?;
    let keyword = |k: &str| {
        profile
            .keywords
            .iter()
            .find(|(key, _)| key == k)
            .map(|(_, v)| v.clone())
    };
    let rgb: Vec<f64> = keyword("_ARLUX_RGB")?
        .split_whitespace()
        .filter_map(|v| v.parse().ok())
        .collect();
    let light: usize = keyword("_ARLUX_LIGHT")?.trim().parse().ok()?;
    (rgb.len() == 3 && rgb.iter().all(|c| c.is_finite() && *c >= 0.0))
        .then(|| (light, profile.clone(), DVec3::new(rgb[0], rgb[1], rgb[2])))
}

/// `scene` with light `light`'s intensity replaced by a recovered table.
pub(crate) fn apply_profile(
    scene: &Scene,
    light: usize,
    profile: &IesProfile,
    colour: DVec3,
) -> Scene {
    let mut out = scene.clone();
    out.lights[light].intensity = Intensity::Ies {
        file: scene.dir().join("reconstructed.ies"),
        profile: profile.clone(),
        rgb: colour,
        direction: AXIS,
        reference: REFERENCE,
    };
    out
}

impl Reconstruction {}

/// Type C angles (degrees) of unit direction `d` in the reconstruction frame.
fn angles(d: DVec3) -> (f64, f64) {
    let side = AXIS.cross(REFERENCE);
    let v = d.dot(AXIS).clamp(-1.0, 1.0).acos().to_degrees();
    let h = d
        .dot(side)
        .atan2(d.dot(REFERENCE))
        .to_degrees()
        .rem_euclid(360.0);
    (v, h)
}

/// The index of the one light to reconstruct, `None` when there is none.
/// Two unknown goniometrics cannot be told apart from one photo (Grosch §5:
/// a surface lit by both is explained by infinitely many pairs).
pub fn light_to_reconstruct(scene: &Scene) -> Result<Option<usize>> {
    let marked: Vec<usize> = (0..scene.lights.len())
        .filter(|&i| scene.lights[i].intensity == Intensity::Reconstruct)
        .collect();
    match marked.as_slice() {
        [] => Ok(None),
        [i] => {
            if !scene.lights[*i].real {
                return Err(Error::key(
                    &scene.file,
                    format!("light[{i}].intensity"),
                    "only a real light can be reconstructed: a virtual light is not in the photo",
                ));
            }
            Ok(Some(*i))
        }
        [a, b, ..] => Err(Error::key(
            &scene.file,
            format!("light[{b}].intensity"),
            format!(
                "light[{a}] and light[{b}] are both \"reconstruct\": one photo cannot tell two unknown goniometrics apart; give all lights but one an intensity (an IES file, a spot, ...)"
            ),
        )),
    }
}

/// One pixel's evidence.
#[derive(Clone)]
struct Sample {
    surface: u32,
    /// Vertical and horizontal angle of the direction from the light, degrees.
    v: f64,
    h: f64,
    /// Irradiance the unknown light would give at unit intensity, with visibility.
    g: f64,
    /// Direct irradiance of the other lights as photographed.
    e_known: DVec3,
    /// π × photo radiance (the radiosity the pixel shows).
    b: DVec3,
    /// Indirect irradiance from the current solution.
    h_ind: DVec3,
    /// Pixel index, surface point and normal (facing the camera).
    pixel: u32,
    x: DVec3,
    n: DVec3,
    /// Surface area the pixel covers, up to a constant: depth² / |cos|.
    area: f64,
    /// Indirect irradiance gathered from what the photo shows.
    gathered_photo: DVec3,
    /// Range in [`Gather::unseen`] of the patches its rays met that the photo does not show.
    unseen: (u32, u32),
}

/// Samples whose median gives a surface's reflectance by EQ2: the same
/// number for every surface, so that surfaces compete on equal terms.
const EQ2_SAMPLES: usize = 64;

/// Relative doubt in a sample's EQ2 below which it always takes part.
const SAFE_RISK: f64 = 0.03;

/// How much a sample's share of indirect light (gathered per pixel with
/// noise) counts against it, next to the relative doubt in its direct light.
const INDIRECT_DOUBT: f64 = 0.1;

/// The least share of its samples' light a direction must explain not to
/// be taken as dark: where the light gives under 5% of what a surface
/// receives, EQ1 subtracts two nearly equal numbers (the photo's light and
/// the other lights' plus the indirect, known to a few percent) and what is
/// left is their error, not the light (on the desk: the ceiling, which the
/// spot never reaches, came out at 7% of the peak).
const MIN_LIGHT_SHARE: f64 = 0.05;

/// Samples' worth of weight a node needs before EQ2 may lean on it.
const WELL_KNOWN_SAMPLES: f64 = 4.0;

/// Gathers each sample's indirect light per pixel (interpolating it from
/// patches fails exactly where propagation happens: at corners and
/// occlusion edges): cosine-distributed rays; where one meets a surface the
/// camera sees, the light leaving it is the photo's pixel there (texture
/// and all); elsewhere it is left to the radiosity solution, by patch.
/// Returns the flat list of those patches ([`Sample::unseen`] ranges).
fn gather_from_photo(
    scene: &Scene,
    tracer: &Tracer,
    patches: &Patches,
    photo: &Image,
    samples: &mut [Sample],
    rays: u32,
) -> Vec<u32> {
    use crate::light::offset_origin;
    use crate::trace::TraceRay;
    let cam = &scene.camera;
    let side = (rays as f64).sqrt().ceil().max(1.0) as u32;
    let count = side * side;
    let pi = std::f64::consts::PI;
    let per: Vec<(DVec3, Vec<u32>)> = samples
        .par_iter()
        .map(|s| {
            let origin = offset_origin(s.x, s.n, s.x + s.n);
            let dirs =
                crate::gather::cosine_directions(s.n, side, hash2(s.pixel as u64, 0x6A7E_6011));
            let traced: Vec<TraceRay> = dirs
                .iter()
                .map(|d| TraceRay::new(origin.as_vec3(), d.as_vec3()))
                .collect();
            let mut hits = vec![None; traced.len()];
            tracer.intersect_batch(&traced, Layer::Real, &mut hits);
            let (mut sum, mut unseen) = (DVec3::ZERO, Vec::new());
            for (d, hit) in dirs.iter().zip(&hits) {
                let Some(hit) = hit else { continue };
                let y = origin + *d * hit.t as f64;
                let seen = crate::gather::photo_radiance_at(cam, tracer, photo, y);
                match seen {
                    Some(radiance) if radiance.is_finite() => sum += radiance,
                    _ => {
                        if let Some(at) = patches.locate(hit.surface, hit.triangle, y) {
                            unseen.push(at.patch);
                        }
                    }
                }
            }
            (sum * (pi / count as f64), unseen)
        })
        .collect();
    let mut flat = Vec::new();
    for (s, (sum, unseen)) in samples.iter_mut().zip(per) {
        s.gathered_photo = sum;
        let start = flat.len() as u32;
        flat.extend(unseen);
        s.unseen = (start, flat.len() as u32);
    }
    flat
}

fn median_rgb(values: &[DVec3]) -> DVec3 {
    let median = |mut c: Vec<f64>| {
        c.sort_by(f64::total_cmp);
        let n = c.len();
        if n % 2 == 1 {
            c[n / 2]
        } else {
            0.5 * (c[n / 2 - 1] + c[n / 2])
        }
    };
    DVec3::new(
        median(values.iter().map(|v| v.x).collect()),
        median(values.iter().map(|v| v.y).collect()),
        median(values.iter().map(|v| v.z).collect()),
    )
}

/// What EQ2 gives each surface when the light to reconstruct is known to be
/// `distribution` (the same samples, textures and indirect light as a
/// reconstruction uses): the reflectances a reconstruction would find with
/// a perfect goniometric, per surface (median over its samples). For
/// measuring a reconstruction when no reflectance ground truth exists.
pub fn reflectances_given(
    scene: &Scene,
    distribution: &Distribution,
    photo: &Image,
    tracer: &Tracer,
    settings: &GonioSettings,
) -> Result<HashMap<u32, DVec3>> {
    let mut ev = Evidence::gather(scene, photo, tracer, settings)?;
    let mut light = ev.unit.clone();
    light.distribution = distribution.clone();
    ev.update_indirect(Some(&light), tracer, settings);
    ev.retexture(distribution, settings);
    let mut by_surface: HashMap<u32, Vec<DVec3>> = HashMap::new();
    for s in &ev.samples {
        let irradiance = distribution.intensity(direction_at(s.v, s.h)) * s.g + s.e_known + s.h_ind;
        if irradiance.min_element() > 0.0 {
            by_surface
                .entry(s.surface)
                .or_default()
                .push(s.b / irradiance);
        }
    }
    Ok(by_surface
        .into_iter()
        .map(|(k, v)| (k, median_rgb(&v)))
        .collect())
}

/// Reconstructs the goniometric of the scene's `"reconstruct"` light from
/// `photo` (radiance in the scene's units).
pub fn reconstruct(
    scene: &Scene,
    photo: &Image,
    tracer: &Tracer,
    settings: &GonioSettings,
) -> Result<Reconstruction> {
    let t0 = Instant::now();
    let mut ev = Evidence::gather(scene, photo, tracer, settings)?;
    let grid = Grid::new(settings);
    let mut surfaces: Vec<u32> = ev.samples.iter().map(|s| s.surface).collect();
    surfaces.sort_unstable();
    surfaces.dedup();
    let mut light = ev.unit.clone();
    let mut table: Option<Vec<DVec3>> = None;
    let (mut rounds, mut change) = (0, f64::INFINITY);
    let mut result = None;
    while rounds < settings.max_rounds && change > settings.tolerance {
        rounds += 1;
        // The indirect light: the photo's radiosity where it sees a patch,
        // the model's (with the current reconstruction) where it does not.
        ev.update_indirect(table.as_ref().map(|_| &light), tracer, settings);
        // Once the light is roughly known, its model lets the texture
        // steps across the known lights' soft shadow edges and across gaps
        // be read too; every round, since the steps read depend on the
        // light (only the first, at round 2, takes long: later ones start
        // from the texture and robust weights before).
        if rounds >= 2 {
            ev.retexture(&light.distribution, settings);
        }
        let (fit, rho) = propagate(&grid, &ev.samples, &ev.known_rho, &surfaces);
        let known = fit.known();
        let values = fit.values_above(MIN_LIGHT_SHARE);
        let peak = values
            .iter()
            .map(|v| v.max_element())
            .fold(0.0, f64::max)
            .max(1e-300);
        change = match &table {
            None => f64::INFINITY,
            Some(old) => {
                old.iter()
                    .zip(&values)
                    .map(|(a, b)| (*a - *b).abs().max_element())
                    .fold(0.0, f64::max)
                    / peak
            }
        };
        let (colour, scalar, residual) = factor_colour(&values, &known);
        let profile = table_profile(&grid, &scalar);
        light.distribution = Distribution::Ies {
            profile: Box::new(profile.clone()),
            axis: AXIS,
            reference: REFERENCE,
            rgb: colour,
        };
        table = Some(values);
        result = Some((profile, colour, known, residual, rho));
    }
    let (profile, colour, known, colour_residual, rho) = result.expect("at least one round runs");
    let names = scene.surface_names();
    let reflectances = surfaces_in_order(scene)
        .into_iter()
        .map(|surface| {
            let (rgb, source) = match rho.get(&surface) {
                Some((r, s)) => (Some(*r), *s),
                None => (None, ReflectanceSource::Unreached),
            };
            SurfaceReflectance {
                surface,
                name: names.get(surface as usize).cloned().unwrap_or_default(),
                rgb,
                source,
            }
        })
        .collect();
    let total: f64 = (0..grid.nv).map(|vi| grid.solid_angle(vi)).sum::<f64>() * grid.nh as f64;
    let covered: f64 = (0..grid.len())
        .filter(|&k| known[k])
        .map(|k| grid.solid_angle(k % grid.nv))
        .sum();
    Ok(Reconstruction {
        light: ev.index,
        position: ev.unit.position,
        colour,
        profile,
        known,
        coverage: covered / total,
        colour_residual,
        reflectances,
        rounds,
        change,
        samples: ev.samples.len(),
        texture_edges: ev.texture_edges,
        patches: ev.patches.patch_count(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

fn surfaces_in_order(scene: &Scene) -> Vec<u32> {
    (0..scene.surfaces.len() as u32).collect()
}

/// Splits an RGB table into one colour (mean channel 1) times a scalar
/// table, by least squares per node; returns the largest relative
/// residual among nodes above a tenth of the peak.
fn factor_colour(values: &[DVec3], known: &[bool]) -> (DVec3, Vec<f64>, f64) {
    let sum: DVec3 = values
        .iter()
        .zip(known)
        .filter(|(_, k)| **k)
        .map(|(v, _)| *v)
        .sum();
    let colour = if sum.element_sum() > 0.0 {
        sum / (sum.element_sum() / 3.0)
    } else {
        DVec3::ONE
    };
    let scalar: Vec<f64> = values
        .iter()
        .map(|v| (v.dot(colour) / colour.length_squared()).max(0.0))
        .collect();
    let peak = values.iter().map(|v| v.max_element()).fold(0.0, f64::max);
    let residual = values
        .iter()
        .zip(&scalar)
        .filter(|(v, _)| v.max_element() > 0.1 * peak)
        .map(|(v, s)| (*v - colour * *s).abs().max_element() / v.max_element())
        .fold(0.0, f64::max);
    (colour, scalar, residual)
}

/// The scalar table as a type C LM-63 profile over the full sphere.
fn table_profile(grid: &Grid, scalar: &[f64]) -> IesProfile {
    IesProfile {
        version: "IESNA:LM-63-2002".to_string(),
        keywords: vec![
            (
                "TEST".to_string(),
                "reconstructed by arlux from a photograph (Grosch et al. 2003, EQ1/EQ2)"
                    .to_string(),
            ),
            ("MANUFAC".to_string(), "arlux".to_string()),
            (
                "OTHER".to_string(),
                "candela relative to the light's rgb; directions the photo does not show are 0"
                    .to_string(),
            ),
        ],
        tilt: None,
        lamps: 1,
        lumens_per_lamp: -1.0,
        multiplier: 1.0,
        photometric_type: PhotometricType::C,
        units: 2,
        width: 0.0,
        length: 0.0,
        height: 0.0,
        ballast_factor: 1.0,
        ballast_lamp_factor: 1.0,
        input_watts: 0.0,
        vertical: (0..grid.nv).map(|i| i as f64 * grid.dv).collect(),
        horizontal: (0..grid.nh).map(|i| i as f64 * grid.dh).collect(),
        candela: scalar.to_vec(),
    }
}

/// The brightest table value and its direction.
pub fn peak(rec: &Reconstruction) -> (f64, DVec3) {
    let p = &rec.profile;
    let nv = p.vertical.len();
    let (k, value) =
        p.candela.iter().enumerate().fold(
            (0, f64::MIN),
            |best, (k, &c)| if c > best.1 { (k, c) } else { best },
        );
    (
        value,
        direction_at(p.vertical[k % nv], p.horizontal[k / nv]),
    )
}

/// Unit direction of type C angles (degrees) in the reconstruction frame.
pub(crate) fn direction_at(v_deg: f64, h_deg: f64) -> DVec3 {
    let side = AXIS.cross(REFERENCE);
    let (v, h) = (v_deg.to_radians(), h_deg.to_radians());
    AXIS * v.cos() + (REFERENCE * h.cos() + side * h.sin()) * v.sin()
}

#[cfg(test)]
mod tests;
