//! Real pixels near the objects shaded again with the objects' change held
//! finer than the patches ([`NearField`]): a pass over the image after the
//! composite, so that the per-pixel loops stay as they are where no object
//! is near (most pixels, every pixel of a relit room). Where rounds of
//! per-pixel samples ran ([`crate::residual`]), a pixel's own estimate of
//! the change replaces the grid's.

use super::*;
use crate::radiosity::NearField;
use crate::residual::PixelResidual;

/// Re-shades the plain real pixels of `out` whose patch holds a grid of
/// `field`, their interpolated indirect light corrected at their point.
/// Edge pixels keep the patch means (their real sub-pixels lie along an
/// object's outline, a pixel wide).
pub(super) fn refine(
    shader: &Shader,
    field: Option<&NearField>,
    residual: Option<&PixelResidual>,
    h_with: &[[Vec3A; 4]],
    out: &mut Composite,
) {
    let sampled = residual
        .is_some_and(|r| !r.shadow.is_empty() || r.room_correction.iter().any(Option::is_some));
    if field.is_none_or(|f| f.patch_count() == 0) && !sampled {
        return;
    }
    let pda = shader.pda();
    let first = out.first_row as usize * out.image.width as usize;
    // Per real point, its entry in the shadow edges' list, found once (a
    // search of the list per pixel cost more than the pixels it finds).
    let edges = residual.map_or(&[][..], |r| &r.shadow[..]);
    let mut edge_of = vec![
        u32::MAX;
        if edges.is_empty() {
            0
        } else {
            pda.real.points.len()
        }
    ];
    for (at, &(k, _)) in edges.iter().enumerate() {
        edge_of[k as usize] = at as u32;
    }
    // The pixel's own samples where rounds ran, else the grid's; and its
    // footprint's terms where it lies on a shadow edge.
    let shade = |local: usize, k: u32| {
        let i = first + local;
        let p = &pda.real.points[k as usize];
        let own = residual.and_then(|r| r.room_correction.get(k as usize).copied().flatten());
        let c = own.or_else(|| {
            let f = field?.at(p.location.patch, p.position.as_dvec3())?;
            Some(f.as_vec3())
        });
        let terms = (edge_of.get(k as usize).copied())
            .filter(|&at| at != u32::MAX)
            .map(|at| footprint_terms(pda, &edges[at as usize]));
        if c.is_none() && terms.is_none() {
            return None;
        }
        shader.plain_with(i, h_with, c.map(Vec3A::from), terms.as_deref())
    };
    let rounds = residual.is_some_and(|r| r.room_correction.iter().any(Option::is_some));
    // Rounds may correct any pixel: each is asked. Else only the points of
    // the patches that hold a grid or a shadow edge's point can change (a
    // pass over every pixel to find them cost the desk's update as much as
    // shading them).
    let listed: Vec<(usize, u32)> = match rounds {
        true => (0..out.image.pixels.len())
            .map(|local| (local, pda.real_at(first + local)))
            .filter(|(_, k)| *k != u32::MAX)
            .collect(),
        false => listed_points(pda, field, edges, first),
    };
    // Shaded into a list as long as the points (collecting only those
    // shaded, in pieces that are then appended, cost as much again).
    let shaded: Vec<Option<PixelShade>> = (listed.par_iter())
        .map(|&(local, k)| shade(local, k))
        .collect();
    let layers = out.direct.pixels.len() == out.image.pixels.len();
    for (&(local, _), s) in listed.iter().zip(&shaded) {
        let Some(s) = s else { continue };
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

/// The real points (composite pixel, point) on the room patches that hold
/// a grid of `field` or one of `edges`' points, patch by patch.
fn listed_points(
    pda: &PixelDataArray,
    field: Option<&NearField>,
    edges: &[(u32, Vec<(u8, f32)>)],
    first: usize,
) -> Vec<(usize, u32)> {
    let by_patch = pda.real_by_patch();
    let mut patches: Vec<usize> = field.map_or(Vec::new(), |f| f.patches().collect());
    patches.extend(
        edges
            .iter()
            .map(|(k, _)| pda.real.points[*k as usize].location.patch as usize),
    );
    patches.sort_unstable();
    patches.dedup();
    let held = pda.first_pixel();
    (patches.iter())
        .flat_map(|&p| by_patch.of(p))
        .filter_map(|&(i, k)| Some(((held + i as usize).checked_sub(first)?, k)))
        .collect()
}

/// A real point's light terms with the objects' shadow averaged over its
/// pixel's footprint, as its entry `edge` in the shadow edges' list says.
fn footprint_terms(pda: &PixelDataArray, edge: &(u32, Vec<(u8, f32)>)) -> Vec<LightTerm> {
    let lights = pda.light_count;
    let k = edge.0 as usize;
    let mut terms = pda.real.terms[k * lights..(k + 1) * lights].to_vec();
    for &(l, v) in &edge.1 {
        let t = &mut terms[l as usize];
        *t = LightTerm::new(t.unoccluded, t.visible(false), v as f64);
    }
    terms
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pda::{PatchPoint, SurfacePoint};

    #[test]
    fn only_points_on_a_grids_patch_or_an_edges_patch_are_listed() {
        // Rows 1..3 of a 4-wide frame held: pixels 4..12, one without a
        // real point; the points' patches in pixel order.
        let patches = [
            Some(2),
            Some(0),
            None,
            Some(5),
            Some(2),
            Some(1),
            Some(5),
            Some(3),
        ];
        let mut pda = PixelDataArray::default();
        (pda.width, pda.height, pda.rows) = (4, 3, (1, 3));
        for p in patches {
            let Some(patch) = p else {
                pda.real_index.push(u32::MAX);
                continue;
            };
            pda.real_index.push(pda.real.points.len() as u32);
            pda.real.points.push(SurfacePoint {
                position: Vec3::ZERO,
                normal: Vec3::Z,
                surface: 0,
                is_virtual: false,
                pixel_terms: false,
                clear_of_own: false,
                location: PatchPoint {
                    patch,
                    weights: [1.0, 0.0, 0.0, 0.0],
                },
            });
        }
        // Grids on patches 2 and 4 (patch 4 holds no point); a shadow edge
        // at point 4 (pixel 5 of those held, on patch 1).
        let field = NearField::zero_on(6, &[2, 4]);
        let edges = vec![(4, vec![(0, 0.5)])];
        let first = pda.first_pixel();
        let mut listed = listed_points(&pda, Some(&field), &edges, first);
        listed.sort_unstable();
        // (composite pixel, point): patch 2's points at pixels 0 and 4,
        // patch 1's at pixel 5; patches 0, 3 and 5 hold neither.
        assert_eq!(listed, [(0, 0), (4, 3), (5, 4)]);
        // Without a field, only the edge's patch.
        assert_eq!(listed_points(&pda, None, &edges, first), [(5, 4)]);
    }
}
