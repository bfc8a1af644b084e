use super::poisson::{JumpGraph, integrate_jumps};
use super::*;

/// Whether neighbouring pixels `p` and `q` see one plane of one surface
/// under the same lights (no light's visibility or direct light changes by
/// more than 10% between them): then only texture and smooth illumination
/// separate their values.
fn continuous(p: &Sample, q: &Sample) -> bool {
    let changes = |a: f64, b: f64| (a - b).abs() > 0.1 * a.max(b);
    same_plane(p, q)
        && !changes(p.g, q.g)
        && !changes(p.e_known.element_sum(), q.e_known.element_sum())
}

/// Whether neighbouring pixels `p` and `q` see one plane of one surface
/// under the same unknown light (its direct light changes by at most 10%):
/// across a change of the known lights alone, a model of their light can
/// tell a texture step from the light's (see [`PenumbraModel`]).
fn continuous_but_known(p: &Sample, q: &Sample) -> bool {
    same_plane(p, q) && (p.g - q.g).abs() <= 0.1 * p.g.max(q.g)
}

/// Whether neighbouring pixels `p` and `q` see one plane of one surface.
fn same_plane(p: &Sample, q: &Sample) -> bool {
    let depth = (p.x - q.x).length().max(1e-12);
    q.surface == p.surface && p.n.dot(q.n) > 0.9 && (q.x - p.x).dot(p.n).abs() < 0.05 * depth
}

/// The samples whose pixel mixes what it shows: a neighbour on another
/// surface or plane (a silhouette: the pixel's value blends both, its
/// sample point has one), or across a shadow edge (partly lit, its centre
/// fully). EQ1 and EQ2 leave them out.
pub(super) fn mixed_pixels(samples: &[Sample], width: u32, height: u32) -> Vec<bool> {
    pixels_with_a_neighbour(samples, width, height, |p, q| !continuous(p, q))
}

/// The samples with a neighbour on another plane or across the unknown
/// light's change: those the known lights' model cannot mend.
pub(super) fn sharp_pixels(samples: &[Sample], width: u32, height: u32) -> Vec<bool> {
    pixels_with_a_neighbour(samples, width, height, |p, q| !continuous_but_known(p, q))
}

/// The samples EQ1 cannot read even with a model of the known lights:
/// [`sharp_pixels`], and those beside a known light's step of over half
/// (a shadow edge the photo does not resolve: the pixel's value blends
/// light its centre does not get). The others, in a penumbra the photo
/// resolves, are read at their centre once the model takes their texture out.
pub(super) fn unreadable_pixels(samples: &[Sample], width: u32, height: u32) -> Vec<bool> {
    pixels_with_a_neighbour(samples, width, height, |p, q| {
        let (a, b) = (p.e_known.element_sum(), q.e_known.element_sum());
        !continuous_but_known(p, q) || (a - b).abs() > 0.5 * a.max(b)
    })
}

/// The samples with a 4-neighbour that is missing or for which `differs`.
fn pixels_with_a_neighbour(
    samples: &[Sample],
    width: u32,
    height: u32,
    differs: impl Fn(&Sample, &Sample) -> bool + Sync,
) -> Vec<bool> {
    let mut at = vec![u32::MAX; (width * height) as usize];
    for (i, s) in samples.iter().enumerate() {
        at[s.pixel as usize] = i as u32;
    }
    samples
        .iter()
        .map(|p| {
            let (col, row) = ((p.pixel % width) as i64, (p.pixel / width) as i64);
            [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)]
                .iter()
                .any(|(dc, dr)| {
                    let (c, r) = (col + dc, row + dr);
                    if c < 0 || r < 0 || c >= width as i64 || r >= height as i64 {
                        return false;
                    }
                    let j = at[(r as u32 * width + c as u32) as usize];
                    j == u32::MAX || differs(p, &samples[j as usize])
                })
        })
        .collect()
}

/// A model of every sample's light for [`remove_texture`] (from the
/// reconstruction so far): across a soft edge of a known light's shadow
/// (mixed pixels, but on one plane under the same unknown light) the step
/// of ln B less the model's step of ln E is texture. Without it such a
/// band only ties its sides by "no texture step", which a texture edge
/// crossing the band breaks (the floor under a table, in the panel's
/// shadow of the top, came out 10–30% off).
pub(super) struct PenumbraModel<'a> {
    /// The unknown light's direct irradiance (I·g) per sample.
    pub(super) unknown: &'a [DVec3],
    /// Pixels mixed for a reason the model cannot mend (a silhouette, the
    /// unknown light's own shadow edge).
    pub(super) sharp: &'a [bool],
    /// [`unreadable_pixels`]: the mixed pixels that stay out of EQ1.
    pub(super) unreadable: &'a [bool],
}

/// Pairs on either side whose steps give a step its surroundings in [`remove_texture`].
const EDGE_WALK: usize = 6;

/// Takes each surface's texture out of the samples' radiosity (Grosch
/// assumes one reflectance per polygon, which a textured floor breaks at
/// every pixel): ln ρ(x) = ln ρ̄ + u(x), where u changes only across
/// texture edges (a step of ln radiance between neighbouring clean pixels
/// of one plane that exceeds the steps around it by more than `edge`:
/// illumination varies smoothly there, a texture steps), found by a
/// least-squares integration of those jumps (Retinex); `mixed` pixels, and
/// a plane across what stands in front of it, are tied by weak links that
/// expect no step. Each surface's
/// texture exp(u) is scaled to area mean 1, so that ρ̄ keeps the meaning of
/// a [[reflectance]]: the surface's area-weighted mean. With a `model`,
/// mixed neighbours across a known light's soft shadow edge give texture
/// steps too ([`PenumbraModel`]), and so do clean pixels across a gap (a
/// thin occluder's shadow of the unknown light or the occluder itself cut
/// off a piece of a plane, which weak links tie only by "no step", wrong
/// where a texture edge runs under the gap); `start` is a texture found
/// before to integrate from (and, where the pairs are the same, to go on
/// reweighting from). Returns the number of texture edges and the texture found.
pub(super) fn remove_texture(
    samples: &mut [Sample],
    mixed: &[bool],
    model: Option<&PenumbraModel>,
    start: Option<&Texture>,
    width: u32,
    height: u32,
    edge: f64,
) -> (usize, Texture) {
    let grid = Grid::new(samples, width, height);
    let r = relations(&grid, mixed, model);
    // A step across a texture edge also holds the illumination's change
    // over one pixel, and illumination near a light or a corner changes by
    // several percent per pixel: a step is texture only by how much it
    // differs from the steps around it in the same direction (their median:
    // an edge's own two or three anti-aliased steps do not move it).
    let mut arriving = vec![[u32::MAX; 2]; samples.len()];
    for (k, &(_, j)) in r.pairs.iter().enumerate() {
        arriving[j as usize][r.directions[k]] = k as u32;
    }
    let excess = excess_steps(&r, &arriving);
    let is_edge = texture_edges(&r, &arriving, &excess, edge);
    let over = |steps: &[[f64; 3]]| -> Vec<bool> {
        steps
            .iter()
            .map(|x| x.iter().any(|x| x.abs() > edge))
            .collect()
    };
    let (soft_edge, measured_edge) = (over(&r.soft_steps), over(&r.measured_steps));
    let edges = is_edge
        .iter()
        .chain(&soft_edge)
        .chain(&measured_edge)
        .filter(|&&e| e)
        .count();
    let kept = |steps: &[[f64; 3]], is: &[bool], c: usize| -> Vec<f64> {
        steps
            .iter()
            .zip(is)
            .map(|(x, &e)| if e { x[c] } else { 0.0 })
            .collect()
    };
    let targets: [Vec<f64>; 3] = std::array::from_fn(|c| {
        let mut t = kept(&excess, &is_edge, c);
        t.extend(kept(&r.soft_steps, &soft_edge, c));
        t.extend(kept(&r.measured_steps, &measured_edge, c));
        t
    });
    // A measured step across n pixels weighs as n pairs in series would.
    let base: Vec<f64> = std::iter::repeat_n(1.0, r.pairs.len() + r.soft.len())
        .chain(r.measured.iter().map(|&(_, _, gap)| 1.0 / gap as f64))
        .collect();
    let mut pairs = r.pairs.clone();
    pairs.extend(&r.soft);
    pairs.extend(r.measured.iter().map(|&(i, k, _)| (i, k)));
    let noise = step_noise(&excess, &is_edge, edge);
    // A link across a gap stands for the links through the pixels it
    // spans, in series: it weighs as much as they would together (a
    // band of mixed pixels ties its sides by such a chain too). The
    // texture may step anywhere behind a table's leg; at full weight
    // these links bent the desk's floor under the table: 95th percentile
    // of the direction error 3.7% of the peak, 3.3% weighed in series.
    let links: Vec<(u32, u32, f64)> = r
        .links
        .iter()
        .map(|&(i, j)| (i, j, LINK_WEIGHT))
        .chain(
            r.gap_links
                .iter()
                .map(|&(i, j, gap)| (i, j, LINK_WEIGHT / gap as f64)),
        )
        .collect();
    // The robust weights found before, where the pairs are the same (a
    // later round with a model): the reweighting goes on from them.
    let same_pairs = start.filter(|t| {
        t.modelled == model.is_some() && t.weights.iter().all(|w| w.len() == pairs.len())
    });
    let solved: Vec<(Vec<f64>, Vec<f64>)> = (0..3)
        .into_par_iter()
        .map(|c| {
            let weights = same_pairs.map(|t| &t.weights[c][..]);
            let graph = JumpGraph {
                n: samples.len(),
                pairs: &pairs,
                base: &base,
                links: &links,
            };
            integrate_jumps(
                &graph,
                &targets[c],
                weights,
                start.map(|s| &s.ln[c][..]),
                noise[c],
            )
        })
        .collect();
    let (u, weights): (Vec<Vec<f64>>, Vec<Vec<f64>>) = solved.into_iter().unzip();
    divide_out(samples, &u);
    (
        edges,
        Texture {
            ln: u,
            weights,
            modelled: model.is_some(),
        },
    )
}

/// Samples by pixel, for walking the image.
struct Grid<'a> {
    samples: &'a [Sample],
    at: Vec<u32>,
    width: u32,
    height: u32,
}

impl<'a> Grid<'a> {
    fn new(samples: &'a [Sample], width: u32, height: u32) -> Self {
        let mut at = vec![u32::MAX; (width * height) as usize];
        for (i, s) in samples.iter().enumerate() {
            at[s.pixel as usize] = i as u32;
        }
        Grid {
            samples,
            at,
            width,
            height,
        }
    }

    /// The sample at (col, row), u32::MAX where none.
    fn sample(&self, col: u32, row: u32) -> u32 {
        self.at[(row * self.width + col) as usize]
    }

    /// From sample `i` in direction `(dc, dr)`: (gap, the sample there or
    /// u32::MAX) for gaps of 2 up to an eighth of the image, within it.
    fn beyond(&self, i: usize, (dc, dr): (u32, u32)) -> impl Iterator<Item = (u32, u32)> + '_ {
        let p = &self.samples[i];
        let (col, row) = (p.pixel % self.width, p.pixel / self.width);
        (2..=self.width.max(self.height) / 8)
            .map(move |gap| (gap, col + dc * gap, row + dr * gap))
            .take_while(|&(_, c, r)| c < self.width && r < self.height)
            .map(|(gap, c, r)| (gap, self.sample(c, r)))
    }
}

/// The neighbour relations [`remove_texture`] integrates.
#[derive(Default)]
struct Relations {
    /// Clean neighbours on one plane (i, j), their direction (0:
    /// rightwards, 1: downwards) and step of ln B per channel: a texture is
    /// coloured (a brown and cream checkerboard steps differently in each
    /// channel), so each channel is integrated on its own.
    pairs: Vec<(u32, u32)>,
    directions: Vec<usize>,
    jumps: Vec<[f64; 3]>,
    /// The pair leaving each pixel rightwards and downwards, if any.
    leaving: Vec<[u32; 2]>,
    /// Neighbours on one plane where either pixel is mixed (across a
    /// shadow's edge, or blending a silhouette in front): what steps there
    /// is light or another surface, so they say nothing of the texture but
    /// that it most likely does not step. Without them, a region that
    /// shadows cut off (the wall under a table) would be integrated on its
    /// own and its texture level, mean 0, would not match the rest of its
    /// surface's (where a poster moves the mean).
    links: Vec<(u32, u32)>,
    /// The same across something in front, with the gap in pixels.
    gap_links: Vec<(u32, u32, u32)>,
    /// Pairs across a known light's soft edge, with their modelled steps.
    soft: Vec<(u32, u32)>,
    soft_steps: Vec<[f64; 3]>,
    /// Clean pixels across a gap, with their steps less the model's.
    measured: Vec<(u32, u32, u32)>,
    measured_steps: Vec<[f64; 3]>,
}

fn log_b(s: &Sample) -> [f64; 3] {
    s.b.max(DVec3::splat(1e-30)).to_array().map(f64::ln)
}

/// The step of ln B from `p` to `q` less the modelled step of their light.
fn modelled_step(p: &Sample, q: &Sample, ep: DVec3, eq: DVec3) -> [f64; 3] {
    let (lp, lq) = (log_b(p), log_b(q));
    std::array::from_fn(|c| lq[c] - lp[c] - (eq[c].max(1e-30) / ep[c].max(1e-30)).ln())
}

/// Sample `i`'s pairs, links and modelled steps rightwards and downwards.
fn relations(grid: &Grid, mixed: &[bool], model: Option<&PenumbraModel>) -> Relations {
    let (samples, width, height) = (grid.samples, grid.width, grid.height);
    let mut r = Relations {
        leaving: vec![[u32::MAX; 2]; samples.len()],
        ..Default::default()
    };
    for (i, p) in samples.iter().enumerate() {
        let (col, row) = (p.pixel % width, p.pixel / width);
        for (dir, (dc, dr)) in [(1u32, 0u32), (0, 1)].into_iter().enumerate() {
            if col + dc >= width || row + dr >= height {
                continue;
            }
            let j = grid.sample(col + dc, row + dr);
            let clean_neighbour =
                j != u32::MAX && samples[j as usize].surface == p.surface && !mixed[j as usize];
            if let Some(m) = model.filter(|_| !mixed[i] && !clean_neighbour && p.g > 0.0)
                && let Some((k, gap, step)) = measured_across(grid, mixed, m, i, (dc, dr))
            {
                r.measured.push((i as u32, k, gap));
                r.measured_steps.push(step);
            }
            if j == u32::MAX || samples[j as usize].surface != p.surface {
                r.gap_links.extend(gap_link(grid, i, (dc, dr)));
                continue;
            }
            let q = &samples[j as usize];
            if mixed[i] || mixed[j as usize] {
                match model {
                    Some(m)
                        if !m.sharp[i] && !m.sharp[j as usize] && continuous_but_known(p, q) =>
                    {
                        // The indirect light is one for both (per pixel it is
                        // gathered with noise larger than its change here).
                        let h = 0.5 * (p.h_ind + q.h_ind);
                        let (ep, eq) = (
                            m.unknown[i] + p.e_known + h,
                            m.unknown[j as usize] + q.e_known + h,
                        );
                        r.soft.push((i as u32, j));
                        r.soft_steps.push(modelled_step(p, q, ep, eq));
                    }
                    _ => {
                        if same_plane(p, q) {
                            r.links.push((i as u32, j));
                        }
                    }
                }
                continue;
            }
            let (lp, lq) = (log_b(p), log_b(q));
            r.leaving[i][dir] = r.pairs.len() as u32;
            r.pairs.push((i as u32, j));
            r.directions.push(dir);
            r.jumps.push([lq[0] - lp[0], lq[1] - lp[1], lq[2] - lp[2]]);
        }
    }
    r
}

/// Across what the light model reads on both sides: the first clean pixel
/// of sample `i`'s plane the unknown light reaches beyond, in direction
/// `(dc, dr)` (past a thin occluder's shadow of that light, or the
/// occluder itself), with the gap and the step less the model's.
fn measured_across(
    grid: &Grid,
    mixed: &[bool],
    m: &PenumbraModel,
    i: usize,
    direction: (u32, u32),
) -> Option<(u32, u32, [f64; 3])> {
    let samples = grid.samples;
    let p = &samples[i];
    for (gap, k) in grid.beyond(i, direction) {
        if k == u32::MAX
            || mixed[k as usize]
            || samples[k as usize].surface != p.surface
            || samples[k as usize].g <= 0.0
        {
            continue;
        }
        let q = &samples[k as usize];
        if !same_plane(p, q) {
            return None;
        }
        let ep = m.unknown[i] + p.e_known + p.h_ind;
        let eq = m.unknown[k as usize] + q.e_known + q.h_ind;
        return Some((k, gap, modelled_step(p, q, ep, eq)));
    }
    None
}

/// Something in front of sample `i` (a table's leg) or nothing at all, in
/// direction `(dc, dr)`: a link to the surface where it shows again, if on
/// the same plane within a gap, so that the region the occluder encloses
/// (the wall between the legs) is not left on its own.
fn gap_link(grid: &Grid, i: usize, direction: (u32, u32)) -> Option<(u32, u32, u32)> {
    let samples = grid.samples;
    let p = &samples[i];
    for (gap, k) in grid.beyond(i, direction) {
        if k != u32::MAX && samples[k as usize].surface == p.surface {
            return same_plane(p, &samples[k as usize]).then_some((i as u32, k, gap));
        }
    }
    None
}

/// Each pair's step less the median of the steps around it in its direction.
fn excess_steps(r: &Relations, arriving: &[[u32; 2]]) -> Vec<[f64; 3]> {
    let (pairs, jumps) = (&r.pairs, &r.jumps);
    (0..pairs.len())
        .into_par_iter()
        .map(|k| {
            let ((i, j), dir) = (pairs[k], r.directions[k]);
            let mut around = [0usize; 2 * EDGE_WALK];
            let mut m = 0;
            let mut back = arriving[i as usize][dir];
            let mut ahead = r.leaving[j as usize][dir];
            for _ in 0..EDGE_WALK {
                if back != u32::MAX {
                    around[m] = back as usize;
                    m += 1;
                    back = arriving[pairs[back as usize].0 as usize][dir];
                }
                if ahead != u32::MAX {
                    around[m] = ahead as usize;
                    m += 1;
                    ahead = r.leaving[pairs[ahead as usize].1 as usize][dir];
                }
            }
            std::array::from_fn(|c| {
                if m == 0 {
                    return jumps[k][c];
                }
                let mut steps = [0.0f64; 2 * EDGE_WALK];
                for (s, &n) in steps.iter_mut().zip(&around[..m]) {
                    *s = jumps[n][c];
                }
                let steps = &mut steps[..m];
                steps.sort_by(f64::total_cmp);
                let slope = if m % 2 == 1 {
                    steps[m / 2]
                } else {
                    0.5 * (steps[m / 2 - 1] + steps[m / 2])
                };
                jumps[k][c] - slope
            })
        })
        .collect()
}

/// The pairs across a texture edge: any channel's excess over `edge` (there
/// every channel keeps its own step), or a ramp. A texture edge the
/// camera's filter (or the texture's own) spreads over a few pixels steps
/// less than `edge` per pixel: a pair is also an edge when the three steps
/// around it, in the same direction, add up to more than `edge` and its own
/// step is a real part of that (a third).
fn texture_edges(
    r: &Relations,
    arriving: &[[u32; 2]],
    excess: &[[f64; 3]],
    edge: f64,
) -> Vec<bool> {
    let mut is_edge: Vec<bool> = excess
        .iter()
        .map(|x| x.iter().any(|x| x.abs() > edge))
        .collect();
    let ramp: Vec<bool> = (0..r.pairs.len())
        .map(|k| {
            if is_edge[k] {
                return false;
            }
            let ((i, j), dir) = (r.pairs[k], r.directions[k]);
            let (before, after) = (arriving[i as usize][dir], r.leaving[j as usize][dir]);
            if before == u32::MAX || after == u32::MAX {
                return false;
            }
            (0..3).any(|c| {
                let span = excess[before as usize][c] + excess[k][c] + excess[after as usize][c];
                span.abs() > edge
                    && excess[k][c].abs() > edge / 3.0
                    && excess[k][c].signum() == span.signum()
            })
        })
        .collect();
    for (k, r) in ramp.into_iter().enumerate() {
        is_edge[k] |= r;
    }
    is_edge
}

/// The photo's noise in a step: the spread of the steps that are neither
/// texture edges nor illumination (their excess over the steps around
/// them), as a robust standard deviation.
fn step_noise(excess: &[[f64; 3]], is_edge: &[bool], edge: f64) -> [f64; 3] {
    std::array::from_fn(|c| {
        let mut plain: Vec<f64> = (0..is_edge.len())
            .filter(|&k| !is_edge[k])
            .map(|k| excess[k][c].abs())
            .collect();
        if plain.is_empty() {
            return edge;
        }
        let m = plain.len() / 2;
        (1.4826 * *plain.select_nth_unstable_by(m, f64::total_cmp).1).clamp(1e-4, edge)
    })
}

/// Divides each sample's radiosity by its texture exp(u), scaled to area
/// mean 1 per surface.
fn divide_out(samples: &mut [Sample], u: &[Vec<f64>]) {
    let mut mean: HashMap<u32, (DVec3, f64)> = HashMap::new();
    let texture_at = |k: usize| DVec3::new(u[0][k].exp(), u[1][k].exp(), u[2][k].exp());
    for (k, s) in samples.iter().enumerate() {
        let m = mean.entry(s.surface).or_insert((DVec3::ZERO, 0.0));
        m.0 += texture_at(k) * s.area;
        m.1 += s.area;
    }
    for k in 0..samples.len() {
        let (sum, area) = mean[&samples[k].surface];
        let texture = texture_at(k) * area / sum.max(DVec3::splat(1e-300));
        // A pathological chain of jumps (black pixels beside bright ones)
        // could overflow: such a pixel keeps its value rather than lose it.
        if texture.is_finite() && texture.min_element() > 0.0 {
            samples[k].b /= texture;
        }
    }
}

/// A texture [`remove_texture`] found: ln per channel and sample, and the
/// robust weights of its pairs for a later call to go on from.
#[derive(Clone, Default)]
pub(super) struct Texture {
    pub(super) ln: Vec<Vec<f64>>,
    pub(super) weights: Vec<Vec<f64>>,
    pub(super) modelled: bool,
}

/// `all` with textures removed and the mixed samples left out (with a
/// `model`, only its unreadable ones); the number of texture edges and the
/// texture, which a later call may `start` from.
pub(super) fn textured(
    all: &[Sample],
    mixed: &[bool],
    model: Option<&PenumbraModel>,
    start: Option<&Texture>,
    width: u32,
    height: u32,
    edge: f64,
) -> (Vec<Sample>, usize, Texture) {
    let mut samples = all.to_vec();
    let (edges, u) = remove_texture(&mut samples, mixed, model, start, width, height, edge);
    let mut keep = mixed
        .iter()
        .enumerate()
        .map(|(i, &m)| !m || model.is_some_and(|model| !model.unreadable[i]));
    samples.retain(|_| keep.next().unwrap_or(false));
    (samples, edges, u)
}

/// Weight of a [`remove_texture`] link between neighbours across a change
/// of light, next to 1 for a pair: enough to tie pieces together, too
/// little to pull a texture edge that happens to lie on a shadow's edge.
/// A link across a gap of n pixels weighs a n-th of it.
const LINK_WEIGHT: f64 = 0.01;
