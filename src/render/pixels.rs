//! An update's pixel side: the objects' image and edges re-traced, the
//! pixel blocks traversed against their new bounds, the real pixels whose
//! shafts they may cross recomputed.

use super::*;

/// An update's pixel side: what it changes in the session.
pub(super) struct PixelUpdate<'a> {
    pub(super) pda: &'a mut PixelDataArray,
    pub(super) blocks: &'a crate::blocks::BlockHierarchy,
    pub(super) active: &'a [bool],
    pub(super) reached: &'a mut Vec<Reached>,
    pub(super) block_shafts: &'a mut Vec<crate::blocks::BlockShafts>,
    pub(super) stats: &'a mut UpdateStats,
    /// What moved since the last update (None: re-trace every pixel).
    pub(super) movers: Option<&'a dyn crate::objects::Movers>,
}

impl PixelUpdate<'_> {
    /// Re-traces the objects' image and edges and recomputes the real
    /// pixels whose shafts to a light may meet the objects' old or new
    /// bounds: the pixels touched (sorted), the rays cast, the pixels re-traced.
    pub(super) fn run(
        &mut self,
        changes: &ChangeInput,
        objects: Option<&Patches>,
        times: &mut StageTimes,
    ) -> (Vec<u32>, u64, u64) {
        let model = changes.model;
        let shaded = crate::object_shading::ObjectMaterials::surface_ids(changes.scene);
        let input = PdaInput {
            camera: &changes.scene.camera,
            tracer: changes.tracer,
            patches: objects.unwrap_or(&model.patches),
            lights: &model.lights,
            active: self.active,
            bounds: changes.bounds,
            settings: changes.settings.pda,
            for_updates: true,
            band: None,
            shaded_per_pixel: &shaded,
        };
        let pda = &mut *self.pda;
        let (mut rays, retraced) = times.time("re-trace objects and edges", || {
            pda.rebuild_virtual(&input, self.movers)
        });
        // The pixels whose shafts may meet the objects' old bounds are those
        // the last update (or the hierarchy's building) reached against
        // them: only the new bounds are traversed.
        let (traversals, now) = times.time("pixel-block traversal", || {
            traverse(
                &input,
                self.blocks,
                self.reached,
                self.block_shafts,
                self.movers,
            )
        });
        let stats = &mut *self.stats;
        let touched = times.time("recompute pixels", || {
            let mut touched: Vec<u32> = Vec::new();
            for (l, t) in traversals.into_iter().enumerate() {
                let Some(t) = t else {
                    stats.skipped_blocks.push(Vec::new());
                    continue;
                };
                stats.shaft_tests += t.shaft_tests;
                rays += pda.recompute_real_terms(&input, &t.pixels, &now[l].lists(), l);
                // A pixel found for several lights counts once.
                touched = merge_sorted(&touched, &t.pixels);
                stats.skipped_blocks.push(t.skipped);
            }
            stats.pixels_recomputed = touched.len();
            touched
        });
        *self.reached = now;
        (touched, rays, retraced)
    }
}

/// Per light, the pixels whose shafts to it may meet the objects where
/// they stand, by groups of surfaces traversed together: an update
/// recomputes the pixels of the groups that hold a surface that moved, and
/// traverses only against the moved surfaces' new bounds. A still object
/// beside a moving one costs its pixels once (when it leaves the group it
/// was traversed in), not at every update (the stool beside a still 2 m
/// table recomputed twice its own pixels).
#[derive(Debug, Clone, Default)]
pub(super) struct Reached {
    /// (surfaces, sorted; the pixels their bounds reach, sorted).
    groups: Vec<(Vec<u32>, Vec<u32>)>,
}

impl Reached {
    /// The pixels every surface of `bounds` reaches, as one group, and the
    /// shafts built on the way (a session's preparation).
    pub(super) fn prepared(
        blocks: &crate::blocks::BlockHierarchy,
        light: &crate::light::LightSource,
        bounds: &crate::objects::VirtualBounds,
    ) -> (Reached, crate::blocks::BlockShafts) {
        let mut shafts = blocks.no_shafts();
        let mut pixels = blocks.traverse(light, &bounds.objects, &mut shafts).pixels;
        pixels.sort_unstable();
        let mut surfaces: Vec<u32> = bounds.surface_bounds().map(|(s, _)| s).collect();
        surfaces.sort_unstable();
        (
            Reached {
                groups: vec![(surfaces, pixels)],
            },
            shafts,
        )
    }

    /// The groups' pixel lists.
    fn lists(&self) -> Vec<&[u32]> {
        self.groups.iter().map(|(_, p)| &p[..]).collect()
    }
}

/// One light's traversal at an update: the pixels to recompute (sorted)
/// with the traversal's counts, and what is reached now.
fn traverse_light(
    input: &PdaInput,
    blocks: &crate::blocks::BlockHierarchy,
    (light, before): (&crate::light::LightSource, Reached),
    movers: Option<&dyn crate::objects::Movers>,
    shafts: &mut crate::blocks::BlockShafts,
) -> (crate::blocks::Traversal, Reached) {
    let present: Vec<(u32, &crate::shaft::ObjectBounds)> = input.bounds.surface_bounds().collect();
    // Without what moved (the first pose after a re-trace), everything did.
    let moved = |s: u32| movers.is_none_or(|m| !m.unmoved(s));
    let here = |s: &u32| present.iter().any(|(p, _)| p == s);
    // A group stays while each of its surfaces stands where it stood.
    let (kept, stale): (Vec<_>, Vec<_>) = (before.groups.into_iter())
        .partition(|(surfaces, _)| surfaces.iter().all(|s| here(s) && !moved(*s)));
    let grouped = |s: u32| kept.iter().any(|(g, _)| g.binary_search(&s).is_ok());
    // The moved surfaces together; each still one of a stale group alone,
    // so that it is not traversed again when another moves.
    let loose: Vec<u32> = (present.iter().map(|(s, _)| *s))
        .filter(|&s| !grouped(s))
        .collect();
    let moving: Vec<u32> = loose.iter().copied().filter(|&s| moved(s)).collect();
    let fresh_groups = std::iter::once(moving)
        .filter(|m| !m.is_empty())
        .chain(loose.iter().filter(|&&s| !moved(s)).map(|&s| vec![s]));
    let mut out = crate::blocks::Traversal::default();
    let mut now = Reached { groups: kept };
    for (_, pixels) in &stale {
        out.pixels = merge_sorted(&out.pixels, pixels);
    }
    for surfaces in fresh_groups {
        let bounds: Vec<crate::shaft::ObjectBounds> = (present.iter())
            .filter(|(s, _)| surfaces.contains(s))
            .map(|(_, b)| **b)
            .collect();
        let mut t = blocks.traverse(light, &bounds, shafts);
        t.pixels.sort_unstable();
        out.pixels = merge_sorted(&out.pixels, &t.pixels);
        out.shaft_tests += t.shaft_tests;
        out.skipped.extend(t.skipped);
        let mut surfaces = surfaces;
        surfaces.sort_unstable();
        now.groups.push((surfaces, t.pixels));
    }
    (out, now)
}

/// Per active light, the pixels to recompute (the moved surfaces' old
/// and new reach; see [`Reached`]) with the traversal's counts, and what
/// is reached now; `reached` is taken.
pub(super) fn traverse(
    input: &PdaInput,
    blocks: &crate::blocks::BlockHierarchy,
    reached: &mut Vec<Reached>,
    block_shafts: &mut [crate::blocks::BlockShafts],
    movers: Option<&dyn crate::objects::Movers>,
) -> (Vec<Option<crate::blocks::Traversal>>, Vec<Reached>) {
    use rayon::prelude::*;
    let mut before = std::mem::take(reached);
    before.resize_with(input.lights.len(), Reached::default);
    let traversals: Vec<(Option<crate::blocks::Traversal>, Reached)> = input
        .lights
        .par_iter()
        .zip(before)
        .zip(block_shafts.par_iter_mut())
        .enumerate()
        .map(|(l, ((light, before), shafts))| match input.active[l] {
            true => {
                let (t, now) = traverse_light(input, blocks, (light, before), movers, shafts);
                (Some(t), now)
            }
            false => (None, Reached::default()),
        })
        .collect();
    traversals.into_iter().unzip()
}

/// The union of two sorted lists, sorted, each value once.
pub(super) fn merge_sorted(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        let v = a[i].min(b[j]);
        i += (a[i] == v) as usize;
        j += (b[j] == v) as usize;
        if out.last() != Some(&v) {
            out.push(v);
        }
    }
    for &v in a[i..].iter().chain(&b[j..]) {
        if out.last() != Some(&v) {
            out.push(v);
        }
    }
    out
}
