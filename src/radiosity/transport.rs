//! The room's transport: the full form-factor matrix or hierarchical
//! radiosity's links (Hanrahan et al. 1991), refined by an oracle on the
//! pair's unoccluded form factor and its visibility.

use glam::DVec3;
use rayon::prelude::*;

use crate::patches::{Element, Patches};
use crate::trace::{Layer, Tracer};

use super::GatherRows;
use super::form_factor::{
    PairShafts, coplanar, faces_away, may_be_occluded, may_be_occluded_using, occluders_between,
    occluders_between_using, point_factor, point_factors, straddles, unoccluded_form_factor,
    visibility,
};

/// Default refinement threshold of hierarchical radiosity: on the desk at
/// 0.5 m patches it keeps every patch within 0.4% of the full matrix with
/// 80% of its form factors (1.5% at 0.003, 0.3% at 0.001; see
/// tests/radiosity_desk.rs).
pub const DEFAULT_LINK_EPSILON: f64 = 0.002;

/// A partly hidden pair is refined while its unoccluded form factor exceeds
/// this fraction of ε; below it, rays at that level estimate visibility.
/// Measured on the desk (0.25 m): 1 (refine only above ε) keeps 287k links
/// but the hierarchical solution drifts 5% from the full matrix; 0.1 stays
/// within 1% with 359k links; refining every hidden pair to the leaves
/// needs 387k links and twice the time.
pub(crate) const VISIBILITY_REFINE_FRACTION: f64 = 0.1;

/// Below this many links a gather runs on one thread: waking the others
/// costs more than the few microseconds of work (a solve applies it
/// dozens of times).
pub(super) const SERIAL_GATHER_LINKS: usize = 1 << 16;

/// Receiver quadrature order of the unoccluded form factor. It is the same
/// for every pair, so that the factors out of one receiver sum to the exact
/// fraction of its hemisphere the sources cover (one in a closed room):
/// per-pair orders would each err a little and the errors add up, which a
/// reflectance of 0.99 amplifies a hundredfold.
pub(super) const FF_ORDER: usize = 3;

/// A hierarchical link: `receiver` gathers `form_factor × B(source)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    pub receiver: u32,
    pub source: u32,
    pub form_factor: f32,
}

/// A link as the transport holds it, its receiver given by the range it
/// lies in: 8 bytes, not 12. A gather streams every link (4.4 million on
/// `lounge`'s finer mesh, tens of gathers a solve), and the receiver read
/// with each was a third of the bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceLink {
    pub source: u32,
    pub form_factor: f32,
}

/// How light moves between patches.
#[derive(Debug, Clone, PartialEq)]
pub enum Transport {
    /// Row-major patch × patch form factors.
    Full { n: usize, form_factors: Vec<f32> },
    /// Links between elements of the hierarchy, sorted by receiver, and
    /// each receiver's range of them (receiver, start, end); and rows of
    /// weights gathered by rays (the texture path's objects, [`GatherRows`]).
    Hierarchical {
        links: Vec<SourceLink>,
        ranges: Vec<(u32, u32, u32)>,
        rows: Option<Box<GatherRows>>,
    },
}

impl Transport {
    /// Every patch against every other: N² form factors.
    pub fn full(patches: &Patches, tracer: &Tracer, layer: Layer) -> Transport {
        let n = patches.patch_count();
        // Possible occluders between each pair of roots, narrowed per patch pair.
        let roots = &patches.roots;
        let root_index: std::collections::HashMap<u32, usize> =
            roots.iter().enumerate().map(|(i, r)| (*r, i)).collect();
        let between: Vec<Vec<u32>> = (0..roots.len() * roots.len())
            .into_par_iter()
            .map(|k| {
                let (a, b) = (
                    &patches.elements[roots[k / roots.len()] as usize],
                    &patches.elements[roots[k % roots.len()] as usize],
                );
                occluders_between(patches, layer, a, b, roots)
            })
            .collect();
        let mut ff = vec![0f32; n * n];
        ff.par_chunks_mut(n.max(1))
            .enumerate()
            .for_each(|(i, row)| {
                let p = patches.patch(i);
                let ri = root_index[&p.root];
                for (j, f) in row.iter_mut().enumerate() {
                    if i != j {
                        let q = patches.patch(j);
                        let u = unoccluded_form_factor(p, q);
                        if u > 0.0 {
                            let candidates = &between[ri * roots.len() + root_index[&q.root]];
                            let occluded = may_be_occluded(patches, layer, p, q, candidates);
                            let v = if occluded {
                                visibility(p, q, tracer, layer)
                            } else {
                                1.0
                            };
                            *f = (u * v) as f32;
                        }
                    }
                }
            });
        Transport::Full {
            n,
            form_factors: ff,
        }
    }

    /// Hierarchical radiosity: starting from every pair of root elements,
    /// refined (see `refine`) until one form factor represents each
    /// exchange to within `epsilon`.
    pub fn hierarchical(
        patches: &Patches,
        tracer: &Tracer,
        layer: Layer,
        epsilon: f64,
    ) -> Transport {
        let with = Refiner {
            patches,
            tracer,
            layer,
            epsilon,
        };
        let roots = &patches.roots;
        // Pair by pair, not root by root: one root's row (a floor against
        // every wall) could take a third of the work, and the other core
        // idled while it ran (lounge's fine links: 16 s wall for 20 s of CPU,
        // against 10.5 s).
        let links: Vec<Link> = (0..roots.len() * roots.len())
            .into_par_iter()
            .filter(|&k| k / roots.len() != k % roots.len())
            .flat_map_iter(|k| {
                // Links refined ahead (a standby session) wait here while an edit is served.
                crate::util::pause::point();
                let mut out = Vec::new();
                refine(
                    &with,
                    roots[k / roots.len()],
                    roots[k % roots.len()],
                    roots,
                    &mut out,
                );
                out
            })
            .collect();
        Transport::hierarchical_from_links(links)
    }

    pub(crate) fn hierarchical_from_links(mut links: Vec<Link>) -> Transport {
        links.sort_by_key(|l| (l.receiver, l.source));
        let mut ranges: Vec<(u32, u32, u32)> = Vec::new();
        for (i, l) in links.iter().enumerate() {
            match ranges.last_mut() {
                Some(r) if r.0 == l.receiver => r.2 = i as u32 + 1,
                _ => ranges.push((l.receiver, i as u32, i as u32 + 1)),
            }
        }
        let links = (links.into_iter())
            .map(|l| SourceLink {
                source: l.source,
                form_factor: l.form_factor,
            })
            .collect();
        Transport::Hierarchical {
            links,
            ranges,
            rows: None,
        }
    }

    /// A hierarchical transport's links with their receivers, in its order
    /// (by receiver, then source); none for a full matrix.
    pub fn links(&self) -> impl ExactSizeIterator<Item = Link> + '_ {
        let (links, ranges): (&[SourceLink], &[(u32, u32, u32)]) = match self {
            Transport::Hierarchical { links, ranges, .. } => (links, ranges),
            Transport::Full { .. } => (&[], &[]),
        };
        let mut receiver_of = ranges.iter().flat_map(|&(r, a, b)| (a..b).map(move |_| r));
        (links.iter()).map(move |l| Link {
            receiver: receiver_of.next().unwrap_or(u32::MAX),
            source: l.source,
            form_factor: l.form_factor,
        })
    }

    /// This transport with `new`'s receivers also gathering through its
    /// rows (objects added to a room's links, [`GatherRows`]). A full
    /// matrix is returned as it is: it is made over every patch it gathers
    /// for, objects included, and holds their every pair already.
    pub fn with_gather_rows(mut self, new: GatherRows) -> Transport {
        if let Transport::Hierarchical { rows, .. } = &mut self {
            *rows = Some(Box::new(new));
        }
        self
    }

    /// Number of form factors stored (links, or the matrix's non-zeros).
    pub fn link_count(&self) -> usize {
        match self {
            Transport::Full { form_factors, .. } => {
                form_factors.iter().filter(|f| **f != 0.0).count()
            }
            Transport::Hierarchical { links, rows, .. } => {
                links.len() + rows.as_ref().map_or(0, |r| r.entry_count())
            }
        }
    }

    pub fn memory_bytes(&self) -> usize {
        match self {
            Transport::Full { form_factors, .. } => form_factors.len() * 4,
            Transport::Hierarchical {
                links,
                ranges,
                rows,
            } => {
                links.len() * std::mem::size_of::<SourceLink>()
                    + ranges.len() * std::mem::size_of::<(u32, u32, u32)>()
                    + rows.as_ref().map_or(0, |r| r.memory_bytes())
            }
        }
    }

    /// Irradiance each patch gathers from patch radiosities `b` (one channel).
    pub fn gather(&self, patches: &Patches, b: &[f64], out: &mut [f64]) {
        self.gather_channels(patches, b, out);
    }

    /// Irradiance per patch from RGB radiosities, the three channels in one
    /// pass over the links: each channel summed as [`Transport::gather`]
    /// sums it, so the result equals three single-channel gathers bit for
    /// bit, in about half their time (the links are read once, not thrice).
    pub fn gather_rgb(&self, patches: &Patches, b: &[DVec3]) -> Vec<DVec3> {
        let mut out = vec![DVec3::ZERO; b.len()];
        self.gather_channels(patches, b, &mut out);
        out
    }

    /// What each patch gathers from radiosities `b` into `out`: one
    /// channel or three ([`Channels`]), every channel the same way.
    pub(crate) fn gather_channels<T: Channels>(&self, patches: &Patches, b: &[T], out: &mut [T]) {
        match self {
            Transport::Full { n, form_factors } => {
                out.par_iter_mut().enumerate().for_each(|(i, o)| {
                    let row = &form_factors[i * n..(i + 1) * n];
                    *o = (row.iter().zip(b)).fold(T::default(), |s, (f, b)| s + *b * *f as f64);
                });
            }
            Transport::Hierarchical {
                links,
                ranges,
                rows,
            } => {
                let elements = &patches.elements;
                // Pull: an element's radiosity is the area-weighted mean of its
                // children's (children follow their parent in the arena).
                let mut node_b = vec![T::default(); elements.len()];
                for (k, &e) in patches.patches.iter().enumerate() {
                    node_b[e as usize] = b[k];
                }
                for e in (0..elements.len()).rev() {
                    if let Some([c0, c1]) = elements[e].children {
                        let (a0, a1) = (elements[c0 as usize].area, elements[c1 as usize].area);
                        node_b[e] =
                            (node_b[c0 as usize] * a0 + node_b[c1 as usize] * a1) / (a0 + a1);
                    }
                }
                let gather_range = |&(_, a, b): &(u32, u32, u32)| -> T {
                    (links[a as usize..b as usize].iter()).fold(T::default(), |s, l| {
                        s + node_b[l.source as usize] * l.form_factor as f64
                    })
                };
                let gathered: Vec<T> = if links.len() < SERIAL_GATHER_LINKS {
                    ranges.iter().map(gather_range).collect()
                } else {
                    ranges.par_iter().map(gather_range).collect()
                };
                let mut node_h = vec![T::default(); elements.len()];
                for (&(receiver, _, _), h) in ranges.iter().zip(gathered) {
                    node_h[receiver as usize] = h;
                }
                if let Some(r) = rows {
                    r.gather_into(&node_b, &mut node_h);
                }
                // Push: what an element gathers reaches every point of its children.
                for e in 0..elements.len() {
                    if let Some(parent) = elements[e].parent {
                        let from_parent = node_h[parent as usize];
                        node_h[e] += from_parent;
                    }
                }
                for (k, &e) in patches.patches.iter().enumerate() {
                    out[k] = node_h[e as usize];
                }
            }
        }
    }
}

/// What a gather sums: one channel (`f64`) or the three of RGB (`DVec3`),
/// each channel with the same operations in the same order, from +0 (so
/// that even a zero's sign is the same both ways).
pub(crate) trait Channels:
    Copy
    + Default
    + Send
    + Sync
    + std::ops::Add<Output = Self>
    + std::ops::AddAssign
    + std::ops::Mul<f64, Output = Self>
    + std::ops::Div<f64, Output = Self>
{
}

impl Channels for f64 {}
impl Channels for DVec3 {}

/// The exact unoccluded point-to-polygon factor towards `q` at the centre
/// and (slightly inset) corners of `p`: their spread bounds how much the
/// irradiance p gathers from q varies across p.
pub(super) fn factor_spread(p: &Element, q: &Element) -> (f64, f64) {
    let polygon = q.shape.corners();
    let mut lo = f64::INFINITY;
    let mut hi: f64 = 0.0;
    let mut mean = 0.0;
    let corners = p.shape.corners();
    // The inset corners and the centre, their factors taken at once.
    let mut xs = [p.centre; 5];
    for (x, c) in xs.iter_mut().zip(corners.iter()) {
        *x = p.centre + (*c - p.centre) * 0.9;
    }
    let xs = &xs[..corners.len() + 1];
    let mut factors = [0.0; 5];
    point_factors(xs, p, q, &polygon, &mut factors[..xs.len()]);
    for &f in &factors[..xs.len()] {
        lo = lo.min(f);
        hi = hi.max(f);
        mean += f;
    }
    (hi - lo, mean / (corners.len() + 1) as f64)
}

/// A bound on the point-to-polygon factor from any point of `p` to `q`:
/// the factor is at most q's solid angle over π, at most its area over π
/// times the nearest distance squared, and no point of p lies nearer to
/// one of q than their centres' distance less each one's farthest corner.
/// Infinite where the two may touch; 1e-6 above the bound, so that it
/// holds for the factors as rounded.
pub(super) fn factor_bound(p: &Element, q: &Element) -> f64 {
    let reach = |e: &Element| {
        (e.shape.corners().iter())
            .map(|c| (*c - e.centre).length())
            .fold(0.0, f64::max)
    };
    let gap = (q.centre - p.centre).length() - reach(p) - reach(q);
    if gap <= 0.0 {
        return f64::INFINITY;
    }
    q.area / (std::f64::consts::PI * gap * gap) * (1.0 + 1e-6)
}

/// How unevenly `p` sees the points of `q`: the relative spread of the
/// point-to-point kernel cosθ_p·cosθ_q/r² from p's centre over q's corners
/// and centre. Averaging q's radiosity over q errs by about F × this × the
/// relative variation of that radiosity.
pub(super) fn source_spread(p: &Element, q: &Element) -> f64 {
    let corners = q.shape.corners();
    let (mut lo, mut hi, mut sum) = (f64::INFINITY, 0.0f64, 0.0);
    for y in corners
        .iter()
        .map(|c| q.centre + (*c - q.centre) * 0.9)
        .chain(std::iter::once(q.centre))
    {
        let r = y - p.centre;
        let d2 = r.length_squared().max(1e-300);
        let k = (p.normal.dot(r) * q.normal.dot(r)).abs() / (d2 * d2);
        lo = lo.min(k);
        hi = hi.max(k);
        sum += k;
    }
    let mean = sum / (corners.len() + 1) as f64;
    if mean > 0.0 { (hi - lo) / mean } else { 0.0 }
}

/// Links receiver `p` to source `q` where one form factor represents the
/// exchange to within `epsilon`. The receiver is subdivided while the
/// factor varies across it by more than epsilon, or while it lies across
/// the plane of a one-sided source ([`straddles`]): its points would gather
/// different amounts. The source while F × its [`source_spread`] exceeds
/// epsilon (its radiosity would be averaged with the wrong weights); the
/// larger of the two while they are partly hidden from each other.
pub(super) fn refine(with: &Refiner, p: u32, q: u32, candidates: &[u32], out: &mut Vec<Link>) {
    let Refiner {
        patches,
        tracer,
        layer,
        epsilon,
    } = *with;
    let (ep, eq) = (&patches.elements[p as usize], &patches.elements[q as usize]);
    if coplanar(ep, eq) || faces_away(ep, eq) {
        return;
    }
    // The roots that may block the pair, listed only where children inherit
    // them (a split) or the rays ask whether an object is among them; a pair
    // linked whole (most: a leaf receiver takes one link from each piece of
    // every wall) asks whether there is any, which the first root that may
    // block answers, or asks nothing when the two do not see each other.
    let shafts = PairShafts::default();
    let listed = std::cell::OnceCell::new();
    let occluders = || {
        listed.get_or_init(|| occluders_between_using(patches, layer, ep, eq, candidates, &shafts))
    };
    let (p_leaf, q_leaf) = (ep.children.is_none(), eq.children.is_none());
    // Two leaves split neither way; a leaf receiver splits its source only
    // where the factor times the source's spread exceeds ε, which no factor
    // of a source that far can reach: neither needs the factor's points.
    let source = (!q_leaf).then(|| source_spread(ep, eq));
    let (spread, mean) = match (p_leaf, source) {
        (true, None) => (0.0, 0.0),
        (true, Some(s)) if factor_bound(ep, eq) * s <= epsilon => (0.0, 0.0),
        // A leaf receiver asks only whether to split the source, by the
        // factor at its centre: its corners' factors (four more exact
        // point factors) were a third of all the refinement computed
        // (lounge's finer mesh: links 11% faster, 0.1% fewer, skills the
        // same to 1e-5). Not across a one-sided source's plane, where the
        // centre may see nothing of what its front part sees.
        (true, Some(_)) if !straddles(ep, eq) => {
            (0.0, point_factor(ep.centre, ep, eq, &eq.shape.corners()))
        }
        _ => factor_spread(ep, eq),
    };
    let split_receiver = if !p_leaf && (spread > epsilon || straddles(ep, eq)) {
        Some(true)
    } else if source.is_some_and(|s| mean * s > epsilon) {
        Some(false)
    } else {
        let f = unoccluded_form_factor(ep, eq);
        if f <= 0.0 {
            return;
        }
        // Where the shaft between the two holds no possible occluder they
        // see each other whole. Otherwise rays estimate the visible part:
        // trusted where the exchange is small (its error is at most F), and
        // refined where it is not (Hanrahan's BFV refinement, exact shafts).
        // A pair between ε's fraction and ε is traced first and split only
        // where its rays disagree: a conservative shaft holds many roots
        // that block nothing. Above ε a pair is split at once, as its rays
        // could all pass by a small occluder that matters at that size.
        // Two leaves are traced wherever a root passes the box and planes:
        // their one to four rays cost less than the hull, built for 6
        // million pairs of lounge's finer mesh (links 3% faster; 34 of 4.4
        // million pairs the hull called clear were found blocked).
        let occluded = may_be_occluded_using(
            patches,
            layer,
            ep,
            eq,
            candidates,
            &shafts,
            !(p_leaf && q_leaf),
        );
        let splits = occluded && f > epsilon * VISIBILITY_REFINE_FRACTION && !(p_leaf && q_leaf);
        // Where no object may block, the rays skip the objects: one could
        // meet them only from the part of the receiver behind a one-sided
        // source's plane, light the form factor already leaves out (lost
        // twice, were it counted here).
        let traced = || match layer {
            Layer::All if !occluders().iter().any(|&r| patches.is_virtual_element(r)) => {
                visibility(ep, eq, tracer, Layer::Real)
            }
            _ => visibility(ep, eq, tracer, layer),
        };
        let visible = match (occluded, splits && f > epsilon) {
            (false, _) => Some(1.0),
            (true, true) => None,
            (true, false) => Some(traced()),
        };
        match visible {
            Some(v) if !(splits && v > 0.0 && v < 1.0) => {
                if v > 0.0 {
                    out.push(Link {
                        receiver: p,
                        source: q,
                        form_factor: (f * v) as f32,
                    });
                }
                None
            }
            _ => Some(!p_leaf && (q_leaf || ep.area >= eq.area)),
        }
    };
    match split_receiver {
        Some(true) => ep
            .children
            .unwrap()
            .iter()
            .for_each(|&c| refine(with, c, q, occluders(), out)),
        Some(false) => eq
            .children
            .unwrap()
            .iter()
            .for_each(|&c| refine(with, p, c, occluders(), out)),
        None => {}
    }
}

/// What [`refine`] works with: the elements, the geometry that may block
/// them (`layer`) and ε.
#[derive(Clone, Copy)]
pub(super) struct Refiner<'a> {
    pub(super) patches: &'a Patches,
    pub(super) tracer: &'a Tracer,
    pub(super) layer: Layer,
    pub(super) epsilon: f64,
}
