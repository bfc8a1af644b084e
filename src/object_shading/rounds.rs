//! An object pixel's radiance sampled in the residual's rounds
//! ([`crate::residual`]), so that more rounds buy a sharper estimate of
//! what a pixel averages: a lamp's highlight on a metal, a texture's
//! detail, a shadow's edge over the object.
//!
//! A sample is a camera ray through a point of the pixel and one sample of
//! the light leaving the point it meets (each light once, one ray from the
//! specular lobe), as [`ObjectShading::radiance`] draws them. Its numbers
//! come from an Owen-scrambled Sobol sequence keyed by the pixel: the
//! pixel's point and the lobe's direction are dimensions 0-3 of one point
//! (stratified jointly), each light's point on its rectangle dimensions
//! 4-5 under a seed of its own. Round `r` takes points `r·k..(r+1)·k`, so
//! the image is the same whatever the thread count and order. A pixel
//! shaded without rounds ([`ObjectShading::radiance`]) draws its samples
//! from the same kind of sequence.

use super::*;
use crate::trace::Hit;

/// A sample's light towards the camera, split so that the irradiance the
/// rounds gather at the pixel can be applied once they end.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Split {
    /// Emission, direct light and the reflected room.
    pub own: DVec3,
    /// The diffuse part's factor of the indirect irradiance over π.
    pub diffuse: DVec3,
}

/// The rect lights a sample may meet, listed once for many samples.
pub(crate) struct Lamps(Vec<paths::Rect>);

/// A round sample's point of the pixel's Sobol sequence.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sobol {
    index: u32,
    key: u32,
    /// The specular lobe's two numbers.
    pub(super) lobe: [f64; 2],
}

impl Sobol {
    /// Point `index` of the sequence keyed by `key`, its lobe's numbers given.
    pub(super) fn new(index: u32, key: u32, lobe: [f64; 2]) -> Sobol {
        Sobol { index, key, lobe }
    }

    /// Light `l`'s point on its rectangle, in [0, 1)².
    pub(super) fn light(&self, l: usize) -> glam::DVec2 {
        let seed = self.key ^ (l as u32 + 1).wrapping_mul(0x9E37_79B9);
        let [s, t, _, _] = sobol_burley::sample_4d(self.index, 1, seed);
        glam::DVec2::new(s as f64, t as f64)
    }
}

/// What a round's sample of a pixel met.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Footprint {
    /// A surface with a material, and its light.
    Shaded(Split),
    /// No object with a material (the room, or nothing): an outline's
    /// other part.
    Elsewhere,
    /// An object without a material, or a part an alpha mask cuts away:
    /// the pixel is shaded as without rounds.
    Unsampled,
}

impl ObjectShading<'_> {
    /// The rect lights, for [`ObjectShading::footprint_sample`] and
    /// [`ObjectShading::leaving`] (a list a sample would otherwise make).
    pub(crate) fn lamps(&self) -> Lamps {
        Lamps(self.rects())
    }

    /// How many samples a whole pixel on `centre` draws without rounds (as
    /// [`ObjectShading::radiance`] does): each round adds as many. None
    /// where the camera sees no surface with a material there.
    pub(crate) fn samples_per_pixel(&self, centre: &SurfacePoint) -> Option<u32> {
        let to = centre.position.as_dvec3() - self.camera.position;
        match self.seen(to.normalize_or_zero(), to.length() * 1.001 + 1e-4, 1.0)? {
            Seen::Shaded(point) => Some(self.sample_count(&point.lobes, 1.0)),
            _ => None,
        }
    }

    /// Sample `index` of the pixel whose top-left corner is `corner` (image
    /// coordinates), its sequence keyed by `key`, `lamps` the rect lights.
    /// Where the sample's ray
    /// meets no surface with a material, `centre` (a plain pixel's point in
    /// the pixel data) is shaded instead, if given. Returns what it met and
    /// the rays it traced.
    pub(crate) fn footprint_sample(
        &self,
        lamps: &Lamps,
        centre: Option<&SurfacePoint>,
        corner: (f64, f64),
        index: u32,
        key: u32,
    ) -> (Footprint, u64) {
        let [fx, fy, u1, u2] = sobol_burley::sample_4d(index, 0, key).map(f64::from);
        let ray = self.camera.ray(corner.0 + fx, corner.1 + fy);
        // A sample stands for a small part of the pixel: its texture read
        // finer than the whole footprint, which the samples average.
        let point = match (self.seen(ray.direction, f64::INFINITY, 0.125), centre) {
            (Some(Seen::Shaded(point)), _) => point,
            (Some(Seen::Clay | Seen::Masked), _) => return (Footprint::Unsampled, 1),
            (None, None) => return (Footprint::Elsewhere, 1),
            (None, Some(c)) => {
                let to = c.position.as_dvec3() - self.camera.position;
                let far = to.length() * 1.001 + 1e-4;
                match self.seen(to.normalize_or_zero(), far, 0.125) {
                    Some(Seen::Shaded(point)) => point,
                    _ => return (Footprint::Unsampled, 2),
                }
            }
        };
        let sample = Sample {
            j: index,
            seed: hash2(key as u64, index as u64),
            sobol: Sobol::new(index, key, [u1, u2]),
        };
        // The camera ray, a shadow ray per light, the lobe's ray and a
        // shadow ray per light where it lands.
        let rays = 2 + 2 * self.lights.len() as u64;
        let split = self.split_sample(&point, &lamps.0, sample);
        (Footprint::Shaded(split), rays)
    }
}

impl ObjectShading<'_> {
    /// The radiance leaving the object surface `hit` towards the origin `o`
    /// of the ray along unit `d` that met it, when the surface has a
    /// material (None: clay, or cut away), `lamps` the rect lights: one sample of its lights and
    /// lobe, keyed by `seed`, and the diffuse part's indirect irradiance
    /// interpolated from its vertices; and the rays that took. A glossy
    /// object seen at a grazing angle mirrors the room, and a metal the
    /// lamps (the light it focuses onto the floor), which its diffuse
    /// radiosity alone leaves out.
    pub(crate) fn leaving(
        &self,
        lamps: &Lamps,
        hit: &Hit,
        (o, d): (DVec3, DVec3),
        seed: u64,
        round: u32,
    ) -> Option<(DVec3, u64)> {
        let s = self.materials.surfaces.get(&hit.surface)?;
        let x = o + d * hit.t as f64;
        // A ray from the room stands for a part of a cone, not a pixel:
        // the texture read at a footprint of a hundredth of its length.
        let mut point = self.point(s, hit.triangle, x, d, 0.01 * hit.t as f64)?;
        point.lobes.roughness = point.lobes.roughness.max(regularized(round));
        let key = seed as u32;
        let [u1, u2, _, _] = sobol_burley::sample_4d(0, 0, key);
        let sample = Sample {
            j: 0,
            seed,
            sobol: Sobol::new(0, key, [u1 as f64, u2 as f64]),
        };
        let split = self.split_sample(&point, &lamps.0, sample);
        let h = self
            .patches
            .locate(hit.surface, hit.triangle, x)
            .map_or(DVec3::ZERO, |at| {
                self.patches.interpolate(self.indirect_with, &at)
            })
            .max(DVec3::ZERO);
        let rays = 2 + 2 * self.lights.len() as u64;
        Some((split.own + split.diffuse * h / std::f64::consts::PI, rays))
    }
}

/// The least roughness an object's lobe takes, in round `round`, where a
/// ray from the room meets it: 0.7 in round 0, falling as (round + 1)^-¼
/// (0.35 by round 15, 0.25 by round 63, 0.12 by round 1023). A metal's
/// narrow lobe reflects a lamp into a small part of the object, which few
/// of a room point's rays find, each carrying the lamp's radiance: at 4
/// rounds those rare, bright rays made `chrome_floor` and `trio` worse
/// than without rounds (0.958 -> 0.954, 0.963 -> 0.957). Widening the lobe
/// spreads the lamp's reflection over more of the object and more rays,
/// at a lower radiance; as rounds grow the lobe returns to the material's
/// own, so the estimate converges to the unwidened one (path-space
/// regularisation, Kaplanyan & Dachsbacher 2013). Measured on
/// `chrome_floor`, `vase_floor` and `trio` at 4, 16 and 64 rounds, 0.5 to
/// 1.0 in round 0 gave skills within 0.01 of each other; 0.7 was best at
/// 4 rounds.
fn regularized(round: u32) -> f64 {
    0.7 * ((round + 1) as f64).powf(-0.25)
}
