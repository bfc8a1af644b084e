//! The session's images for a screen: linear data as rendered, and 8-bit
//! sRGB at an exposure, for the views a page offers.

use glam::Vec3;

use super::Interactive;
use crate::image_io::{Image, linear_to_srgb};
use crate::surface_ids::id_colour;

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

impl Interactive {
    /// The exposure (stops) that brings the photo's mean to mid-grey.
    pub fn auto_exposure(&self) -> f32 {
        let mean = self.photo.mean().max(1e-12);
        (0.18 / mean).log2() as f32
    }

    /// The view's linear data: radiance for the final image and the photo,
    /// the factor for the shadow layer (1 where nothing changed).
    pub fn linear(&self, view: View) -> Image {
        match (view, self.composite()) {
            (View::Final, _) => self.image().clone(),
            (View::Shadow, Some(c)) => c.shadow(&self.photo),
            (View::Shadow, None) => {
                let mut ones = Image::new(self.photo.width, self.photo.height);
                ones.pixels.fill(Vec3::ONE);
                ones
            }
            (View::Photo | View::Ids, _) => self.photo.clone(),
        }
    }

    /// The view as 8-bit sRGB RGBA, row-major, radiance × 2^`ev` (the shadow
    /// layer's factor is shown as it is).
    pub fn rgba(&self, view: View, ev: f32) -> Vec<u8> {
        let gain = match view {
            View::Shadow => 1.0,
            _ => ev.exp2(),
        };
        let image = self.linear(view);
        let alpha = self.composite().map(|c| c.alpha.as_slice());
        let mut out = Vec::with_capacity(4 * image.pixels.len());
        for (i, p) in image.pixels.iter().enumerate() {
            let mut c = (*p * gain).to_array().map(linear_to_srgb);
            if view == View::Ids {
                let id = id_colour(self.room.ids.ids[i]).map(|v| v as f32 / 255.0);
                let a = alpha.and_then(|a| a.get(i)).copied().unwrap_or(0.0);
                for k in 0..3 {
                    let model = 0.5 * c[k] + 0.5 * id[k];
                    c[k] = model * (1.0 - a) + a;
                }
            }
            out.extend(c.map(|v| (v * 255.0).round() as u8));
            out.push(255);
        }
        out
    }
}
