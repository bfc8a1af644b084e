//! Final gathering from the photograph: rays over a point's hemisphere,
//! and the photo's own radiance wherever the camera sees what they meet.

use glam::DVec3;

use crate::camera::Camera;
use crate::image_io::Image;
use crate::trace::{Layer, TraceRay, Tracer};
use crate::util::rng::unit_random;

/// `side`² cosine-distributed directions about unit `n`, one per cell of a
/// `side` × `side` stratification, from the random `state`. Cells come in
/// 4 × 4 tiles: traced 16 at a time, a packet's rays then leave in
/// neighbouring directions (Embree's packets gain little from rays that
/// fan out over the whole hemisphere).
pub fn cosine_directions(n: DVec3, side: u32, mut state: u64) -> Vec<DVec3> {
    let t = if n.x.abs() < 0.9 {
        DVec3::X.cross(n).normalize()
    } else {
        DVec3::Y.cross(n).normalize()
    };
    let b = n.cross(t);
    const TILE: u32 = 4;
    let tiles = side.div_ceil(TILE);
    (0..tiles * tiles)
        .flat_map(|tile| {
            let (ti, tj) = (tile % tiles * TILE, tile / tiles * TILE);
            (0..TILE * TILE)
                .map(move |c| (ti + c % TILE, tj + c / TILE))
                .filter(|&(i, j)| i < side && j < side)
        })
        .map(|(i, j)| {
            let u1 = (i as f64 + unit_random(&mut state)) / side as f64;
            let u2 = (j as f64 + unit_random(&mut state)) / side as f64;
            let (r, phi) = (u1.sqrt(), std::f64::consts::TAU * u2);
            t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()
        })
        .collect()
}

/// Whether gathering rays from `p` over the hemisphere about unit `n`,
/// lifted off the surface as [`crate::light::offset_origin`] lifts them,
/// cannot meet a solid with corners `corners`: every corner lies behind
/// the plane through `p`, or in front by less than half the lift (what
/// single-precision rounding of the rays and corners may add). A ray then
/// starts in front of the whole solid and moves away from it.
pub fn clear_of_solid(corners: &[DVec3], p: DVec3, n: DVec3) -> bool {
    let slack = 0.5 * crate::light::origin_lift(p);
    corners.iter().all(|c| (*c - p).dot(n) <= slack)
}

/// The photo's radiance at the real point `y`, when the camera sees it
/// (inside the frame, nothing real in between).
pub(crate) fn photo_radiance_at(
    camera: &Camera,
    tracer: &Tracer,
    photo: &Image,
    y: DVec3,
) -> Option<DVec3> {
    photo_radiances(camera, tracer, photo, &[y])[0]
}

/// [`photo_radiance_at`] of many points, their rays back to the camera
/// traced in packets.
pub(crate) fn photo_radiances(
    camera: &Camera,
    tracer: &Tracer,
    photo: &Image,
    points: &[DVec3],
) -> Vec<Option<DVec3>> {
    let mut out = vec![None; points.len()];
    let mut framed: Vec<(usize, u32, u32)> = Vec::with_capacity(points.len());
    for (i, y) in points.iter().enumerate() {
        let Some((px, py, _)) = camera.project(*y) else {
            continue;
        };
        if px >= 0.0 && py >= 0.0 && px < camera.width as f64 && py < camera.height as f64 {
            framed.push((i, px as u32, py as u32));
        }
    }
    let back: Vec<TraceRay> = framed
        .iter()
        .map(|&(i, _, _)| TraceRay::segment(camera.position.as_vec3(), points[i].as_vec3(), 1e-4))
        .collect();
    let mut hidden = vec![false; back.len()];
    tracer.occluded_batch(&back, Layer::Real, &mut hidden);
    for (&(i, px, py), hidden) in framed.iter().zip(hidden) {
        if !hidden {
            out[i] = Some(photo.get(px, py).as_dvec3());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_fill_every_cell_of_the_stratification_once_in_tiles() {
        let n = DVec3::new(0.3, -0.5, 0.8).normalize();
        let t = if n.x.abs() < 0.9 {
            DVec3::X.cross(n).normalize()
        } else {
            DVec3::Y.cross(n).normalize()
        };
        let b = n.cross(t);
        // 12: whole tiles; 5 and 1: tiles cut at the edge.
        for side in [12u32, 5, 1] {
            let dirs = cosine_directions(n, side, 7);
            assert_eq!(dirs.len(), (side * side) as usize);
            let mut seen = vec![false; (side * side) as usize];
            for (k, d) in dirs.iter().enumerate() {
                assert!((d.length() - 1.0).abs() < 1e-12 && d.dot(n) >= 0.0);
                // Back to the cell: u1 = 1 − cos²θ, u2 = φ / 2π.
                let u1 = 1.0 - d.dot(n).powi(2);
                let u2 = d.dot(b).atan2(d.dot(t)).rem_euclid(std::f64::consts::TAU)
                    / std::f64::consts::TAU;
                let (i, j) = ((u1 * side as f64) as u32, (u2 * side as f64) as u32);
                assert!(!seen[(j * side + i) as usize], "cell ({i}, {j}) twice");
                seen[(j * side + i) as usize] = true;
                // A packet of 16 stays within one 4 × 4 tile.
                if side == 12 {
                    let tile = k / 16;
                    assert_eq!(
                        (i / 4 + j / 4 * 3) as usize,
                        tile,
                        "direction {k} outside its packet's tile"
                    );
                }
            }
        }
    }
}
