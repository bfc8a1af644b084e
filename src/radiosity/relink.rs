//! Virtual objects added to a room's transport: the room's links they may
//! shadow refined again, and the room linked with what the objects send
//! it (element by element, or through their clusters).

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
    /// the objects send the room their light through [`ClusterLinks`]
    /// (element by element where their clusters are too near). The objects
    /// get no links of their own to gather through: the caller supplies
    /// their light (the texture path's [`GatherRows`](super::GatherRows),
    /// the pixel path's final gathering). A full matrix is rebuilt.
    pub fn with_objects(&self, patches: &Patches, tracer: &Tracer, epsilon: f64) -> Transport {
        self.with_objects_using(patches, tracer, epsilon, None)
    }

    /// [`Transport::with_objects`], keeping in `facts` (made for this
    /// transport by [`RoomLinkFacts::new`]) what it learns about the room's
    /// links for the next placement of the objects: the same links result.
    pub fn with_objects_using(
        &self,
        patches: &Patches,
        tracer: &Tracer,
        epsilon: f64,
        facts: Option<&RoomLinkFacts>,
    ) -> Transport {
        let Transport::Hierarchical {
            links: room_links, ..
        } = self
        else {
            return Transport::full(patches, tracer, Layer::All);
        };
        let plan = Plan::new(patches, room_links, facts);
        let mut links: Vec<Link> = room_links
            .iter()
            .zip(&plan.near)
            .filter(|(_, n)| !**n)
            .map(|(l, _)| *l)
            .collect();
        let with = object_refiner(patches, tracer, epsilon, &plan.clusters);
        let made: Vec<(Vec<Link>, Vec<ClusterLink>)> = (plan.tasks.par_iter())
            .with_max_len(4)
            .map(|task| plan.run(&with, room_links, *task, facts))
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
                plan.clusters,
                cluster_links,
            )));
        }
        transport
    }
}

/// What adding the objects to a room's links takes: one task per room
/// link the objects may shadow and per room root (what it receives from
/// the objects' clusters), so that both cores share the few large ones.
struct Plan {
    clusters: RootClusters,
    /// Per room link, whether the objects may shadow it.
    near: Vec<bool>,
    room_roots: Vec<u32>,
    tasks: Vec<Task>,
}

#[derive(Clone, Copy)]
enum Task {
    /// Room link `i`, refined again with the objects as occluders.
    Room(usize),
    /// What room root `r` receives from the objects' clusters.
    Cluster(u32),
}

impl Plan {
    fn new(patches: &Patches, room_links: &[Link], facts: Option<&RoomLinkFacts>) -> Plan {
        let is_virtual = |r: &u32| patches.is_virtual_element(*r);
        let object_roots: Vec<u32> = patches.roots.iter().copied().filter(is_virtual).collect();
        let clusters = RootClusters::build(patches, &object_roots);
        let near = near_objects(patches, room_links, &clusters, facts);
        let room_roots: Vec<u32> = (patches.roots.iter().copied())
            .filter(|r| !is_virtual(r))
            .collect();
        let cluster_tasks = match clusters.nodes.is_empty() {
            true => Vec::new(),
            false => room_roots.iter().map(|&r| Task::Cluster(r)).collect(),
        };
        let tasks = (0..room_links.len())
            .filter(|&i| near[i])
            .map(Task::Room)
            .chain(cluster_tasks)
            .collect();
        Plan {
            clusters,
            near,
            room_roots,
            tasks,
        }
    }

    fn run(
        &self,
        with: &Refiner,
        room_links: &[Link],
        task: Task,
        facts: Option<&RoomLinkFacts>,
    ) -> (Vec<Link>, Vec<ClusterLink>) {
        let (mut out, mut to_clusters) = (Vec::new(), Vec::new());
        match task {
            Task::Room(i) => {
                relink_room_link(with, room_links, i, facts, &self.room_roots, &mut out)
            }
            Task::Cluster(r) => {
                refine_cluster(with, r, 0, &self.room_roots, &mut out, &mut to_clusters)
            }
        }
        (out, to_clusters)
    }
}

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
