//! The session's images for a screen: linear data as rendered, and 8-bit
//! sRGB at an exposure, for the views a page offers.

use glam::Vec3;
use rayon::prelude::*;

use super::Interactive;
use crate::image_io::{Image, linear_to_srgb, linear_to_srgb8};
use crate::surface_ids::{SurfaceIds, id_colour};

/// What a page shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// The augmented photo.
    Final,
    /// The photo as shot (the "before" of a before/after wipe).
    Photo,
    /// The shadow-catcher layer: the factor the change puts on the photo.
    Shadow,
    /// The model over the photo: each real surface in its colour, the
    /// virtual objects in white.
    Ids,
}

impl View {
    pub fn parse(name: &str) -> Option<View> {
        Some(match name {
            "final" => View::Final,
            "photo" => View::Photo,
            "shadow" => View::Shadow,
            "ids" => View::Ids,
            _ => return None,
        })
    }
}

/// What a screen needs of one state, apart from the photo and the room's
/// surface ids (which do not change): cheap to hand to another thread.
#[derive(Debug, Clone)]
pub struct Frame {
    pub version: u64,
    /// The augmented photo, linear.
    pub image: Image,
    /// The shadow-catcher factor (1 where nothing changed).
    pub shadow: Image,
    /// The virtual objects' coverage per pixel.
    pub alpha: Vec<f32>,
}

impl Interactive {
    /// The current state's [`Frame`].
    pub fn frame(&self) -> Frame {
        let (w, h) = (self.photo.width, self.photo.height);
        let (shadow, alpha) = match self.composite() {
            Some(c) => (c.shadow(&self.photo), c.alpha.clone()),
            None => {
                let mut ones = Image::new(w, h);
                ones.pixels.fill(Vec3::ONE);
                (ones, vec![0.0; (w * h) as usize])
            }
        };
        Frame {
            version: self.version,
            image: self.image().clone(),
            shadow,
            alpha,
        }
    }

    /// The exposure (stops) that brings the photo's mean to mid-grey.
    pub fn auto_exposure(&self) -> f32 {
        let mean = self.photo.mean().max(1e-12);
        (0.18 / mean).log2() as f32
    }
}

impl Frame {
    /// The view's linear data: radiance for the final image and the photo,
    /// the factor for the shadow layer.
    pub fn linear<'a>(&'a self, photo: &'a Image, view: View) -> &'a Image {
        match view {
            View::Final => &self.image,
            View::Shadow => &self.shadow,
            View::Photo | View::Ids => photo,
        }
    }

    /// The view as 8-bit sRGB RGBA, row-major, radiance × 2^`ev` (the
    /// shadow layer's factor as it is); `ids`: the room's surface per pixel.
    pub fn rgba(&self, photo: &Image, ids: &SurfaceIds, view: View, ev: f32) -> Vec<u8> {
        let gain = match view {
            View::Shadow => 1.0,
            _ => ev.exp2(),
        };
        let image = self.linear(photo, view);
        let mut out = vec![0u8; 4 * image.pixels.len()];
        // Row by row on every core, the bytes by table: what the server adds
        // to an update is mostly this.
        let width = image.width as usize;
        out.par_chunks_mut(4 * width)
            .enumerate()
            .for_each(|(row, bytes)| {
                for (k, px) in bytes.chunks_exact_mut(4).enumerate() {
                    let i = row * width + k;
                    if view != View::Ids {
                        let [r, g, b] = (image.pixels[i] * gain).to_array().map(linear_to_srgb8);
                        px.copy_from_slice(&[r, g, b, 255]);
                        continue;
                    }
                    let mut c = (image.pixels[i] * gain).to_array().map(linear_to_srgb);
                    let id = id_colour(ids.ids[i]).map(|v| v as f32 / 255.0);
                    let a = self.alpha.get(i).copied().unwrap_or(0.0);
                    for k in 0..3 {
                        let model = 0.5 * c[k] + 0.5 * id[k];
                        c[k] = model * (1.0 - a) + a;
                    }
                    let [r, g, b] = c.map(|v| (v * 255.0).round() as u8);
                    px.copy_from_slice(&[r, g, b, 255]);
                }
            });
        out
    }
}
