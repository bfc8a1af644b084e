//! The display of a light change (Loscos Eq. 3 in floating point): each
//! pixel's texture × B/D, the radiosity where the photo saw it unlit.

use super::*;

impl TexturePath {
    /// Per pixel B/D: each light's exact unoccluded irradiance times the
    /// mesh's visibility, plus the mesh's indirect light, over D.
    pub(super) fn display(&self, scales: &[f64], indirect: &[DVec3]) -> Composite {
        let p = &self.patches;
        let h_v = p.vertex_values(indirect);
        let pi = std::f64::consts::PI;
        let photo = &self.photo;
        let nl = self.lights.len();
        let (w, h) = (photo.width, photo.height);
        let mut out = Composite {
            first_row: 0,
            image: Image::new(w, h),
            direct: Image::new(w, h),
            indirect: Image::new(w, h),
            change: Image::new(w, h),
            object: Image::new(w, h),
            alpha: vec![0.0; (w * h) as usize],
            copied: 0,
            ratio_fallbacks: 0,
            clamped: 0,
            noise: Vec::new(),
        };
        out.fill(photo, crate::image_io::PixelRect::full(w, h), |i| {
            let Some(px) = &self.pixels[i] else {
                return PixelShade {
                    value: photo.pixels[i],
                    direct: Vec3::ZERO,
                    indirect: Vec3::ZERO,
                    alpha: 0.0,
                    object: Vec3::ZERO,
                    copied: true,
                    fallback: false,
                    clamped: false,
                };
            };
            let (at, texture) = match px {
                PixelPoint::Real { at, texture, texel } => (
                    at,
                    Some(self.textures[*texture as usize].texels[*texel as usize]),
                ),
                PixelPoint::Virtual { at } => (at, None),
            };
            let mut e = DVec3::ZERO;
            for (l, &s) in scales.iter().enumerate() {
                if s > 0.0 {
                    let v: f64 = at
                        .weights
                        .iter()
                        .map(|&(k, w)| self.visibility[l][k as usize] * w)
                        .sum();
                    e += self.unoccluded[i * nl + l].as_dvec3() * (s * v.clamp(0.0, 1.0));
                }
            }
            let hh = p.interpolate(&h_v, at);
            let rho = self.reflectance[at.patch as usize];
            let mut fallback = false;
            let value = match texture {
                Some(t) => {
                    let d = self.display[i].as_dvec3();
                    if luminance(d) > self.d_floor && d.min_element() > 0.0 {
                        t.as_dvec3() * (e + hh) / d
                    } else {
                        // D ≈ 0: the photo saw this surface unlit; only the model knows it.
                        fallback = true;
                        rho * (e + hh) / pi
                    }
                }
                None => rho * (e + hh) / pi,
            };
            let value = if value.is_finite() {
                value.max(DVec3::ZERO)
            } else {
                DVec3::ZERO
            }
            .as_vec3();
            let alpha = if texture.is_some() { 0.0 } else { 1.0 };
            PixelShade {
                value,
                direct: e.as_vec3(),
                indirect: hh.as_vec3(),
                alpha,
                object: value * alpha,
                copied: false,
                fallback,
                clamped: false,
            }
        });
        out
    }
}
