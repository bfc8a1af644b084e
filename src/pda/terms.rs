//! One real or virtual point's light term for one light: the visibility
//! oracle's shadow rays through the room and the objects.

use super::*;

/// A light and what its terms are traced against.
#[derive(Clone, Copy)]
pub(super) struct LightQuery<'a> {
    pub(super) tracer: &'a Tracer,
    pub(super) light: &'a LightSource,
    pub(super) bounds: &'a VirtualBounds,
    pub(super) settings: PdaSettings,
}

/// The point a term is for: position, normal, the object whose solid the
/// point's face is clear of (if any), and the seed of its samples.
#[derive(Clone, Copy)]
pub(super) struct TermPoint {
    pub(super) x: DVec3,
    pub(super) n: DVec3,
    pub(super) own: Option<usize>,
    pub(super) seed: u64,
}

/// Visibility of one light from a point through the two worlds, by the
/// oracle. `before`: for a term computed before, its geometry factor (when
/// positive) and whether the objects may shadow x now (the pixel-block
/// traversal's answer; where it differs from [`VirtualBounds::may_shadow`],
/// one of the two excludes the objects and their rays meet nothing);
/// `real`: the real blockers already known for these samples, where rays
/// traced through the room are kept (a real point's; samples beyond
/// [`RealMask::MAX_SAMPLES`] are always traced).
pub(super) fn light_term(
    q: LightQuery,
    p: TermPoint,
    before: Option<(f32, bool)>,
    real: Option<&mut RealMask>,
) -> (LightTerm, u64) {
    let light = q.light;
    let unoccluded = match before {
        Some((u, _)) if u > 0.0 => u,
        _ => {
            let g = light.unoccluded_irradiance(p.x, p.n);
            let colour = light.colour().max_element();
            if g == DVec3::ZERO || colour <= 0.0 {
                return (LightTerm::default(), 0);
            }
            (g.max_element() / colour) as f32
        }
    };
    let t = Tracing {
        q,
        p,
        origin: offset_origin(p.x, p.n, light.position),
        unoccluded,
        check_virtual: before
            .map_or_else(|| q.bounds.may_shadow(p.x, light, p.own), |(_, may)| may),
    };
    let Some(grid) = &light.grid else {
        return t.point_light(real);
    };
    // Buffers for the most rays one call may cast: on the stack for the
    // usual budgets (filling 256 entries per pixel and light, whatever the
    // budget, cost more than the shading around it), on the heap beyond.
    let settings = q.settings;
    let most = 1usize
        << settings
            .min_level
            .max(settings.penumbra_level)
            .min(crate::light::MAX_GRID_LEVEL);
    const SMALL: usize = 16;
    let blank = TraceRay::new(glam::Vec3::ZERO, glam::Vec3::Z);
    if most <= SMALL {
        t.area_light(
            grid,
            real,
            Buffers {
                targets: &mut [DVec3::ZERO; SMALL],
                rays: &mut [blank; SMALL],
                real_blocked: &mut [false; SMALL],
                virt_blocked: &mut [false; SMALL],
            },
        )
    } else {
        t.area_light(
            grid,
            real,
            Buffers {
                targets: &mut vec![DVec3::ZERO; most],
                rays: &mut vec![blank; most],
                real_blocked: &mut vec![false; most],
                virt_blocked: &mut vec![false; most],
            },
        )
    }
}

/// One term being traced.
struct Tracing<'a> {
    q: LightQuery<'a>,
    p: TermPoint,
    /// The rays' origin, off the surface.
    origin: DVec3,
    unoccluded: f32,
    /// Whether rays go through the objects (else only the point's own
    /// solid, known without tracing, may block).
    check_virtual: bool,
}

/// Per-sample buffers of one term.
struct Buffers<'b> {
    targets: &'b mut [DVec3],
    rays: &'b mut [TraceRay],
    real_blocked: &'b mut [bool],
    virt_blocked: &'b mut [bool],
}

impl Tracing<'_> {
    /// On a face clear of its own solid (and no other object near), what
    /// the solid blocks is known without tracing: whatever lies behind the
    /// face, which a ray reaches only through the solid — and everything
    /// when the light's centre is behind it, as the rays then leave from
    /// the solid's side of the face ([`offset_origin`]).
    fn own_blocks(&self, y: DVec3) -> bool {
        self.p.own.is_some() && own_blocks(self.p.x, self.p.n, self.q.light.position, y)
    }

    /// A point light: one ray.
    fn point_light(&self, real: Option<&mut RealMask>) -> (LightTerm, u64) {
        let (tracer, position) = (self.q.tracer, self.q.light.position);
        let ray = segment(self.origin, position);
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
            && !if self.check_virtual {
                tracer.occluded(&ray, Layer::Virtual)
            } else {
                self.own_blocks(position)
            };
        rays_cast += (real_visible && self.check_virtual) as u64;
        let f = |b: bool| if b { 1.0 } else { 0.0 };
        (
            LightTerm::new(self.unoccluded, f(real_visible), f(all)),
            rays_cast,
        )
    }

    /// An area light: its samples at the base level, and at the penumbra
    /// level where they disagree.
    fn area_light(
        &self,
        grid: &crate::light::JitteredGrid,
        mut real: Option<&mut RealMask>,
        b: Buffers,
    ) -> (LightTerm, u64) {
        let (tracer, light, settings) = (self.q.tracer, self.q.light, self.q.settings);
        let mut level = settings.min_level;
        let mut rays_cast = 0u64;
        loop {
            let mut count = 0;
            for st in grid.samples(level, self.p.seed) {
                b.targets[count] = light.point_at(st);
                b.rays[count] = segment(self.origin, b.targets[count]);
                count += 1;
            }
            let penumbra = level != settings.min_level;
            let keep = real
                .as_deref_mut()
                .filter(|_| count <= RealMask::MAX_SAMPLES);
            let real_blocked = &mut b.real_blocked[..count];
            match keep.as_ref().and_then(|m| m.get(penumbra)) {
                Some(bits) => (0..count).for_each(|k| real_blocked[k] = bits >> k & 1 == 1),
                None => {
                    tracer.occluded_batch(&b.rays[..count], Layer::Real, real_blocked);
                    rays_cast += count as u64;
                    if let Some(m) = keep {
                        m.set(
                            penumbra,
                            (0..count).fold(0u16, |b, k| b | (real_blocked[k] as u16) << k),
                        );
                    }
                }
            }
            let virt_blocked = &mut b.virt_blocked[..count];
            if self.check_virtual {
                tracer.occluded_batch(&b.rays[..count], Layer::Virtual, virt_blocked);
                rays_cast += count as u64;
            } else {
                for (blocked, &target) in virt_blocked.iter_mut().zip(&b.targets[..count]) {
                    *blocked = self.own_blocks(target);
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
            let mut corner_shows = false;
            if level < settings.penumbra_level && !all_none && !real_mixed {
                let (shows, cast) = self.a_corner_shows();
                corner_shows = shows;
                rays_cast += cast;
            }
            if level < settings.penumbra_level && (real_mixed || all_mixed || corner_shows) {
                level = settings.penumbra_level;
                continue;
            }
            // Where no ray or every ray is blocked the fractions are 1 or 0
            // whatever the rays weigh: the weights (the light's intensity
            // towards x per sample) are needed only for the rest.
            if !real_mixed && !all_mixed {
                let settled = |some: bool| if some { 0.0 } else { 1.0 };
                return (
                    LightTerm::new(self.unoccluded, settled(real_some), settled(all_some)),
                    rays_cast,
                );
            }
            let (real, all) = self.weighted(&b.targets[..count], real_blocked, virt_blocked);
            return (LightTerm::new(self.unoccluded, real, all), rays_cast);
        }
    }

    /// Where every first ray was blocked: whether a corner of the light
    /// (2% inside it) shows. A shadow's edge crossing the light leaves a
    /// corner of it visible, and the few first rays may all miss the part
    /// that shows: the pixel would go dark among lit neighbours (grain in
    /// soft shadows). Four rays, and only in full shadow, where there were
    /// no more; the rays cast are returned with the answer.
    fn a_corner_shows(&self) -> (bool, u64) {
        const INSIDE: f64 = 0.02;
        let (tracer, light) = (self.q.tracer, self.q.light);
        let (a, b) = (INSIDE, 1.0 - INSIDE);
        let targets =
            [(a, a), (b, a), (a, b), (b, b)].map(|(s, t)| light.point_at(glam::DVec2::new(s, t)));
        let rays = targets.map(|y| segment(self.origin, y));
        let mut real_blocked = [false; 4];
        tracer.occluded_batch(&rays, Layer::Real, &mut real_blocked);
        let mut cast = 4u64;
        for k in (0..4).filter(|&k| !real_blocked[k]) {
            let virt = match self.check_virtual {
                true => {
                    cast += 1;
                    tracer.occluded(&rays[k], Layer::Virtual)
                }
                false => self.own_blocks(targets[k]),
            };
            if !virt {
                return (true, cast);
            }
        }
        (false, cast)
    }

    /// The fractions of the light through the room, and through the room
    /// and the objects, each ray weighing what its sample contributes at x.
    fn weighted(
        &self,
        targets: &[DVec3],
        real_blocked: &[bool],
        virt_blocked: &[bool],
    ) -> (f64, f64) {
        let (x, n, light) = (self.p.x, self.p.n, self.q.light);
        let (mut total, mut real, mut all) = (0.0, 0.0, 0.0);
        for k in 0..targets.len() {
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
        (frac(real), frac(all))
    }
}
