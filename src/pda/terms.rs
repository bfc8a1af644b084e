//! One real or virtual point's light term for one light: the visibility
//! oracle's shadow rays through the room and the objects.

use super::*;

/// Visibility of one light from x through the two worlds, by the oracle.
/// `before`: for a term computed before, its geometry factor (when
/// positive) and whether the objects may shadow x now (the pixel-block
/// traversal's answer; where it differs from [`VirtualBounds::may_shadow`],
/// one of the two excludes the objects and their rays meet nothing);
/// `real`: the real blockers already known for these samples, where rays
/// traced through the room are kept (a real point's; samples beyond
/// [`RealMask::MAX_SAMPLES`] are always traced).
#[allow(clippy::too_many_arguments)]
pub(super) fn light_term(
    tracer: &Tracer,
    light: &LightSource,
    bounds: &VirtualBounds,
    own: Option<usize>,
    x: DVec3,
    n: DVec3,
    seed: u64,
    settings: PdaSettings,
    before: Option<(f32, bool)>,
    mut real: Option<&mut RealMask>,
) -> (LightTerm, u64) {
    let unoccluded = match before {
        Some((u, _)) if u > 0.0 => u,
        _ => {
            let g = light.unoccluded_irradiance(x, n);
            let colour = light.colour().max_element();
            if g == DVec3::ZERO || colour <= 0.0 {
                return (LightTerm::default(), 0);
            }
            (g.max_element() / colour) as f32
        }
    };
    let check_virtual = before.map_or_else(|| bounds.may_shadow(x, light, own), |(_, may)| may);
    // On a face clear of its own solid (and no other object near), what
    // the solid blocks is known without tracing: whatever lies behind the
    // face, which a ray reaches only through the solid — and everything
    // when the light's centre is behind it, as the rays then leave from
    // the solid's side of the face ([`offset_origin`]).
    let own_blocks = |y: DVec3| own.is_some() && own_blocks(x, n, light.position, y);
    let origin = offset_origin(x, n, light.position);
    let Some(grid) = &light.grid else {
        let ray = segment(origin, light.position);
        let (real_visible, mut rays_cast) = match real.as_ref().and_then(|m| m.get(false)) {
            Some(bits) => (bits == 0, 0),
            None => {
                let blocked = tracer.occluded(&ray, Layer::Real);
                if let Some(m) = real {
                    m.set(false, blocked as u16);
                }
                (!blocked, 1)
            }
        };
        let all = real_visible
            && !if check_virtual {
                tracer.occluded(&ray, Layer::Virtual)
            } else {
                own_blocks(light.position)
            };
        rays_cast += (real_visible && check_virtual) as u64;
        let f = |b: bool| if b { 1.0 } else { 0.0 };
        return (
            LightTerm::new(unoccluded, f(real_visible), f(all)),
            rays_cast,
        );
    };
    // Buffers for the most rays one call may cast: on the stack for the
    // usual budgets (filling 256 entries per pixel and light, whatever the
    // budget, cost more than the shading around it), on the heap beyond.
    let most = 1usize
        << settings
            .min_level
            .max(settings.penumbra_level)
            .min(crate::light::MAX_GRID_LEVEL);
    const SMALL: usize = 16;
    let mut run = |targets: &mut [DVec3],
                   rays: &mut [TraceRay],
                   real_blocked: &mut [bool],
                   virt_blocked: &mut [bool]|
     -> (LightTerm, u64) {
        let mut level = settings.min_level;
        let mut rays_cast = 0u64;
        loop {
            let mut count = 0;
            for st in grid.samples(level, seed) {
                targets[count] = light.point_at(st);
                rays[count] = segment(origin, targets[count]);
                count += 1;
            }
            let penumbra = level != settings.min_level;
            let keep = real
                .as_deref_mut()
                .filter(|_| count <= RealMask::MAX_SAMPLES);
            match keep.as_ref().and_then(|m| m.get(penumbra)) {
                Some(bits) => (0..count).for_each(|k| real_blocked[k] = bits >> k & 1 == 1),
                None => {
                    tracer.occluded_batch(&rays[..count], Layer::Real, &mut real_blocked[..count]);
                    rays_cast += count as u64;
                    if let Some(m) = keep {
                        m.set(
                            penumbra,
                            (0..count).fold(0u16, |b, k| b | (real_blocked[k] as u16) << k),
                        );
                    }
                }
            }
            if check_virtual {
                tracer.occluded_batch(&rays[..count], Layer::Virtual, &mut virt_blocked[..count]);
                rays_cast += count as u64;
            } else {
                for k in 0..count {
                    virt_blocked[k] = own_blocks(targets[k]);
                }
            }
            // Which rays the room blocks, and which it or the objects block:
            // some, and some not, of each.
            let (mut real_some, mut real_none, mut all_some, mut all_none) =
                (false, false, false, false);
            for k in 0..count {
                let all = real_blocked[k] || virt_blocked[k];
                real_some |= real_blocked[k];
                real_none |= !real_blocked[k];
                all_some |= all;
                all_none |= !all;
            }
            let (real_mixed, all_mixed) = (real_some && real_none, all_some && all_none);
            if level < settings.penumbra_level && (real_mixed || all_mixed) {
                level = settings.penumbra_level;
                continue;
            }
            // Where no ray or every ray is blocked the fractions are 1 or 0
            // whatever the rays weigh: the weights (the light's intensity
            // towards x per sample) are needed only for the rest.
            if !real_mixed && !all_mixed {
                let settled = |some: bool| if some { 0.0 } else { 1.0 };
                return (
                    LightTerm::new(unoccluded, settled(real_some), settled(all_some)),
                    rays_cast,
                );
            }
            // Each ray weighs what its sample contributes at x.
            let (mut total, mut real, mut all) = (0.0, 0.0, 0.0);
            for k in 0..count {
                let w = crate::light::point_contribution(targets[k], x, n, |d| light.intensity(d))
                    .max_element();
                total += w;
                if !real_blocked[k] {
                    real += w;
                    if !virt_blocked[k] {
                        all += w;
                    }
                }
            }
            let frac = |v: f64| if total > 0.0 { v / total } else { 0.0 };
            return (LightTerm::new(unoccluded, frac(real), frac(all)), rays_cast);
        }
    };
    let blank = TraceRay::new(glam::Vec3::ZERO, glam::Vec3::Z);
    if most <= SMALL {
        run(
            &mut [DVec3::ZERO; SMALL],
            &mut [blank; SMALL],
            &mut [false; SMALL],
            &mut [false; SMALL],
        )
    } else {
        run(
            &mut vec![DVec3::ZERO; most],
            &mut vec![blank; most],
            &mut vec![false; most],
            &mut vec![false; most],
        )
    }
}
