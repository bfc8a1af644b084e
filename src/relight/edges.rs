//! The objects' outlines on the texture path. Its pixels are points (one
//! ray through each centre), so an object's edge was a staircase where the
//! pixel path mixes the object and the room by their share of the pixel.
//! Here each pixel beside an outline counts its n × n sub-rays that meet an
//! object (the pixel path's supersampling, 4 × 4 by default) and mixes, by
//! that share, the object's light with the room's seen beside it: the
//! pixel's own where its centre sees that side, else its neighbours' mean
//! on the other side.

use super::*;
use crate::camera::Camera;
use crate::trace::TraceRay;

/// Sub-rays per pixel side: the pixel path's default supersampling.
const SIDE: u32 = 4;

impl TexturePath {
    /// Mixes the pixels along the objects' outlines in `out` by their
    /// coverage (its image, alpha, object and change layers).
    pub(super) fn antialias_edges(&self, out: &mut Composite, camera: &Camera, tracer: &Tracer) {
        let (w, h) = (out.image.width as usize, out.image.height as usize);
        if w == 0 || h == 0 || tracer.virtual_objects.is_none() {
            return;
        }
        let is_object = |i: usize| matches!(self.pixels[i], Some(PixelPoint::Virtual { .. }));
        let image = &out.image.pixels;
        let mixed: Vec<(usize, f32, Vec3, Vec3)> = (0..w * h)
            .into_par_iter()
            .filter_map(|i| {
                let (x, y) = (i % w, i / w);
                let centre = is_object(i);
                let (sum, count) = neighbours(x, y, w, h)
                    .filter(|&j| is_object(j) != centre)
                    .fold((Vec3::ZERO, 0u32), |(s, c), j| (s + image[j], c + 1));
                if count == 0 {
                    return None;
                }
                let coverage = coverage(camera, tracer, x as u32, y as u32);
                let beside = sum / count as f32;
                let (object, room) = if centre {
                    (image[i], beside)
                } else {
                    (beside, image[i])
                };
                Some((i, coverage, object, room))
            })
            .collect();
        let layers = out.object.pixels.len() == out.image.pixels.len();
        for (i, a, object, room) in mixed {
            let value = object * a + room * (1.0 - a);
            out.image.pixels[i] = value;
            if layers {
                out.alpha[i] = a;
                out.object.pixels[i] = object * a;
                out.change.pixels[i] = value - self.photo.pixels[i];
            }
        }
    }
}

/// The 4-neighbours of (x, y) inside a w × h frame, as indices.
fn neighbours(x: usize, y: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let at = move |dx: isize, dy: isize| {
        let (nx, ny) = (x as isize + dx, y as isize + dy);
        (nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h)
            .then(|| ny as usize * w + nx as usize)
    };
    [(-1, 0), (1, 0), (0, -1), (0, 1)]
        .into_iter()
        .filter_map(move |(dx, dy)| at(dx, dy))
}

/// The share of pixel (x, y)'s SIDE × SIDE sub-rays (cell centres) whose
/// nearest surface is an object's.
fn coverage(camera: &Camera, tracer: &Tracer, x: u32, y: u32) -> f32 {
    let n = SIDE * SIDE;
    let rays: Vec<TraceRay> = (0..n)
        .map(|k| {
            let (sx, sy) = ((k % SIDE) as f64 + 0.5, (k / SIDE) as f64 + 0.5);
            let r = camera.ray(x as f64 + sx / SIDE as f64, y as f64 + sy / SIDE as f64);
            TraceRay::new(r.origin.as_vec3(), r.direction.as_vec3())
        })
        .collect();
    let mut hits = vec![None; rays.len()];
    tracer.intersect_batch(&rays, Layer::All, &mut hits);
    hits.iter().flatten().filter(|h| h.is_virtual).count() as f32 / n as f32
}
