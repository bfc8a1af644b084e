//! The composite of a session's pixels, after the rounds of per-pixel
//! samples the settings ask for ([`crate::residual`]).

use super::*;
use crate::residual::{PixelResidual, ResidualInput, estimate};

/// The last composite's shadow edges (without rounds: the residual holds
/// nothing else), with the lights on they were sampled for.
#[derive(Default)]
pub(super) struct KeptEdges {
    last: Option<(Vec<bool>, PixelResidual)>,
    /// Nothing moved since they were sampled (a relight is next).
    pub(super) still: bool,
}

impl Session {
    /// Composites the image; `recomputed` lists the pixels whose real
    /// point's light terms changed since the last composite.
    pub(super) fn recomposite(&mut self, times: &mut StageTimes, recomputed: &[u32]) {
        let patches = own_or_room(&self.pose.changes.own, &self.prepared.model);
        let kept = &mut self.pose.changes.rays.near;
        let near = match (&self.pose.changes.near, &self.pose.changes.own) {
            (Some(source), Some(objects)) => {
                Some(times.time("the change near the objects", || {
                    let input = self.prepared.change_input(
                        &self.pose.scales_with,
                        &self.pose.bounds,
                        &self.pose.room,
                    );
                    changes::near_field(&input, objects, source, &self.pose.pda, kept)
                }))
            }
            _ => None,
        };
        let known = self.pose.known.take();
        // The shadow edges' samples read the geometry and which lights are
        // on, not their scales: a relight that switches none on or off
        // takes the last ones (the same, bit for bit; a ninth of a
        // `lounge` relight's time, traced again).
        let on: Vec<bool> = self.pose.scales_with.iter().map(|&s| s > 0.0).collect();
        let still = std::mem::take(&mut self.pose.edges.still);
        let kept_edges = (self.pose.edges.last.take())
            .filter(|(was_on, _)| still && *was_on == on)
            .map(|(_, edges)| edges);
        let mut out = std::mem::replace(&mut self.composite, crate::composite::Composite::empty());
        let materials = crate::object_shading::ObjectMaterials::of(&self.prepared.scene);
        let shading = ObjectShading {
            materials: &materials,
            tracer: &self.prepared.tracer,
            camera: &self.prepared.scene.camera,
            photo: &self.prepared.photo,
            lights: &self.prepared.model.lights,
            scales_with: &self.pose.scales_with,
            scales_without: &self.prepared.scales_without,
            patches,
            indirect_with: &self.pose.changes.indirect_with,
            indirect_without: &self.prepared.indirect_without,
            reflectance: &self.pose.changes.reflectance,
            settings: self.prepared.settings.shading,
            brightness: crate::object_shading::mean_luminance(&self.prepared.photo),
        };
        let rounds = self.prepared.settings.residual.enabled();
        let kept_edges = kept_edges.filter(|_| !rounds);
        let reused = kept_edges.is_some();
        let residual = match kept_edges {
            Some(edges) => Some(edges),
            None => self.residual(&shading, times),
        };
        // A session's objects with materials are shaded first, their samples
        // kept for the next update (rounds sample them their own way).
        let mut kept = std::mem::take(&mut self.pose.shaded);
        let shaded = (self.run.for_updates
            && !materials.is_empty()
            && !self.prepared.settings.residual.enabled())
        .then(|| times.time("objects' pixels", || kept.shade(&shading, &self.pose.pda)));
        let known = times.time("composite", || {
            let input = CompositeInput {
                objects: (!materials.is_empty()).then_some(&shading),
                pda: &self.pose.pda,
                camera: &self.prepared.scene.camera,
                photo: &self.prepared.photo,
                photo_base: self.prepared.photo_base.as_ref(),
                lights: &self.prepared.model.lights,
                scales_without: &self.prepared.scales_without,
                scales_with: &self.pose.scales_with,
                indirect_without: &self.prepared.indirect_without,
                indirect_with: &self.pose.changes.indirect_with,
                reflectance: &self.pose.changes.reflectance,
                patch_vertices: &patches.patch_vertices,
                mode: self.prepared.settings.mode,
                floor: ratio_floor(&self.prepared.model, &self.prepared.scales_without),
                known: None,
                near: near.as_ref(),
                residual: residual.as_ref(),
                shaded: shaded.as_ref(),
                layers: self.run.layers,
            };
            if !self.run.for_updates {
                composite_into(&input, &mut out);
                return None;
            }
            // Once, then kept for every update, which refreshes only what it recomputed.
            let known = match known {
                Some(k) => k.again(&input, recomputed),
                None => RealPixels::of(&input),
            };
            composite_into(
                &CompositeInput {
                    known: Some(&known),
                    ..input
                },
                &mut out,
            );
            Some(known)
        });
        if let Some((lamps, shot)) = &self.prepared.lamps {
            times.time("lamps in view", || {
                lamps.apply(
                    &mut out,
                    shot,
                    &self.prepared.photo,
                    &self.pose.scales_with,
                    &self.prepared.tracer,
                )
            });
        }
        out.noise = Vec::new();
        if let Some(r) = residual.as_ref().filter(|_| !reused) {
            self.run.rays += r.stats.rays;
        }
        // Without rounds only the shadow edges ran: no rounds to report,
        // the edges kept for a relight.
        if !rounds {
            self.pose.edges.last = residual.map(|r| (on, r));
        } else if let Some(r) = residual {
            if r.noise.len() == out.image.pixels.len() {
                out.noise = r.noise;
            }
            self.run.residual_stats = Some(match self.run.residual_stats {
                // A still's bands: their rounds are one, their work adds up.
                Some(s) if self.run.band.is_some() && !self.run.for_updates => s.and(&r.stats),
                _ => r.stats,
            });
        }
        self.composite = out;
        self.pose.known = known;
        self.pose.shaded = kept;
    }

    /// The rounds of per-pixel samples the settings ask for; without
    /// rounds, the point lights' shadow edges alone (None: nothing to
    /// sample).
    fn residual(&self, shading: &ObjectShading, times: &mut StageTimes) -> Option<PixelResidual> {
        let mut settings = self.prepared.settings.residual;
        if let Some(limit) = settings.time {
            // The bands after the first run the rounds it ran: its budget
            // is its share of what is left.
            let now = self.run.started.elapsed().as_secs_f64();
            settings.time = Some(now + (limit - now).max(0.0) * self.run.time_share);
        }
        let sampler = match (&self.pose.changes.near, &self.pose.changes.own) {
            (Some(_), Some(objects)) => Some(crate::radiosity::ChangeSampler::new(
                objects,
                &self.pose.bounds,
                self.prepared.model.patches.patch_count(),
                &self.prepared.tracer,
            )),
            _ => None,
        };
        let no_coarse = Vec::new();
        let input = ResidualInput {
            pda: &self.pose.pda,
            shading,
            room: sampler.as_ref(),
            coarse: self
                .pose
                .changes
                .near
                .as_ref()
                .map_or(&no_coarse, |s| &s.coarse),
            settings,
            started: self.run.started,
        };
        match settings.enabled() {
            true => times.time("per-pixel rounds", || estimate(&input)),
            // Without rounds, the shadow edges alone (see `estimate`).
            false => times.time("shadow edges", || estimate(&input)),
        }
    }
}

impl Session {
    /// The current pose composited again with `rounds` rounds of per-pixel
    /// samples (0: none): the image `render` gives of it with `--samples
    /// rounds`. The session's own setting, which its updates use, stays.
    /// Returns what the rounds did (None: none ran).
    pub fn refine(
        &mut self,
        rounds: u32,
        times: &mut StageTimes,
    ) -> Option<crate::residual::ResidualStats> {
        let kept = self.prepared.settings.residual;
        self.prepared.settings.residual = crate::residual::ResidualSettings {
            samples: rounds,
            time: None,
        };
        self.run.started = std::time::Instant::now();
        self.run.residual_stats = None;
        self.recomposite(times, &[]);
        self.prepared.settings.residual = kept;
        self.run.residual_stats
    }
}
