//! An update's pixel side: the objects' image and edges re-traced, the
//! pixel blocks traversed against their new bounds, the real pixels whose
//! shafts they may cross recomputed.

use super::*;

/// An update's pixel side: what it changes in the session.
pub(super) struct PixelUpdate<'a> {
    pub(super) pda: &'a mut PixelDataArray,
    pub(super) blocks: &'a crate::blocks::BlockHierarchy,
    pub(super) active: &'a [bool],
    pub(super) reached: &'a mut Vec<Vec<u32>>,
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
            traverse(&input, self.blocks, self.reached, self.block_shafts)
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
                rays += pda.recompute_real_terms(&input, &t.pixels, &now[l], l);
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

/// Per active light, the blocks' traversal against the objects' new
/// bounds with the pixels reached before merged in, and the pixels reached
/// now (sorted); `reached` is taken.
pub(super) fn traverse(
    input: &PdaInput,
    blocks: &crate::blocks::BlockHierarchy,
    reached: &mut Vec<Vec<u32>>,
    block_shafts: &mut [crate::blocks::BlockShafts],
) -> (Vec<Option<crate::blocks::Traversal>>, Vec<Vec<u32>>) {
    use rayon::prelude::*;
    let traversals: Vec<Option<(crate::blocks::Traversal, Vec<u32>)>> = input
        .lights
        .par_iter()
        .zip(std::mem::take(reached))
        .zip(block_shafts.par_iter_mut())
        .enumerate()
        .map(|(l, ((light, before), shafts))| {
            input.active[l].then(|| {
                let mut t = blocks.traverse(light, &input.bounds.objects, shafts);
                let mut now = std::mem::take(&mut t.pixels);
                now.sort_unstable();
                // Both lists sorted: merged, not sorted again.
                t.pixels = merge_sorted(&now, &before);
                (t, now)
            })
        })
        .collect();
    traversals
        .into_iter()
        .map(|t| t.map_or((None, Vec::new()), |(t, now)| (Some(t), now)))
        .unzip()
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
