//! Final gathering from the photograph: rays over a point's hemisphere,
//! and the photo's own radiance wherever the camera sees what they meet.

use glam::DVec3;

use crate::camera::Camera;
use crate::image_io::Image;
use crate::light::unit_random;
use crate::trace::{Layer, TraceRay, Tracer};

/// `side`² cosine-distributed directions about unit `n`, one per cell of a
/// `side` × `side` stratification, from the random `state`.
pub fn cosine_directions(n: DVec3, side: u32, mut state: u64) -> Vec<DVec3> {
    let t = if n.x.abs() < 0.9 { DVec3::X.cross(n).normalize() } else { DVec3::Y.cross(n).normalize() };
    let b = n.cross(t);
    (0..side * side)
        .map(|k| {
            let (i, j) = (k % side, k / side);
            let u1 = (i as f64 + unit_random(&mut state)) / side as f64;
            let u2 = (j as f64 + unit_random(&mut state)) / side as f64;
            let (r, phi) = (u1.sqrt(), std::f64::consts::TAU * u2);
            t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()
        })
        .collect()
}

/// The photo's radiance at the real point `y`, when the camera sees it
/// (inside the frame, nothing real in between).
pub fn photo_radiance_at(camera: &Camera, tracer: &Tracer, photo: &Image, y: DVec3) -> Option<DVec3> {
    photo_radiances(camera, tracer, photo, &[y])[0]
}

/// [`photo_radiance_at`] of many points, their rays back to the camera
/// traced in packets.
pub fn photo_radiances(camera: &Camera, tracer: &Tracer, photo: &Image, points: &[DVec3]) -> Vec<Option<DVec3>> {
    let mut out = vec![None; points.len()];
    let mut framed: Vec<(usize, u32, u32)> = Vec::with_capacity(points.len());
    for (i, y) in points.iter().enumerate() {
        let Some((px, py, _)) = camera.project(*y) else { continue };
        if px >= 0.0 && py >= 0.0 && px < camera.width as f64 && py < camera.height as f64 {
            framed.push((i, px as u32, py as u32));
        }
    }
    let back: Vec<TraceRay> = framed.iter().map(|&(i, _, _)| TraceRay::segment(camera.position.as_vec3(), points[i].as_vec3(), 1e-4)).collect();
    let mut hidden = vec![false; back.len()];
    tracer.occluded_batch(&back, Layer::Real, &mut hidden);
    for (&(i, px, py), hidden) in framed.iter().zip(hidden) {
        if !hidden {
            out[i] = Some(photo.get(px, py).as_dvec3());
        }
    }
    out
}
