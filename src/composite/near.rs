//! Real pixels near the objects shaded again with the objects' change held
//! finer than the patches ([`NearField`]): a pass over the image after the
//! composite, so that the per-pixel loops stay as they are where no object
//! is near (most pixels, every pixel of a relit room).

use super::*;
use crate::radiosity::NearField;

/// Re-shades the plain real pixels of `out` whose patch holds a grid of
/// `field`, their interpolated indirect light corrected at their point.
/// Edge pixels keep the patch means (their real sub-pixels lie along an
/// object's outline, a pixel wide).
pub(super) fn refine(
    shader: &Shader,
    field: &NearField,
    h_with: &[[Vec3A; 4]],
    out: &mut Composite,
) {
    if field.patch_count() == 0 {
        return;
    }
    let pda = shader.pda();
    let first = out.first_row as usize * out.image.width as usize;
    let redone: Vec<(usize, PixelShade)> = (0..out.image.pixels.len())
        .into_par_iter()
        .filter_map(|local| {
            let i = first + local;
            let k = pda.real_at(i);
            if k == u32::MAX {
                return None;
            }
            let p = &pda.real.points[k as usize];
            let c = field.at(p.location.patch, p.position.as_dvec3())?;
            let s = shader.plain_with(i, h_with, Some(c.as_vec3a()))?;
            Some((local, s))
        })
        .collect();
    let layers = out.direct.pixels.len() == out.image.pixels.len();
    for (local, s) in redone {
        out.image.pixels[local] = s.value;
        out.alpha[local] = s.alpha;
        if layers {
            out.direct.pixels[local] = s.direct;
            out.indirect.pixels[local] = s.indirect;
            out.change.pixels[local] = s.value - shader.photo_at(first + local);
            out.object.pixels[local] = s.object;
        }
    }
}
