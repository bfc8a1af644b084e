//! `stand = "below"`: an object dropped onto the real surface under its
//! footprint, as `arlux serve` places one where the user clicks, wherever
//! the scene, a variant or a motion puts it.

use glam::DVec3;

use super::{Scene, VirtualObject};
use crate::error::{Error, Result};

/// Where under its footprint an object looks for the surface it rests on:
/// the centre, and the corners of the footprint pulled in by a quarter.
const FOOTPRINT: [(f64, f64); 5] = [
    (0.5, 0.5),
    (0.125, 0.125),
    (0.875, 0.125),
    (0.125, 0.875),
    (0.875, 0.875),
];

impl Scene {
    /// Every object with `stand = "below"` (whose mesh was read) moved up
    /// or down so that its lowest point rests on the highest real surface
    /// found straight below its footprint, looking down from the middle of
    /// its height (an object half sunk into a table stands on the table).
    /// An error naming the object when no real surface lies below it.
    ///
    /// The real surfaces are searched triangle by triangle (a few rays per
    /// object, once per placement): no acceleration structure is needed
    /// for that, and the tracer is built later, from the placed objects.
    pub fn stand_objects(&mut self) -> Result<()> {
        for k in 0..self.objects.len() {
            let o = &self.objects[k];
            if !o.stand_below || !o.mesh_read {
                continue;
            }
            let lift = self.lift_onto_surface(o).ok_or_else(|| {
                Error::key(
                    &self.file,
                    format!("virtual '{}'.stand", o.name),
                    "no real surface lies below its footprint",
                )
            })?;
            self.objects[k].pose.translate.y += lift;
        }
        Ok(())
    }

    /// How far `o` moves up (negative: down) to rest on the surface below.
    fn lift_onto_surface(&self, o: &VirtualObject) -> Option<f64> {
        let points = (0..o.surfaces.len())
            .flat_map(|i| o.world_triangles(i))
            .flatten()
            .map(|p| p.as_dvec3());
        let (lo, hi) = crate::geometry::bounds(points);
        if lo.cmpgt(hi).any() {
            return None;
        }
        let from_y = 0.5 * (lo.y + hi.y);
        let triangles: Vec<_> = (self.surfaces.iter())
            .flat_map(|s| s.triangles.iter())
            .collect();
        let rest = FOOTPRINT
            .iter()
            .filter_map(|&(s, t)| {
                let from = DVec3::new(lo.x + s * (hi.x - lo.x), from_y, lo.z + t * (hi.z - lo.z));
                (triangles.iter())
                    .filter_map(|tri| crate::geometry::ray_triangle(from, DVec3::NEG_Y, tri))
                    .min_by(f64::total_cmp)
                    .map(|t| from_y - t)
            })
            .max_by(f64::total_cmp)?;
        Some(rest - lo.y)
    }
}
