//! Virtual objects added to a room's transport: the room's links they may
//! shadow refined again, and the objects linked (element by element, or
//! through their clusters).

use super::clusters::refine_cluster;
use super::form_factor::ShaftTest;
use super::transport::*;
use super::*;
use crate::patches::Patches;
use crate::shaft::Shaft;
use crate::trace::{Layer, Tracer};
use rayon::prelude::*;

impl Transport {
    /// This transport (of a room's patches) with virtual objects added:
    /// `patches` holds the room's elements first, unchanged, then the
    /// objects'. Hierarchical links whose shaft cannot meet an object are
    /// kept; the others are refined again with the objects as occluders;
    /// the objects' elements are linked with everything. A full matrix is
    /// rebuilt.
    ///
    /// With `objects_receive` false the objects get no links of their own to
    /// gather through (the caller supplies their light, e.g. by final
    /// gathering from the photo); they still shadow the room and send it
    /// light, through [`ClusterLinks`] where their clusters are far enough.
    pub fn with_objects(
        &self,
        patches: &Patches,
        tracer: &Tracer,
        epsilon: f64,
        objects_receive: bool,
    ) -> Transport {
        self.with_objects_using(patches, tracer, epsilon, objects_receive, None)
    }

    /// [`Transport::with_objects`], keeping in `facts` (made for this
    /// transport by [`RoomLinkFacts::new`]) what it learns about the room's
    /// links for the next placement of the objects: the same links result.
    pub fn with_objects_using(
        &self,
        patches: &Patches,
        tracer: &Tracer,
        epsilon: f64,
        objects_receive: bool,
        facts: Option<&RoomLinkFacts>,
    ) -> Transport {
        let Transport::Hierarchical {
            links: room_links, ..
        } = self
        else {
            return Transport::full(patches, tracer, Layer::All);
        };
        let is_virtual = |r: &u32| patches.is_virtual_element(*r);
        let object_roots: Vec<u32> = patches.roots.iter().copied().filter(is_virtual).collect();
        let all_roots = &patches.roots;
        let clusters = RootClusters::build(patches, &object_roots);
        let near = near_objects(patches, room_links, &clusters, facts);
        let mut links: Vec<Link> = room_links
            .iter()
            .zip(&near)
            .filter(|(_, n)| !**n)
            .map(|(l, _)| *l)
            .collect();
        let room_roots: Vec<u32> = all_roots
            .iter()
            .copied()
            .filter(|r| !is_virtual(r))
            .collect();
        // One task per room link the objects may shadow and per object
        // root (with every other root), so that both cores share the few
        // large ones. Not per (object root, root) pair: a task and its
        // result per pair held a 4,000-triangle object's 16 M pairs at 1.1 GB
        // for 22 MB of links. Objects that gather from the room are linked
        // with it element by element and with each other through their
        // clusters; the objects reach each room root through their clusters.
        enum Task {
            Room(usize),
            Object(u32),
            Cluster(u32),
        }
        let mut object_tasks: Vec<Task> = if objects_receive {
            object_roots.iter().map(|&v| Task::Object(v)).collect()
        } else {
            Vec::new()
        };
        if !clusters.nodes.is_empty() {
            object_tasks.extend(room_roots.iter().map(|&r| Task::Cluster(r)));
        }
        let tasks: Vec<Task> = (0..room_links.len())
            .filter(|&i| near[i])
            .map(Task::Room)
            .chain(object_tasks)
            .collect();
        let with = object_refiner(patches, tracer, epsilon, &clusters);
        let made: Vec<(Vec<Link>, Vec<ClusterLink>)> = tasks
            .par_iter()
            .with_max_len(4)
            .map(|task| {
                let mut out = Vec::new();
                let mut to_clusters = Vec::new();
                match *task {
                    Task::Room(i) => {
                        relink_room_link(&with, room_links, i, facts, &room_roots, &mut out)
                    }
                    Task::Object(v) => (out, to_clusters) = link_object_root(&with, v, &room_roots),
                    Task::Cluster(r) => {
                        refine_cluster(&with, r, 0, &room_roots, &mut out, &mut to_clusters)
                    }
                }
                (out, to_clusters)
            })
            .collect();
        let mut cluster_links = Vec::new();
        for (new, to_clusters) in made {
            links.extend(new);
            cluster_links.extend(to_clusters);
        }
        let mut transport = Transport::hierarchical_from_links(links);
        if let Transport::Hierarchical { clusters: c, .. } = &mut transport
            && !cluster_links.is_empty()
        {
            cluster_links.sort_by_key(|l| (l.receiver, l.node));
            *c = Some(Box::new(ClusterLinks::new(
                patches,
                clusters,
                cluster_links,
            )));
        }
        transport
    }
}

/// What linking every object root with the room and the other objects
/// would make, measured on a sample of the roots: the texture path's cost,
/// known before it is paid ([`Transport::estimate_object_links`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ObjectLinkEstimate {
    /// The objects' roots, and how many of them were linked to measure.
    pub roots: usize,
    pub sampled: usize,
    /// Links (element and cluster) expected for all the roots, with the
    /// room's own (copied into the transport made).
    pub links: f64,
    /// Seconds expected for all the roots, at this machine's thread count.
    pub seconds: f64,
}

impl Transport {
    /// Links `sample` of the objects' roots, evenly spread over them (as
    /// [`Transport::with_objects`] with `objects_receive` links each), and
    /// scales what they made and took to all of them. `None` for a
    /// transport without hierarchical links or a scene without objects.
    pub fn estimate_object_links(
        &self,
        patches: &Patches,
        tracer: &Tracer,
        epsilon: f64,
        sample: usize,
    ) -> Option<ObjectLinkEstimate> {
        let Transport::Hierarchical { .. } = self else {
            return None;
        };
        let object_roots: Vec<u32> = (patches.roots.iter().copied())
            .filter(|r| patches.is_virtual_element(*r))
            .collect();
        if object_roots.is_empty() || sample == 0 {
            return None;
        }
        let room_roots: Vec<u32> = (patches.roots.iter().copied())
            .filter(|r| !patches.is_virtual_element(*r))
            .collect();
        let clusters = RootClusters::build(patches, &object_roots);
        let with = object_refiner(patches, tracer, epsilon, &clusters);
        let n = object_roots.len();
        let step = n.div_ceil(sample.min(n));
        let picked: Vec<u32> = object_roots.iter().step_by(step).copied().collect();
        let started = std::time::Instant::now();
        let links: usize = picked
            .par_iter()
            .map(|&v| {
                let (out, to_clusters) = link_object_root(&with, v, &room_roots);
                out.len() + to_clusters.len()
            })
            .sum();
        let scale = n as f64 / picked.len() as f64;
        Some(ObjectLinkEstimate {
            roots: n,
            sampled: picked.len(),
            // The room's links are copied into the new transport too.
            links: links as f64 * scale + self.link_count() as f64,
            seconds: started.elapsed().as_secs_f64() * scale,
        })
    }
}

/// How the objects' links are refined: through everything, the objects'
/// clusters among the occluders, a pair traced before it is split.
fn object_refiner<'a>(
    patches: &'a Patches,
    tracer: &'a Tracer,
    epsilon: f64,
    clusters: &'a RootClusters,
) -> Refiner<'a> {
    Refiner {
        patches,
        tracer,
        layer: Layer::All,
        epsilon,
        split_above_epsilon: false,
        objects: Some(clusters),
    }
}

/// The area of an object patch at the default virtual patch size (0.1 m).
const OBJECT_PATCH_AREA: f64 = 0.01;

/// Object root `v`'s links: from the room element by element, from the
/// objects through their clusters (element by element only near v), so
/// that the links grow as N log N with the objects' triangles, not N².
fn link_object_root(with: &Refiner, v: u32, room_roots: &[u32]) -> (Vec<Link>, Vec<ClusterLink>) {
    let (mut out, mut to_clusters) = (Vec::new(), Vec::new());
    // A triangle smaller than an object patch carries its share of the
    // patch's light: ε grows as its area shrinks (up to 256×), so that the
    // error of the light it gathers, weighted by its area, stays a patch's.
    let area = with.patches.elements[v as usize].area;
    let coarse = Refiner {
        epsilon: with.epsilon * (OBJECT_PATCH_AREA / area.max(1e-12)).clamp(1.0, 256.0),
        ..*with
    };
    for &r in room_roots {
        refine(&coarse, v, r, room_roots, &mut out);
    }
    refine_cluster(with, v, 0, room_roots, &mut out, &mut to_clusters);
    (out, to_clusters)
}

/// Which of the room's `links` the objects (`clusters`) may shadow: the
/// pair's box must meet the objects' box, its box shaft leave out no corner
/// of it, and a cluster of the objects may hold a root in the pair's shaft.
fn near_objects(
    patches: &Patches,
    room_links: &[Link],
    clusters: &RootClusters,
    facts: Option<&RoomLinkFacts>,
) -> Vec<bool> {
    let Some(top) = clusters.nodes.first() else {
        return vec![false; room_links.len()];
    };
    let (olo, ohi) = (top.lo, top.hi);
    let object_box = crate::geometry::box_corners(olo, ohi);
    let near = |i: usize| {
        let l = &room_links[i];
        let (a, b) = (
            &patches.elements[l.receiver as usize],
            &patches.elements[l.source as usize],
        );
        let ((alo, ahi), (blo, bhi)) = (a.bounds, b.bounds);
        let (lo, hi) = (alo.min(blo), ahi.max(bhi));
        if olo.cmpgt(hi).any() || ohi.cmplt(lo).any() {
            return false;
        }
        let fresh = PairShafts::default();
        let shafts = facts.and_then(|f| f.shafts.get(i)).unwrap_or(&fresh);
        // A shaft that leaves out the objects' whole box leaves out each of their roots.
        !shafts
            .coarse
            .get_or_init(|| Shaft::between_boxes(a.bounds, b.bounds))
            .excludes(&object_box)
            && clusters.any_may_block(&ShaftTest::new(patches, Layer::All, a, b, shafts))
    };
    (0..room_links.len()).into_par_iter().map(near).collect()
}

/// Refines room link `i` again with the objects as occluders, from the
/// link's kept room facts when there are some (made on first need).
fn relink_room_link(
    with: &Refiner,
    room_links: &[Link],
    i: usize,
    facts: Option<&RoomLinkFacts>,
    room_roots: &[u32],
    out: &mut Vec<Link>,
) {
    let l = room_links[i];
    let patches = with.patches;
    let (ep, eq) = (
        &patches.elements[l.receiver as usize],
        &patches.elements[l.source as usize],
    );
    match facts.and_then(|f| Some((f.facts.get(i)?, f.shafts.get(i)?))) {
        Some((cell, shafts)) => {
            let known = cell
                .get_or_init(|| PairFacts::of(patches, with.tracer, ep, eq, room_roots, shafts));
            refine_from(
                with,
                l.receiver,
                l.source,
                &[],
                &[0],
                Some((known, shafts)),
                out,
            );
        }
        None => refine(with, l.receiver, l.source, room_roots, out),
    }
}
