//! A session's lights scaled or switched in place: the pixel data, the
//! room's model and links and the objects' patches are kept, and what
//! depends on the lights' scales (the room's solution, the objects' change
//! to it, the composite) is computed again by the functions a full render
//! uses, so the image is the one a full render of the new scales gives.

use super::*;

/// Why a session cannot take new light scales in place (a full render can).
#[derive(Debug, Clone, PartialEq)]
pub enum Relight {
    /// Something besides the lights' scales changed.
    NotOnlyScales,
    /// A light is switched on that the pixel data holds no terms for, or
    /// off where a full render would leave it out.
    LightsTraced,
    /// A full render of the new scales would mesh the room otherwise (the
    /// automatic patch size follows whether the scene changes its lights).
    PatchSize,
}

/// The room's solution for each light alone at scale 1 (None for a light
/// the session never traces): radiosity is linear in the lights' emission
/// on fixed links, so any scales' solution is their weighted sum
/// (superposition), solved once per session, the first time its lights are
/// scaled. It agrees with a solve at the scales to the solver's tolerance
/// (a relative residual of 1e-7).
fn room_per_light(
    model: &Model,
    active: &[bool],
    settings: &RenderSettings,
    times: &mut StageTimes,
) -> Vec<Option<Solution>> {
    times.time("solve the room per light", || {
        let reflectance = &model.estimate.reflectance;
        (model.direct_per_light.iter().zip(active))
            .map(|(e, &active)| {
                if !active {
                    return None;
                }
                let b: Vec<DVec3> = reflectance.iter().zip(e).map(|(r, e)| *r * *e).collect();
                Some(solve_from(
                    &model.patches,
                    &model.transport,
                    reflectance,
                    &b,
                    None,
                    settings.model.estimate.solve_tolerance,
                    500,
                ))
            })
            .collect()
    })
}

/// Σ scaleₗ · Bₗ over the lights switched on (radiosity and indirect light).
fn superposed(per_light: &[Option<Solution>], scales: &[f64]) -> Solution {
    let n = per_light
        .iter()
        .flatten()
        .map(|s| s.radiosity.len())
        .next()
        .unwrap_or(0);
    let mut out = Solution {
        radiosity: vec![DVec3::ZERO; n],
        indirect_irradiance: vec![DVec3::ZERO; n],
        iterations: 0,
        residual: 0.0,
    };
    for (solution, &scale) in per_light.iter().zip(scales) {
        let Some(s) = solution.as_ref().filter(|_| scale > 0.0) else {
            continue;
        };
        for (o, b) in out.radiosity.iter_mut().zip(&s.radiosity) {
            *o += *b * scale;
        }
        for (o, h) in out
            .indirect_irradiance
            .iter_mut()
            .zip(&s.indirect_irradiance)
        {
            *o += *h * scale;
        }
        out.iterations = out.iterations.max(s.iterations);
        out.residual = out.residual.max(s.residual);
    }
    out
}

impl Relight {
    /// Why, in a few words, for a report.
    pub fn describe(&self) -> &'static str {
        match self {
            Relight::NotOnlyScales => "more than their scales changed",
            Relight::LightsTraced => "a light switched on or off that the pixel data does not hold",
            Relight::PatchSize => "the room meshed finer or coarser for the new scales",
        }
    }
}

impl Session {
    /// Renders `scene`, which differs from the session's only in its
    /// lights' scales, without tracing a pixel again; the image is bit for
    /// bit what [`Session::start`] of `scene` gives. `Err` says why it
    /// cannot (the caller renders in full).
    pub fn relight(
        &mut self,
        scene: &Scene,
        times: &mut StageTimes,
    ) -> std::result::Result<(), Relight> {
        self.check_relight(scene)?;
        self.started = std::time::Instant::now();
        for (kept, given) in self.scene.lights.iter_mut().zip(&scene.lights) {
            kept.scale = given.scale;
        }
        for (light, given) in self.model.lights.iter_mut().zip(&scene.lights) {
            light.scale = given.scale;
        }
        self.given_lights.clone_from(&scene.lights);
        self.scales_with = self.model.lights.iter().map(|l| l.scale).collect();
        let brightens = (self.scales_with.iter().zip(&self.scales_without)).any(|(w, wo)| w > wo);
        let grain = "the photo's grain: no light is added or scaled up";
        self.left_out.retain(|l| l != grain);
        if !brightens {
            self.photo_base = None;
            self.left_out.push(grain.to_string());
        } else if self.photo_base.is_none() {
            let lamps = self.lamps.as_ref().map(|l| &l.0);
            let photo = &self.photo;
            self.photo_base = Some(times.time("photo grain", || photo_without_grain(photo, lamps)));
        }
        let (model, active, settings) = (&self.model, &self.active, &self.settings);
        let per_light = self
            .room_per_light
            .get_or_insert_with(|| room_per_light(model, active, settings, times));
        self.room = times.time("solve the room", || {
            superposed(per_light, &self.scales_with)
        });
        let objects = self.changes.own.take().filter(|_| self.has_objects());
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
        // The pose is the same: its rays are read with the new radiosity.
        let rays = std::mem::take(&mut self.changes.rays);
        let directions = &mut self.gather_directions;
        let solved = solve_changes(&input, objects.as_ref(), directions, rays.view, times);
        self.changes = solved.with_patches(objects);
        self.changes.rays.near = rays.near;
        // Every real pixel's composite reads the scales: none is kept.
        self.known = None;
        self.recomposite(times, &[]);
        Ok(())
    }

    fn has_objects(&self) -> bool {
        self.tracer.virtual_objects.is_some()
    }

    /// Whether `scene` is the session's but for its lights' scales, with the
    /// same lights traced and the same room mesh as a full render of it.
    fn check_relight(&self, scene: &Scene) -> std::result::Result<(), Relight> {
        let unscaled = |l: &crate::scene::Light| crate::scene::Light {
            scale: 0.0,
            ..l.clone()
        };
        let same_lights = scene.lights.len() == self.given_lights.len()
            && (scene.lights.iter().zip(&self.given_lights))
                .all(|(a, b)| unscaled(a) == unscaled(b));
        let same_objects = scene.objects.len() == self.scene.objects.len()
            && (scene.objects.iter().zip(&self.scene.objects))
                .all(|(a, b)| a.enabled == b.enabled && a.pose == b.pose);
        if !same_lights
            || !same_objects
            || scene.camera != self.scene.camera
            || scene.surfaces.len() != self.scene.surfaces.len()
        {
            return Err(Relight::NotOnlyScales);
        }
        let active = (scene.lights.iter().zip(&self.scales_without))
            .map(|(l, &without)| l.scale > 0.0 || without > 0.0);
        if !active.eq(self.active.iter().copied()) {
            return Err(Relight::LightsTraced);
        }
        // A goniometric reconstruction or a patch size given in metres keeps
        // the mesh; the automatic one is fine exactly when lights change.
        if self.settings.patch_size == PatchSize::Auto
            && lights_change(&scene.lights) != lights_change(&self.given_lights)
        {
            return Err(Relight::PatchSize);
        }
        Ok(())
    }
}
