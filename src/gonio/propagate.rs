//! Reflectance propagation (Grosch §2.3): from the surfaces whose
//! reflectance is known, EQ1 fills the intensity table; the next surface is
//! the one whose EQ2 estimate, read through the table, risks least.

use super::*;

/// The intensity table where it is well known, and what EQ2's risk reads
/// from it.
struct KnownTable<'a> {
    grid: &'a Grid,
    values: Vec<DVec3>,
    known: Vec<bool>,
    /// Per node, the angle to the nearest known node, and that node.
    dist: Vec<f64>,
    from: Vec<usize>,
    slopes: Vec<f64>,
    /// The brightest known value.
    peak: f64,
    /// Half a node's diagonal, radians.
    half_node: f64,
}

impl<'a> KnownTable<'a> {
    fn new(grid: &'a Grid, fit: &Fit, known: Vec<bool>) -> Self {
        let values = fit.values();
        let (dist, from) = grid.distance_field(&known);
        let slopes = grid.slopes(&values, &known);
        let peak = (0..grid.len())
            .filter(|&k| known[k])
            .map(|k| values[k].element_sum() / 3.0)
            .fold(0.0, f64::max);
        let half_node = 0.5 * (grid.dv.powi(2) + grid.dh.powi(2)).sqrt().to_radians();
        KnownTable {
            grid,
            values,
            known,
            dist,
            from,
            slopes,
            peak,
            half_node,
        }
    }

    /// A sample's EQ2 estimate with the table's intensity: (risk, angle to
    /// the known directions, ρ); None where it receives no light.
    fn rank(&self, s: &Sample) -> Option<(f64, f64, DVec3)> {
        let grid = self.grid;
        let (intensity, angle) = if s.g > 0.0 {
            nearby_intensity(grid, s, &self.values, &self.known, &self.dist, &self.from)?
        } else {
            (DVec3::ZERO, 0.0)
        };
        let irradiance = intensity * s.g + s.e_known + s.h_ind;
        if irradiance.min_element() <= 0.0 {
            return None;
        }
        // The error EQ2 inherits from the assumed intensity: how fast the
        // table changes where it is taken from, over the angle to it (plus
        // half a node: the table is bilinear), as a share of the sample's
        // light. A sample the light does not reach carries none.
        let risk = if s.g > 0.0 {
            let src = self.from[grid.nearest(s.v, s.h)];
            let reach = angle + self.half_node;
            let slope = if src == usize::MAX {
                0.0
            } else {
                self.slopes[src]
            };
            // Beyond the known directions the light may be anything up to
            // the brightest seen: as much doubt per radian.
            let doubt = slope * reach + self.peak * angle;
            s.g * doubt / (irradiance.element_sum() / 3.0)
        } else {
            0.0
        };
        // Gathered indirect light is noisy per pixel: prefer direct.
        let indirect_share = s.h_ind.element_sum() / irradiance.element_sum();
        Some((
            risk + INDIRECT_DOUBT * indirect_share,
            angle,
            s.b / irradiance,
        ))
    }
}

/// One pass of Grosch's propagation over the samples, given their
/// indirect light. Returns the fitted RGB table and each surface's reflectance.
pub(super) fn propagate(
    grid: &Grid,
    samples: &[Sample],
    known_rho: &HashMap<u32, DVec3>,
    surfaces: &[u32],
) -> (Fit, HashMap<u32, (DVec3, ReflectanceSource)>) {
    let mut fit = Fit::new(grid.len());
    let mut rho: HashMap<u32, (DVec3, ReflectanceSource)> = HashMap::new();
    let mut by_surface: HashMap<u32, Vec<usize>> = HashMap::new();
    for (i, s) in samples.iter().enumerate() {
        by_surface.entry(s.surface).or_default().push(i);
    }
    let eq1 = |s: &Sample, r: DVec3| -> (DVec3, DVec3) {
        let safe = r.max(DVec3::splat(1e-6));
        (s.b / safe - s.e_known - s.h_ind, s.b / safe)
    };
    for (&surface, &r) in known_rho {
        rho.insert(surface, (r, ReflectanceSource::Known));
        for &i in by_surface.get(&surface).into_iter().flatten() {
            if samples[i].g > 0.0 {
                let (y, total) = eq1(&samples[i], r);
                fit.add(grid, &samples[i], y, total);
            }
        }
    }
    let mut step = 0;
    loop {
        // Propagate only from nodes many pixels agree on: a node touched by
        // a few samples at a surface's rim is where EQ1 is least reliable.
        let known = fit.well_known(WELL_KNOWN_SAMPLES);
        if !known.iter().any(|&k| k) {
            break;
        }
        let table = KnownTable::new(grid, &fit, known);
        // For each surface still unknown: its samples' (risk, ρ estimate).
        let mut best: Option<(f64, u32, DVec3, usize, f64)> = None;
        for &surface in surfaces {
            if rho.contains_key(&surface) {
                continue;
            }
            let Some(ids) = by_surface.get(&surface) else {
                continue;
            };
            let mut ranked: Vec<(f64, f64, DVec3)> = ids
                .iter()
                .filter_map(|&i| table.rank(&samples[i]))
                .collect();
            if ranked.is_empty() {
                continue;
            }
            ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
            // Every sample at most twice as doubtful as the EQ2_SAMPLES-th
            // (or as SAFE_RISK): many average out what is left of the texture.
            let risk = ranked[EQ2_SAMPLES.min(ranked.len()) - 1].0;
            let take = ranked
                .iter()
                .take_while(|x| x.0 <= SAFE_RISK.max(2.0 * risk))
                .count();
            if best.as_ref().is_none_or(|b| risk < b.0) {
                let r = median_rgb(&ranked[..take].iter().map(|x| x.2).collect::<Vec<_>>());
                let angle = ranked[..take].iter().map(|x| x.1).fold(0.0, f64::max);
                best = Some((risk, surface, r, take, angle));
            }
        }
        let Some((_, surface, r, take, angle)) = best else {
            break;
        };
        let r = r.clamp(DVec3::ZERO, DVec3::splat(crate::estimate::MAX_REFLECTANCE));
        step += 1;
        rho.insert(
            surface,
            (
                r,
                ReflectanceSource::Propagated {
                    step,
                    angle_deg: angle.to_degrees(),
                    samples: take,
                },
            ),
        );
        for &i in &by_surface[&surface] {
            if samples[i].g > 0.0 {
                let (y, total) = eq1(&samples[i], r);
                fit.add(grid, &samples[i], y, total);
            }
        }
    }
    (fit, rho)
}
