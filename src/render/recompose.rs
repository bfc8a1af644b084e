//! The composite of a session's pixels, after the rounds of per-pixel
//! samples the settings ask for ([`crate::residual`]).

use super::*;
use crate::residual::{PixelResidual, ResidualInput, estimate};

impl Session {
    /// Composites the image; `recomputed` lists the pixels whose real
    /// point's light terms changed since the last composite.
    pub(super) fn recomposite(&mut self, times: &mut StageTimes, recomputed: &[u32]) {
        let patches = self.changes.own.as_ref().map_or(&self.model.patches, |o| o);
        let kept = &mut self.changes.rays.near;
        let near = match (&self.changes.near, &self.changes.own) {
            (Some(source), Some(objects)) => {
                Some(times.time("the change near the objects", || {
                    let input = ChangeInput {
                        scene: &self.scene,
                        photo: &self.photo,
                        tracer: &self.tracer,
                        model: &self.model,
                        scales_with: &self.scales_with,
                        settings: &self.settings,
                        bounds: &self.bounds,
                        room: &self.room,
                    };
                    changes::near_field(&input, objects, source, &self.pda, kept)
                }))
            }
            _ => None,
        };
        let known = self.known.take();
        let mut out = std::mem::replace(&mut self.composite, crate::composite::Composite::empty());
        let materials = crate::object_shading::ObjectMaterials::of(&self.scene);
        let shading = ObjectShading {
            materials: &materials,
            tracer: &self.tracer,
            camera: &self.scene.camera,
            photo: &self.photo,
            lights: &self.model.lights,
            scales_with: &self.scales_with,
            scales_without: &self.scales_without,
            patches,
            indirect_with: &self.changes.indirect_with,
            indirect_without: &self.indirect_without,
            reflectance: &self.changes.reflectance,
            settings: self.settings.shading,
        };
        let residual = self.residual(&shading, times);
        let known = times.time("composite", || {
            let input = CompositeInput {
                objects: (!materials.is_empty()).then_some(&shading),
                pda: &self.pda,
                camera: &self.scene.camera,
                photo: &self.photo,
                photo_base: self.photo_base.as_ref(),
                lights: &self.model.lights,
                scales_without: &self.scales_without,
                scales_with: &self.scales_with,
                indirect_without: &self.indirect_without,
                indirect_with: &self.changes.indirect_with,
                reflectance: &self.changes.reflectance,
                patch_vertices: &patches.patch_vertices,
                mode: self.settings.mode,
                floor: ratio_floor(&self.model, &self.scales_without),
                known: None,
                near: near.as_ref(),
                residual: residual.as_ref(),
                layers: self.layers,
            };
            if !self.for_updates {
                composite_into(&input, &mut out);
                return None;
            }
            // Once, then kept for every update, which refreshes only what it recomputed.
            let known = match known {
                Some(mut k) => {
                    k.refresh(&input, recomputed);
                    k
                }
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
        if let Some((lamps, shot)) = &self.lamps {
            times.time("lamps in view", || {
                lamps.apply(&mut out, shot, &self.photo, &self.scales_with, &self.tracer)
            });
        }
        out.noise = Vec::new();
        if let Some(r) = residual {
            if r.noise.len() == out.image.pixels.len() {
                out.noise = r.noise;
            }
            self.rays += r.stats.rays;
            self.residual_stats = Some(match self.residual_stats {
                // A still's bands: their rounds are one, their work adds up.
                Some(s) if self.band.is_some() && !self.for_updates => s.and(&r.stats),
                _ => r.stats,
            });
        }
        self.composite = out;
        self.known = known;
    }

    /// The rounds of per-pixel samples the settings ask for (None: none).
    fn residual(&self, shading: &ObjectShading, times: &mut StageTimes) -> Option<PixelResidual> {
        let mut settings = self.settings.residual;
        if !settings.enabled() {
            return None;
        }
        if let Some(limit) = settings.time {
            // The bands after the first run the rounds it ran: its budget
            // is its share of what is left.
            let now = self.started.elapsed().as_secs_f64();
            settings.time = Some(now + (limit - now).max(0.0) * self.time_share);
        }
        let sampler = match (&self.changes.near, &self.changes.own) {
            (Some(_), Some(objects)) => Some(crate::radiosity::ChangeSampler::new(
                objects,
                &self.bounds,
                self.model.patches.patch_count(),
                &self.tracer,
            )),
            _ => None,
        };
        let no_coarse = Vec::new();
        let input = ResidualInput {
            pda: &self.pda,
            shading,
            room: sampler.as_ref(),
            coarse: self.changes.near.as_ref().map_or(&no_coarse, |s| &s.coarse),
            settings,
            started: self.started,
        };
        times.time("per-pixel rounds", || estimate(&input))
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
        let kept = self.settings.residual;
        self.settings.residual = crate::residual::ResidualSettings {
            samples: rounds,
            time: None,
        };
        self.started = std::time::Instant::now();
        self.residual_stats = None;
        self.recomposite(times, &[]);
        self.settings.residual = kept;
        self.residual_stats
    }
}
