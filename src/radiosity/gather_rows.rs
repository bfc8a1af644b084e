//! The virtual objects in a transport as rows of weights gathered by rays,
//! linear in the radiosity they read as links are, so a light's change on
//! the texture path still costs one radiosity step (Loscos's relighting):
//! - the objects' leaves, grouped where they lie close and face alike,
//!   each group tracing one set of cosine-distributed rays whose first
//!   hits make its row ([`GatherRows::trace`]; the pixel path's final
//!   gathering shares vertices' gathers the same way);
//! - the room's leaves that see the objects, each ray towards them reading
//!   an object's radiosity less the room's behind it
//!   ([`GatherRows::of_view`]), the room's own links kept.
//!
//! What they cost follows the objects' area and the room's leaves near
//! them, not the objects' triangles: linking every object triangle with
//! the room's elements (hierarchical refinement, 4.8 M links for a
//! 30,000-triangle prop) took 9.6 s of a 12 s render.

use glam::DVec3;
use rayon::prelude::*;

use super::change::{ObjectView, cosine_direction};
use crate::patches::{Patches, Shape};
use crate::trace::{Layer, TraceRay, Tracer};

/// The largest angle between the normals of two leaves that share a
/// group (as [`crate::render`]'s vertices that share a gather).
const SHARE_ANGLE_DEG: f64 = 5.0;

/// What the texture path's transport with the objects would hold, measured
/// on a sample of the work before it is done.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ObjectLinkEstimate {
    /// The objects' roots (their triangles, or parts of them).
    pub roots: usize,
    /// The groups of the objects' leaves that gather by rays, and how many
    /// of them gathered to measure.
    pub groups: usize,
    pub sampled: usize,
    /// Links and rows' weights expected, the room's own included.
    pub links: f64,
    /// Seconds expected, at this machine's thread count.
    pub seconds: f64,
}

/// Rows of weights, each shared by a group of leaves.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GatherRows {
    /// Per group: its members' range in `members`, its row's in `entries`.
    groups: Vec<[u32; 4]>,
    /// Receiving elements (leaves), group by group.
    members: Vec<u32>,
    /// (source element, weight): the fraction of the group's rays that
    /// met that element first.
    entries: Vec<(u32, f32)>,
    /// Rays traced.
    pub rays: u64,
}

/// How the objects' leaves gather: `rays` per group, leaves within
/// `within` metres (and 5°) of a group's first sharing it
/// ([`GatherRows::groups_of`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatherRowsSettings {
    pub rays: u32,
    pub within: f64,
}

impl GatherRows {
    /// The groups of the virtual leaves of `patches` (elements, each
    /// group's first its seed; no rays traced), made once for
    /// [`GatherRows::trace`], [`GatherRows::estimate`] and
    /// [`GatherRows::representatives`].
    pub fn groups_of(patches: &Patches, within: f64) -> Vec<Vec<u32>> {
        let cos_max = SHARE_ANGLE_DEG.to_radians().cos();
        let cell = |p: DVec3| (p / within.max(1e-9)).floor().as_i64vec3().to_array();
        let mut near: crate::util::FastMap<[i64; 3], Vec<u32>> = crate::util::fast_map();
        let mut groups: Vec<Vec<u32>> = Vec::new();
        // Serial and in patch order: each choice reads the groups before, and
        // is the same whatever the thread count.
        for &e in &patches.patches {
            if !patches.is_virtual_element(e) {
                continue;
            }
            let el = &patches.elements[e as usize];
            let [cx, cy, cz] = cell(el.centre);
            let joined = (near.get(&[cx, cy, cz]).into_iter().flatten()).find(|&&g| {
                let seed = &patches.elements[groups[g as usize][0] as usize];
                seed.surface == el.surface
                    && (seed.centre - el.centre).length() <= within
                    && seed.normal.dot(el.normal) >= cos_max
            });
            if let Some(&g) = joined {
                groups[g as usize].push(e);
                continue;
            }
            let g = groups.len() as u32;
            groups.push(vec![e]);
            for x in -1..=1 {
                for y in -1..=1 {
                    for z in -1..=1 {
                        near.entry([cx + x, cy + y, cz + z]).or_default().push(g);
                    }
                }
            }
        }
        groups
    }

    /// Per patch of `patches`, the patch whose direct light it may take:
    /// for a leaf of a surface `shared` names, its group's (of `groups`)
    /// leaf nearest the group's area-weighted centre; itself for every
    /// other patch. Leaves that close and facing alike see the lights
    /// alike (the pixel path's face clusters, Willmott, Heckbert & Garland
    /// 1999).
    pub fn representatives(
        patches: &Patches,
        groups: &[Vec<u32>],
        shared: impl Fn(u32) -> bool,
    ) -> Vec<u32> {
        let mut out: Vec<u32> = (0..patches.patch_count() as u32).collect();
        let elements = &patches.elements;
        for members in groups
            .iter()
            .filter(|m| shared(elements[m[0] as usize].surface))
        {
            let area: f64 = members.iter().map(|&e| elements[e as usize].area).sum();
            let centre = (members.iter())
                .map(|&e| elements[e as usize].centre * elements[e as usize].area)
                .sum::<DVec3>()
                / area.max(1e-300);
            let nearest = (members.iter())
                .min_by(|&&a, &&b| {
                    let d = |e: u32| (elements[e as usize].centre - centre).length_squared();
                    d(a).total_cmp(&d(b))
                })
                .and_then(|&e| elements[e as usize].patch);
            if let Some(r) = nearest {
                for &e in members {
                    if let Some(k) = elements[e as usize].patch {
                        out[k as usize] = r;
                    }
                }
            }
        }
        out
    }

    /// Each group's row (of `groups`), from `rays` rays leaving its leaves
    /// (a point by area, a cosine-distributed direction about the leaf's
    /// normal, one Owen-scrambled Sobol point per ray).
    pub fn trace(patches: &Patches, tracer: &Tracer, groups: &[Vec<u32>], rays: u32) -> GatherRows {
        let rows: Vec<Vec<(u32, f32)>> = groups
            .par_iter()
            .map(|members| row(patches, tracer, members, rays))
            .collect();
        let mut out = GatherRows {
            rays: groups.len() as u64 * u64::from(rays),
            ..GatherRows::default()
        };
        for (members, row) in groups.iter().zip(rows) {
            let (m, e) = (out.members.len() as u32, out.entries.len() as u32);
            out.members.extend(members);
            out.entries.extend(row);
            out.groups
                .push([m, out.members.len() as u32, e, out.entries.len() as u32]);
        }
        out
    }

    /// Rows for the room's leaves from what they see of the objects
    /// ([`ObjectView`], traced from them): each ray that meets
    /// an object reads its radiosity, less that of the room element it
    /// hides, so the room's own links carry on unchanged (George, Sillion
    /// & Greenberg 1990, as the pixel path's change does).
    pub fn of_view(patches: &Patches, view: &ObjectView) -> GatherRows {
        let mut out = GatherRows {
            rays: view.rays,
            ..GatherRows::default()
        };
        let element = |k: u32| patches.patches.get(k as usize).copied();
        for (k, seen) in view.receivers() {
            let Some(receiver) = element(k) else {
                continue;
            };
            let mut row: Vec<(u32, f64)> = Vec::with_capacity(2 * seen.len());
            for s in seen {
                let w = f64::from(s.weight) / std::f64::consts::PI;
                row.extend(element(s.object).map(|e| (e, w)));
                row.extend(element(s.behind).map(|e| (e, -w)));
            }
            row.sort_unstable_by_key(|r| r.0);
            let (m, e) = (out.members.len() as u32, out.entries.len() as u32);
            out.members.push(receiver);
            for chunk in row.chunk_by(|a, b| a.0 == b.0) {
                let w: f64 = chunk.iter().map(|r| r.1).sum();
                out.entries.push((chunk[0].0, w as f32));
            }
            out.groups.push([m, m + 1, e, out.entries.len() as u32]);
        }
        out
    }

    /// These rows followed by `other`'s.
    pub fn append(&mut self, other: GatherRows) {
        let (m, e) = (self.members.len() as u32, self.entries.len() as u32);
        self.groups
            .extend((other.groups.iter()).map(|&[a, b, c, d]| [a + m, b + m, c + e, d + e]));
        self.members.extend(other.members);
        self.entries.extend(other.entries);
        self.rays += other.rays;
    }

    /// What [`GatherRows::trace`] of `groups` would hold and take,
    /// measured on `sample` of them, evenly spread: (weights, seconds).
    pub fn estimate(
        patches: &Patches,
        tracer: &Tracer,
        (groups, rays): (&[Vec<u32>], u32),
        sample: usize,
    ) -> (f64, f64) {
        if groups.is_empty() {
            return (0.0, 0.0);
        }
        let step = groups.len().div_ceil(sample.clamp(1, groups.len()));
        let picked: Vec<&Vec<u32>> = groups.iter().step_by(step).collect();
        let started = std::time::Instant::now();
        let entries: usize = (picked.par_iter())
            .map(|members| row(patches, tracer, members, rays).len())
            .sum();
        let scale = groups.len() as f64 / picked.len() as f64;
        (
            entries as f64 * scale,
            started.elapsed().as_secs_f64() * scale,
        )
    }

    /// Adds to each member's irradiance its group's row applied to the
    /// elements' radiosities `node_b` (one channel or three).
    pub(crate) fn gather_into<T: super::transport::Channels>(
        &self,
        node_b: &[T],
        node_h: &mut [T],
    ) {
        let h: Vec<T> = (self.groups.par_iter())
            .with_min_len(64)
            .map(|&[_, _, a, b]| {
                (self.entries[a as usize..b as usize].iter()).fold(T::default(), |h, &(s, w)| {
                    h + node_b[s as usize] * f64::from(w)
                })
            })
            .collect();
        for (&[a, b, ..], h) in self.groups.iter().zip(h) {
            for &m in &self.members[a as usize..b as usize] {
                node_h[m as usize] += h;
            }
        }
    }

    /// Weights held (a link's worth each).
    pub fn entry_count(&self) -> usize {
        self.entries.len()
    }

    pub fn group_count(&self) -> usize {
        self.groups.len()
    }

    pub fn memory_bytes(&self) -> usize {
        self.groups.len() * 16 + self.members.len() * 4 + self.entries.len() * 8
    }
}

/// The row of one group: the elements its rays meet first, each with the
/// fraction of the rays that met it.
fn row(patches: &Patches, tracer: &Tracer, members: &[u32], rays: u32) -> Vec<(u32, f32)> {
    let elements = &patches.elements;
    let mut cumulative = Vec::with_capacity(members.len());
    let mut total = 0.0;
    for &m in members {
        total += elements[m as usize].area;
        cumulative.push(total);
    }
    let seed = crate::util::rng::hash2(u64::from(members[0]), 0x6A7) as u32;
    let starts: Vec<(DVec3, DVec3)> = (0..rays)
        .map(|r| {
            let [u0, u1, u2, u3] = sobol_burley::sample_4d(r, 0, seed).map(f64::from);
            let u4 = f64::from(sobol_burley::sample_4d(r, 1, seed)[0]);
            let k = cumulative
                .partition_point(|&c| c < u0 * total)
                .min(members.len() - 1);
            let el = &elements[members[k] as usize];
            // A coarse leaf's rays leave from its surface's own triangle.
            let shape = el
                .patch
                .map_or(&el.shape, |p| patches.sample_shape(p as usize));
            let x = point_on(shape, u1, u2);
            let d = cosine_direction(el.normal, u3, u4);
            (crate::light::offset_origin(x, el.normal, x + el.normal), d)
        })
        .collect();
    let traced: Vec<TraceRay> = (starts.iter())
        .map(|(o, d)| TraceRay::new(o.as_vec3(), d.as_vec3()))
        .collect();
    let mut hits = vec![None; traced.len()];
    tracer.intersect_batch(&traced, Layer::All, &mut hits);
    let weight = 1.0 / rays.max(1) as f64;
    let mut met: Vec<u32> = (starts.iter().zip(&hits))
        .filter_map(|((o, d), hit)| {
            let hit = hit.as_ref()?;
            let y = *o + *d * hit.t as f64;
            let at = patches.locate(hit.surface, hit.triangle, y)?;
            patches.patches.get(at.patch as usize).copied()
        })
        .collect();
    met.sort_unstable();
    let mut out: Vec<(u32, f32)> = Vec::new();
    for chunk in met.chunk_by(|a, b| a == b) {
        out.push((chunk[0], (chunk.len() as f64 * weight) as f32));
    }
    out
}

/// The point of `shape` at (`u`, `v`) in \[0, 1)², uniform by area.
fn point_on(shape: &Shape, u: f64, v: f64) -> DVec3 {
    match *shape {
        Shape::Quad { origin, u: a, v: b } => origin + a * u + b * v,
        Shape::Tri([a, b, c]) => {
            let r = u.sqrt();
            a * (1.0 - r) + b * (r * (1.0 - v)) + c * (r * v)
        }
    }
}
