//! The objects' change to the room's indirect light at one point, by
//! rounds of rays: the near grid's estimator ([`super::NearView`]) at a
//! pixel's own point, which [`crate::residual`] averages over rounds.

use super::change::{
    Target, Towards, cone_towards, meet_target, rays_for, receiving_side, targets,
};
use super::near::taper;
use crate::light::offset_origin;
use crate::objects::VirtualBounds;
use crate::patches::Patches;
use crate::trace::{TraceRay, Tracer};
use glam::DVec3;

/// Rays per round from a point towards an object that fills its
/// hemisphere (fewer for a smaller cone, at least 4): a round's rays per
/// pixel stay of the order of an object pixel's gather.
const ROUND_RAYS: u32 = 16;

/// Samples the objects' first-order change at room points.
pub struct ChangeSampler<'a> {
    /// The room's patches (the first `room_count`) followed by the objects'.
    patches: &'a Patches,
    room_count: usize,
    targets: Vec<Target>,
    tracer: &'a Tracer,
}

impl<'a> ChangeSampler<'a> {
    pub fn new(
        patches: &'a Patches,
        objects: &VirtualBounds,
        room_count: usize,
        tracer: &'a Tracer,
    ) -> ChangeSampler<'a> {
        ChangeSampler {
            patches,
            room_count,
            targets: targets(objects),
            tracer,
        }
    }

    /// How much of a point's own change replaces the patch means at `x`
    /// (as the near grid's: all within an object's radius of it, none
    /// beyond twice), 0 on an object's patch.
    pub fn weight(&self, patch: u32, x: DVec3) -> f64 {
        if patch as usize >= self.room_count {
            return 0.0;
        }
        taper(x, &self.targets)
    }

    /// Round `round` of the change of irradiance at point `x` of room patch
    /// `patch`: each ray's estimate of the whole change (its radiance
    /// change × its weight × the rays of the round) passed to `add`, in a
    /// fixed order; returns the rays traced. `seed` keys the point's
    /// Sobol sequences. `read(hit, origin, direction, seed)` gives the
    /// radiance a ray meets at its hit and the rays that took: an object's
    /// with the objects there, a real surface's without them (what the
    /// object hides); a patch's mean radiosity varies too much near a
    /// lamp, or across an object lit at a grazing angle, to stand for it.
    pub fn sample<R>(
        &self,
        patch: u32,
        x: DVec3,
        (seed, round): (u64, u32),
        read: &R,
        add: &mut impl FnMut(DVec3),
    ) -> u64
    where
        R: Fn(&crate::trace::Hit, DVec3, DVec3, u64) -> (DVec3, u64),
    {
        let el = self.patches.patch(patch as usize);
        let cones: Vec<_> = (self.targets.iter())
            .filter_map(|t| {
                let n = receiving_side(el, t)?;
                let cone = cone_towards(x, 0.0, t);
                Some((t, n, cone, rays_for(cone.1, ROUND_RAYS)))
            })
            .collect();
        let total: u32 = cones.iter().map(|c| c.3).sum();
        let mut traced = 0;
        for &(t, n, cone, count) in &cones {
            let key = crate::util::rng::hash2(seed, t.surface as u64) as u32;
            let towards = Towards::new(n, cone, count);
            let dirs: Vec<(DVec3, f64)> = (0..count)
                .map(|r| {
                    let [u1, u2, _, _] =
                        sobol_burley::sample_4d(round * count + r, 0, key).map(f64::from);
                    towards.at(u1, u2)
                })
                .collect();
            let rays: Vec<TraceRay> = (dirs.iter())
                .map(|(d, _)| TraceRay::new(offset_origin(x, n, x + n).as_vec3(), d.as_vec3()))
                .collect();
            let (met, queries) =
                meet_target(self.tracer, &rays, t.surface, |r| dirs[r].0.dot(n) > 0.0);
            traced += queries;
            let mut met = met.into_iter().peekable();
            for (r, ray) in rays.iter().enumerate() {
                let Some((_, h, behind)) = met.next_if(|m| m.0 == r) else {
                    add(DVec3::ZERO);
                    continue;
                };
                let (d, w) = dirs[r];
                let seed = crate::util::rng::hash2(key as u64, (round * count + r as u32) as u64);
                let (change, rays) = self.change_along(ray, d, (&h, behind.as_ref()), seed, read);
                traced += rays;
                add(change * (w * total as f64));
            }
        }
        traced
    }

    /// The radiance of the object `hit` meets along `ray` less the room's
    /// it hides there (`behind`, the room's first hit), and the rays that took.
    fn change_along<R>(
        &self,
        ray: &TraceRay,
        d: DVec3,
        (hit, behind): (&crate::trace::Hit, Option<&crate::trace::Hit>),
        seed: u64,
        read: &R,
    ) -> (DVec3, u64)
    where
        R: Fn(&crate::trace::Hit, DVec3, DVec3, u64) -> (DVec3, u64),
    {
        let o = ray.origin.as_dvec3();
        let (with, mut rays) = read(hit, o, d, seed);
        let behind = match behind {
            Some(b) => {
                let (l, r) = read(b, o, d, crate::util::rng::hash2(seed, 1));
                rays += r;
                l
            }
            None => DVec3::ZERO,
        };
        (with - behind, rays)
    }
}
