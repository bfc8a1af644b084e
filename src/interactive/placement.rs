//! Where an object may stand: the point a click sees, and the checks that
//! keep an object out of the room's solids and inside the room.

use glam::DVec3;

use super::Refusal;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::placement::object_points;
use crate::scene::{Pose, Scene, VirtualObject};
use crate::surface_ids::SurfaceIds;
use crate::trace::{Layer, TraceRay, Tracer};

/// A surface is floor-like when its normal lies within this angle of +y.
const FLOOR_DEG: f64 = 30.0;

/// The range of a placed light's height off the surface clicked, metres.
pub const LIGHT_HEIGHT_M: (f64, f64) = (0.05, 5.0);

/// Free space a placed light keeps beyond its height (a lamp's bulb is not a point).
const LIGHT_CLEARANCE_M: f64 = 0.05;

/// The room's real geometry, for picking and checking places.
pub struct Room {
    tracer: Tracer,
    names: Vec<String>,
    lo: DVec3,
    hi: DVec3,
    /// The real surface seen at each pixel centre.
    pub ids: SurfaceIds,
}

impl Room {
    pub fn new(scene: &Scene) -> Result<Room> {
        let tracer = Tracer::build(&crate::scene_tracer::real_triangle_sets(scene), &[])
            .map_err(|e| Error::file(&scene.file, e.to_string()))?;
        let (lo, hi) = scene.real_bounds();
        let margin = 0.01 * (hi - lo).length();
        let ids = SurfaceIds::at_pixel_centres(&scene.camera, &tracer, Layer::Real);
        Ok(Room {
            tracer,
            names: scene.surfaces.iter().map(|s| s.name.clone()).collect(),
            lo: lo - margin,
            hi: hi + margin,
            ids,
        })
    }

    /// The real surface point seen at image point (x, y), with its normal
    /// (facing the camera) and its surface's name.
    pub fn pick(
        &self,
        camera: &Camera,
        x: f64,
        y: f64,
    ) -> std::result::Result<(DVec3, DVec3, &str), Refusal> {
        for (field, v, size) in [("x", x, camera.width), ("y", y, camera.height)] {
            if !(v.is_finite() && (0.0..=size as f64).contains(&v)) {
                return Err(Refusal::new(
                    field,
                    format!("must be a pixel coordinate within 0..={size}"),
                ));
            }
        }
        let ray = camera.ray(x, y);
        let hit = self
            .tracer
            .intersect(
                &TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3()),
                Layer::Real,
            )
            .ok_or_else(|| Refusal::new("x", "no surface of the room is seen there"))?;
        let point = ray.origin + ray.direction * hit.t as f64;
        Ok((
            point,
            hit.normal.as_dvec3(),
            &self.names[hit.surface as usize],
        ))
    }

    /// Where `object` at `pose` (its rotation and scale kept) stands on the
    /// floor-like surface seen at (x, y): the translation that puts its
    /// footprint's centre (the middle of its lowest extent) on that point.
    pub fn standing_place(
        &self,
        camera: &Camera,
        object: &VirtualObject,
        pose: &Pose,
        (x, y): (f64, f64),
    ) -> std::result::Result<DVec3, Refusal> {
        let (point, normal, name) = self.pick(camera, x, y)?;
        if normal.y < FLOOR_DEG.to_radians().cos() {
            return Err(Refusal::new(
                "x",
                format!(
                    "'{name}' is not floor-like there (its normal is {:.0}° from vertical): objects stand on floors and tables",
                    normal.y.clamp(-1.0, 1.0).acos().to_degrees()
                ),
            ));
        }
        let turned = Pose {
            translate: DVec3::ZERO,
            ..*pose
        };
        let (lo, hi) = crate::geometry::bounds(object_points(object, &turned));
        let footprint = DVec3::new(0.5 * (lo.x + hi.x), lo.y, 0.5 * (lo.z + hi.z));
        Ok(point - footprint)
    }

    /// Where a light goes when placed `height` metres off the real surface
    /// seen at (x, y), along its normal (above a floor or a table, out from a
    /// wall, below a ceiling): refused where less room than that (and a
    /// lamp's clearance) is free there, or outside the room.
    pub fn light_place(
        &self,
        camera: &Camera,
        (x, y): (f64, f64),
        height: f64,
    ) -> std::result::Result<DVec3, Refusal> {
        let (lo, hi) = LIGHT_HEIGHT_M;
        if !(height.is_finite() && (lo..=hi).contains(&height)) {
            return Err(Refusal::new(
                "height_m",
                format!("a light's height off the surface must lie in {lo}..={hi} m"),
            ));
        }
        let (point, normal, name) = self.pick(camera, x, y)?;
        let ray = TraceRay {
            tnear: 1e-4,
            tfar: (height + LIGHT_CLEARANCE_M) as f32,
            ..TraceRay::new(point.as_vec3(), normal.as_vec3())
        };
        if let Some(hit) = self.tracer.intersect(&ray, Layer::Real) {
            return Err(Refusal::new(
                "height_m",
                format!(
                    "only {:.2} m is free off '{name}' there, before '{}' (a light needs {height:.2} m and {:.2} m of clearance)",
                    hit.t, self.names[hit.surface as usize], LIGHT_CLEARANCE_M
                ),
            ));
        }
        let at = point + normal * height;
        if at.cmplt(self.lo).any() || at.cmpgt(self.hi).any() {
            return Err(Refusal::new(
                "height_m",
                format!("{at:.2} lies outside the room"),
            ));
        }
        Ok(at)
    }

    /// Refuses `object` where it stands (its pose) when it leaves the
    /// room's box or cuts into a real surface: a segment from its centre to
    /// one of its vertices or face centres that crosses the room's geometry
    /// deeper than 5% of its size (see [`crate::placement::TOUCH`]).
    pub fn check_place(&self, object: &VirtualObject) -> std::result::Result<(), String> {
        let points: Vec<DVec3> = object_points(object, &object.pose).collect();
        let (lo, hi) = crate::geometry::bounds(points.iter().copied());
        if lo.cmplt(self.lo).any() || hi.cmpgt(self.hi).any() {
            return Err(format!(
                "'{}' would reach outside the room (its box {lo:.2}..{hi:.2}, the room's {:.2}..{:.2})",
                object.name, self.lo, self.hi
            ));
        }
        if let Some((surface, _)) =
            crate::placement::cut_into(&self.tracer, Layer::Real, object, &[])
        {
            return Err(format!(
                "'{}' would cut into '{}'",
                object.name, self.names[surface as usize]
            ));
        }
        Ok(())
    }
}
