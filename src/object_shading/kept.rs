//! What a session keeps of its objects' shaded pixels, so that an update
//! shades again only the pixels whose rays the moved objects may cross.
//!
//! A pixel of an object with a material is the mean of its samples (see
//! [`ObjectShading::radiance`]), and each sample is emission plus direct
//! light, one ray from the specular lobe and the diffuse part's indirect
//! light. What the rays decide (the points met, the lights' visibility
//! there, the photo where the camera sees them) stays as it was while no
//! moved object comes near any of the sample's rays; what the solution
//! decides (the room's indirect light where the lobe's ray landed, the
//! object's own gathered light) changes with every pose. A session keeps
//! the first per sample and reads the second again: the same numbers,
//! summed in the same order, as shading the pixel anew, so an update's
//! image is still a full render's, bit for bit. A pixel of a still object
//! beside a moving one is read again in microseconds where shading it
//! traces 16-24 camera rays and 3 + 3 × lights shadow and lobe rays.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::ObjectShading;
use super::paths::Measured;
use crate::light::LightSource;
use crate::objects::Movers;
use crate::pda::{PixelDataArray, SurfacePoint};
use crate::util::FastMap;

/// At most this many bytes of kept samples (a lobe ray takes 64: 4 M of
/// them, an object over 200,000 pixels of a plate at 20 a pixel); past it,
/// pixels are shaded anew at every update.
const KEEP_BYTES: usize = 256 << 20;

/// A shaded point's samples as a session keeps them (see the module's doc).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Record {
    /// Whether it may be kept: not a point an alpha mask cuts away
    /// (shaded by what lies behind it).
    pub keepable: bool,
    /// Emission, direct light and the lamps' reflections, summed over the samples.
    pub base: DVec3,
    /// The diffuse part's factors, summed on the vertices whose indirect
    /// light each sample's point reads.
    pub diffuse: DiffuseWeights,
    /// Each sample's lobe ray (one a sample): where it ended, and what it
    /// met that reads the solution.
    pub lobes: Vec<(Vec3, Option<Measured>)>,
    /// A cone from the camera holding every sample's camera ray: its
    /// axis's far end and radius there.
    pub view: (Vec3, f32),
    /// How far the samples' points lie from the pixel's point at most.
    pub spread: f32,
}

impl Record {
    /// Widens the view cone from `eye` through `x` to hold the camera ray that ended at `end`.
    pub(crate) fn sees(&mut self, eye: DVec3, x: DVec3, end: DVec3) {
        let u = (x - eye).normalize_or_zero();
        let far = self.view.0.as_dvec3();
        let reach = ((far - eye).dot(u)).max((x - eye).length() * 1.001);
        let t = (end - eye).dot(u).max(1e-9);
        let across = ((end - eye) - u * t).length();
        let reach_now = reach.max(t);
        let radius = (self.view.1 as f64 * reach_now / reach).max(across * reach_now / t);
        self.view = (
            (eye + u * reach_now).as_vec3(),
            (radius * (1.0 + 1e-6)) as f32,
        );
    }
}

/// The point a record is for: its position's bits, surface and share of its pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct PointKey([u32; 3], u32, u64);

impl PointKey {
    fn of(p: &SurfacePoint, share: f64) -> PointKey {
        let x = p.position;
        PointKey(
            [x.x.to_bits(), x.y.to_bits(), x.z.to_bits()],
            p.surface,
            share.to_bits(),
        )
    }
}

/// Each virtual point's radiance for the composite, as
/// [`ObjectShading::radiance`] gives it (None: no material there).
#[derive(Debug, Clone, Default)]
pub struct ShadedPoints {
    /// By point of the pixel data's whole virtual pixels.
    pub whole: Vec<Option<DVec3>>,
    /// By point of its edge pixels' sub-pixels.
    pub edge: Vec<Option<DVec3>>,
}

/// A session's kept samples, by point (see the module's doc).
#[derive(Default)]
pub struct KeptShading {
    /// The lights' scales the samples were drawn at.
    scales: Vec<f64>,
    records: FastMap<PointKey, Record>,
    /// What moved since, for the next composite (None: nothing is kept).
    movers: Option<Box<dyn Movers + Send>>,
    /// Points read again over kept samples in the last composite.
    pub kept: usize,
}

impl std::fmt::Debug for KeptShading {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KeptShading")
            .field("points", &self.records.len())
            .field("kept", &self.kept)
            .finish()
    }
}

/// A point's radiance and what becomes of its record.
enum Outcome {
    Kept(PointKey, DVec3),
    Fresh(PointKey, Option<DVec3>, Record),
    Plain(Option<DVec3>),
}

impl KeptShading {
    /// The next composite's samples may be kept where `movers` come near
    /// none of their rays. A second move before the samples were read again
    /// (composites with rounds skip them) leaves them unknown: dropped.
    pub fn since(&mut self, movers: Box<dyn Movers + Send>) {
        if self.movers.is_some() {
            *self = KeptShading::default();
        }
        self.movers = Some(movers);
    }

    /// Shades every virtual point of `pda` whose surface has a material.
    /// After an update, a still object's kept samples are read again where
    /// nothing that moved comes near their rays, and its points drawn anew
    /// are kept; a moved object's are not (it is likely to move again: a
    /// drag). The session's first composite keeps every point's; any other
    /// (the lights scaled, a render saved) shades anew and keeps the samples
    /// as they were, dropping them if the lights' scales changed.
    pub fn shade(&mut self, shading: &ObjectShading, pda: &PixelDataArray) -> ShadedPoints {
        let movers = self.movers.take();
        let first = self.scales.is_empty();
        if movers.is_none() && !first {
            if self.scales != shading.scales_with {
                *self = KeptShading::default();
            }
            self.kept = 0;
            let plain = |p: &SurfacePoint, share| {
                (p.is_virtual).then(|| shading.radiance(p, share)).flatten()
            };
            return shaded_points(pda, plain);
        }
        let movers = movers.filter(|_| self.scales == shading.scales_with);
        let mut old = std::mem::take(&mut self.records);
        let lights = lit(shading.lights, shading.scales_with);
        let one = |p: &SurfacePoint, share: f64| {
            if !p.is_virtual || !shading.materials.has(p.surface) {
                return Outcome::Plain(None);
            }
            if movers.as_ref().is_some_and(|m| !m.unmoved(p.surface)) {
                return Outcome::Plain(shading.radiance(p, share));
            }
            let key = PointKey::of(p, share);
            let kept = old.get(&key).filter(|r| r.keepable);
            if let (Some(m), Some(r)) = (&movers, kept)
                && clear(&**m, shading, p, r, &lights)
            {
                return Outcome::Kept(key, replay(shading, r));
            }
            let mut record = Record::default();
            let value = shading.shade_point(p, share, None, Some(&mut record));
            Outcome::Fresh(key, value, record)
        };
        let share = 1.0 / (pda.supersample * pda.supersample) as f64;
        let edge_pixel = at_edges(pda);
        let whole: Vec<Outcome> = (pda.virtual_samples.points.par_iter())
            .zip(&edge_pixel)
            .map(|(p, &e)| if e { Outcome::Plain(None) } else { one(p, 1.0) })
            .collect();
        let edge: Vec<Outcome> = (pda.edge_samples.points.par_iter())
            .map(|p| one(p, share))
            .collect();
        self.scales = shading.scales_with.to_vec();
        let mut bytes = 0;
        let mut keep = |o: Outcome| -> Option<DVec3> {
            let (key, value, record) = match o {
                Outcome::Plain(v) => return v,
                Outcome::Kept(key, v) => (key, Some(v), old.remove(&key).unwrap_or_default()),
                Outcome::Fresh(key, v, record) => (key, v, record),
            };
            bytes += std::mem::size_of::<Record>()
                + record.lobes.len() * std::mem::size_of::<(Vec3, Option<Measured>)>()
                + record.diffuse.bytes();
            if bytes <= KEEP_BYTES {
                self.records.insert(key, record);
            }
            value
        };
        let mut kept = 0;
        let mut take = |o: Outcome| {
            kept += usize::from(matches!(o, Outcome::Kept(..)));
            keep(o)
        };
        let out = ShadedPoints {
            whole: whole.into_iter().map(&mut take).collect(),
            edge: edge.into_iter().map(&mut take).collect(),
        };
        self.kept = kept;
        out
    }
}

/// Each virtual point's radiance by `shade(point, share of its pixel)`.
fn shaded_points(
    pda: &PixelDataArray,
    shade: impl Fn(&SurfacePoint, f64) -> Option<DVec3> + Sync,
) -> ShadedPoints {
    let share = 1.0 / (pda.supersample * pda.supersample) as f64;
    ShadedPoints {
        whole: (pda.virtual_samples.points.par_iter())
            .zip(&at_edges(pda))
            .map(|(p, &e)| if e { None } else { shade(p, 1.0) })
            .collect(),
        edge: (pda.edge_samples.points.par_iter())
            .map(|p| shade(p, share))
            .collect(),
    }
}

/// Per whole virtual point, whether its pixel is an edge pixel, which the
/// composite shades from its sub-pixels alone (both lists in pixel order).
fn at_edges(pda: &PixelDataArray) -> Vec<bool> {
    let mut edges = pda.edges.iter().map(|e| e.pixel).peekable();
    (pda.virtual_pixels.iter())
        .map(|&pixel| {
            while edges.next_if(|&e| e < pixel).is_some() {}
            edges.peek() == Some(&pixel)
        })
        .collect()
}

/// The lights a sample's rays may reach with the objects in the way (those
/// lit): balls around them.
fn lit(lights: &[LightSource], scales: &[f64]) -> Vec<(DVec3, f64)> {
    (lights.iter().zip(scales))
        .filter(|(_, s)| **s > 0.0)
        .map(|(l, _)| l.ball())
        .collect()
}

/// Whether point `p`'s kept samples hold: its surface stood still and no
/// moved object comes near its camera rays, its shadow rays, its lobe's
/// rays or the shadow rays where they landed.
fn clear(
    movers: &dyn Movers,
    shading: &ObjectShading,
    p: &SurfacePoint,
    r: &Record,
    lights: &[(DVec3, f64)],
) -> bool {
    let eye = shading.camera.position;
    let x = p.position.as_dvec3();
    let spread = r.spread as f64;
    let towards_lights = |a: DVec3, slack: f64| {
        (lights.iter()).all(|&(c, radius)| movers.clear_towards(a, c, radius, slack))
    };
    movers.unmoved(p.surface)
        && movers.clear_towards(eye, r.view.0.as_dvec3(), r.view.1 as f64, 0.0)
        && towards_lights(x, spread)
        && r.lobes.iter().all(|(y, m)| {
            let y = y.as_dvec3();
            movers.clear_towards(x, y, 0.0, spread)
                && m.as_ref().is_none_or(|m| {
                    (!m.is_virtual || movers.unmoved(m.surface)) && towards_lights(y, 0.0)
                })
        })
}

/// The radiance of `p` from its kept samples over the solution `shading`
/// holds, summed as [`ObjectShading::shade_point`] sums them.
fn replay(shading: &ObjectShading, r: &Record) -> DVec3 {
    let reads = (r.lobes.iter().filter_map(|(_, m)| m.as_ref()))
        .fold(DVec3::ZERO, |sum, m| sum + m.radiance(shading));
    let diffuse = r.diffuse.light(shading.indirect_with);
    total(r.base, reads, diffuse, r.lobes.len() as u32)
}

/// A point's radiance from its samples' sums: `base` (emission, direct
/// light, lamps' reflections), `reads` (the lobes' rays that read the
/// solution), `diffuse` (the diffuse part's factors times the indirect
/// irradiance each sample's point reads).
pub(crate) fn total(base: DVec3, reads: DVec3, diffuse: DVec3, n: u32) -> DVec3 {
    (((base + reads) + diffuse / std::f64::consts::PI) / n as f64).max(DVec3::ZERO)
}

/// A pixel's diffuse factors, each sample's spread over the vertices its
/// point's indirect light is interpolated from: the light is then read at
/// every sample's own point for any solution, a sum over a few vertices.
/// Read at the pixel's centre for all of them instead, a pixel across a
/// curved object's facets lost what the interpolation varies over it
/// (`vase_floor` 0.930 → 0.928 against the truth, back to 0.930 so).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct DiffuseWeights(Vec<(u32, DVec3)>);

impl DiffuseWeights {
    /// Adds factor `d` at a point interpolated from `(vertex, weight)` pairs.
    pub(crate) fn add(&mut self, d: DVec3, at: impl IntoIterator<Item = (u32, f64)>) {
        for (v, w) in at.into_iter().filter(|&(v, w)| w != 0.0 && v != u32::MAX) {
            match self.0.iter_mut().find(|(u, _)| *u == v) {
                Some((_, c)) => *c += d * w,
                None => self.0.push((v, d * w)),
            }
        }
    }

    /// The factors times the vertices' indirect irradiance in `table` (none negative).
    pub(crate) fn light(&self, table: &[DVec3]) -> DVec3 {
        (self.0.iter()).fold(DVec3::ZERO, |sum, &(v, c)| {
            sum + c * table
                .get(v as usize)
                .copied()
                .unwrap_or(DVec3::ZERO)
                .max(DVec3::ZERO)
        })
    }

    /// Bytes held beside the record.
    pub(crate) fn bytes(&self) -> usize {
        self.0.len() * std::mem::size_of::<(u32, DVec3)>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diffuse_factors_read_the_light_at_each_samples_point() {
        // Two samples: one at vertex 0, one halfway between vertices 1 and 2.
        let mut w = DiffuseWeights::default();
        w.add(
            DVec3::ONE,
            [(0, 1.0), (u32::MAX, 0.0), (u32::MAX, 0.0), (u32::MAX, 0.0)],
        );
        w.add(
            DVec3::splat(2.0),
            [(1, 0.5), (2, 0.5), (7, 0.0), (u32::MAX, 0.0)],
        );
        let table = [DVec3::splat(3.0), DVec3::splat(-1.0), DVec3::splat(5.0)];
        // 1 × 3 + 2 × (0.5 × max(−1, 0) + 0.5 × 5): a negative vertex reads 0.
        assert_eq!(w.light(&table), DVec3::splat(8.0));
        assert_eq!(w.bytes(), 3 * std::mem::size_of::<(u32, DVec3)>());
        // A vertex met again adds to its factor.
        w.add(
            DVec3::ONE,
            [(2, 1.0), (u32::MAX, 0.0), (u32::MAX, 0.0), (u32::MAX, 0.0)],
        );
        assert_eq!(w.light(&table), DVec3::splat(13.0));
        assert_eq!(w.bytes(), 3 * std::mem::size_of::<(u32, DVec3)>());
    }

    /// What a session holds per lobe ray kept (`design/updates.md` gives it).
    #[test]
    fn a_kept_lobe_ray_takes_64_bytes() {
        assert_eq!(std::mem::size_of::<(Vec3, Option<Measured>)>(), 64);
    }
}
