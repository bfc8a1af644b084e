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
//! the image is the same whatever the thread count and order.

use super::*;

/// A sample's light towards the camera, split so that the irradiance the
/// rounds gather at the pixel can be applied once they end.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Split {
    /// Emission, direct light and the reflected room.
    pub own: DVec3,
    /// The diffuse part's factor of the indirect irradiance over π.
    pub diffuse: DVec3,
}

/// A round sample's point of the pixel's Sobol sequence.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sobol {
    index: u32,
    key: u32,
    /// The specular lobe's two numbers.
    pub(super) lobe: [f64; 2],
}

impl Sobol {
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
    /// Sample `index` of the pixel whose top-left corner is `corner` (image
    /// coordinates), its sequence keyed by `key`. Where the sample's ray
    /// meets no surface with a material, `centre` (a plain pixel's point in
    /// the pixel data) is shaded instead, if given. Returns what it met and
    /// the rays it traced.
    pub(crate) fn footprint_sample(
        &self,
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
        let sobol = Sobol {
            index,
            key,
            lobe: [u1, u2],
        };
        let sample = Sample {
            j: index,
            n: 1,
            seed: hash2(key as u64, index as u64),
            sobol: Some(sobol),
        };
        let rects = self.rects();
        // The camera ray, a shadow ray per light, the lobe's ray and a
        // shadow ray per light where it lands.
        let rays = 2 + 2 * self.lights.len() as u64;
        let split = self.split_sample(&point, &rects, sample);
        (Footprint::Shaded(split), rays)
    }
}
