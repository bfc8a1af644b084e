//! [`SurfaceIds`]: which surface the camera sees at each pixel centre, and
//! the registration picture a user checks the model against the photo with
//! (`arlux ids`): a colour per surface beside the photo overlaid with the
//! surfaces' outlines.

use glam::Vec3;
use rayon::prelude::*;

use crate::camera::Camera;
use crate::image_io::{Image, linear_to_srgb8};
use crate::trace::{Hit, Layer, TraceRay, Tracer};

/// The closest hits of the rays through the pixel centres of one image row,
/// traced in packets, in the given layer.
pub fn row_hits(camera: &Camera, tracer: &Tracer, layer: Layer, row: u32) -> Vec<Option<Hit>> {
    let rays: Vec<TraceRay> = (0..camera.width)
        .map(|col| {
            let r = camera.pixel_ray(col, row);
            TraceRay::new(r.origin.as_vec3(), r.direction.as_vec3())
        })
        .collect();
    let mut hits = vec![None; rays.len()];
    tracer.intersect_batch(&rays, layer, &mut hits);
    hits
}

/// Surface id per pixel, row-major; -1 where the ray leaves the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceIds {
    pub width: u32,
    pub height: u32,
    pub ids: Vec<i32>,
}

impl SurfaceIds {
    /// Traces one ray through every pixel centre, in the given layer.
    pub fn at_pixel_centres(camera: &Camera, tracer: &Tracer, layer: Layer) -> SurfaceIds {
        let w = camera.width as usize;
        let mut ids = vec![-1i32; camera.pixel_count()];
        ids.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
            for (o, h) in out
                .iter_mut()
                .zip(row_hits(camera, tracer, layer, row as u32))
            {
                *o = h.map_or(-1, |h| h.surface as i32);
            }
        });
        SurfaceIds {
            width: camera.width,
            height: camera.height,
            ids,
        }
    }

    /// How many pixels see some surface.
    pub fn covered(&self) -> usize {
        self.ids.iter().filter(|&&i| i >= 0).count()
    }

    /// Whether the pixel differs in id from its right or lower neighbour.
    pub(crate) fn is_outline(&self, x: u32, y: u32) -> bool {
        let w = self.width as usize;
        let i = y as usize * w + x as usize;
        (x + 1 < self.width && self.ids[i + 1] != self.ids[i])
            || (y + 1 < self.height && self.ids[i + w] != self.ids[i])
    }

    /// The registration picture, 2·width × height, sRGB bytes: left, a colour
    /// per surface (black where nothing is hit); right, the photo (exposed so
    /// its mean is mid-grey) with every surface outline drawn in that surface's colour.
    pub fn registration_picture(&self, photo: &Image) -> Vec<u8> {
        let (w, h) = (self.width, self.height);
        let mean = photo.mean().max(1e-12) as f32;
        let gain = 0.18 / mean;
        let mut out = vec![0u8; 6 * (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let id = self.ids[(y * w + x) as usize];
                let colour = id_colour(id);
                let left = (y as usize * 2 * w as usize + x as usize) * 3;
                out[left..left + 3].copy_from_slice(&colour);
                let right = left + 3 * w as usize;
                let px = if self.is_outline(x, y) {
                    colour.map(|c| c.max(40))
                } else {
                    (photo.get(x, y) * gain).to_array().map(linear_to_srgb8)
                };
                out[right..right + 3].copy_from_slice(&px);
            }
        }
        out
    }
}

/// A distinct, saturated colour per surface id (golden-ratio hues); black for -1.
pub fn id_colour(id: i32) -> [u8; 3] {
    if id < 0 {
        return [0, 0, 0];
    }
    let hue = (id as f32 * 0.618_034).fract() * 6.0;
    let value = if id % 2 == 0 { 1.0 } else { 0.75 };
    let f = hue.fract();
    let rgb = match hue as u32 {
        0 => Vec3::new(1.0, f, 0.0),
        1 => Vec3::new(1.0 - f, 1.0, 0.0),
        2 => Vec3::new(0.0, 1.0, f),
        3 => Vec3::new(0.0, 1.0 - f, 1.0),
        4 => Vec3::new(f, 0.0, 1.0),
        _ => Vec3::new(1.0, 0.0, 1.0 - f),
    } * value;
    rgb.to_array().map(|c| (c * 255.0).round() as u8)
}
