//! A session's lights scaled or switched in place: the pixel data, the
//! room's model and links, the objects' patches and the pose's rays are
//! kept; the room's solution and the objects' change are sums of each
//! light's alone (superposition: radiosity is linear in the emission on
//! fixed links), and the composite is computed again. The image is a full
//! render's of the new scales to the solvers' tolerances (1e-5 relative).

use super::*;

/// Why a session cannot take new light scales in place (a full render can).
#[derive(Debug, Clone, PartialEq)]
pub enum Relight {
    /// Something besides the lights' scales changed.
    NotOnlyScales,
    /// A light is switched on that the kept pixel data (or the texture
    /// path's preprocess) holds nothing for, or off where a full render
    /// would leave it out.
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
                crate::util::pause::point();
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

/// Σ scaleₗ · Bₗ over the lights switched on (radiosity and indirect
/// light), over the room's `n` patches (zero where every light is off).
fn superposed(per_light: &[Option<Solution>], scales: &[f64], n: usize) -> Solution {
    let mut out = dark(n);
    for (solution, &scale) in per_light.iter().zip(scales) {
        let Some(s) = solution.as_ref().filter(|_| scale > 0.0) else {
            continue;
        };
        add_scaled(&mut out.radiosity, &s.radiosity, scale);
        add_scaled(&mut out.indirect_irradiance, &s.indirect_irradiance, scale);
        out.iterations = out.iterations.max(s.iterations);
        out.residual = out.residual.max(s.residual);
    }
    out
}

/// The room's solution with every light off.
fn dark(n: usize) -> Solution {
    Solution {
        radiosity: vec![DVec3::ZERO; n],
        indirect_irradiance: vec![DVec3::ZERO; n],
        iterations: 0,
        residual: 0.0,
    }
}

/// `out += part × scale`, value by value.
fn add_scaled(out: &mut [DVec3], part: &[DVec3], scale: f64) {
    for (o, p) in out.iter_mut().zip(part) {
        *o += *p * scale;
    }
}

/// The final gather reads the photo times the room's radiosity with the
/// change over the photo's, that ratio capped at 4
/// ([`super::changes`]): below the cap the change is linear in the
/// lights' scales. Where the room alone comes within 3 of it (leaving the
/// objects' own light a third of the room's before the cap could bind),
/// the change is solved at the scales instead.
fn below_gather_clamp(room: &Solution, model: &Model) -> bool {
    let without = &model.estimate.solution.radiosity;
    (room.radiosity.iter().zip(without))
        .all(|(b, w)| (*b / w.max(DVec3::splat(1e-12))).max_element() <= 3.0)
}

/// The objects' change made by each light alone at scale 1 (and by the
/// objects' own glow with every light off), at one pose: the change at any
/// scales is their weighted sum, as the room's solution is.
pub(super) struct ChangeBasis {
    lights: Vec<Option<Solved>>,
    glow: Option<Solved>,
}

/// What a [`ChangeBasis`] is solved from.
struct BasisParts<'a> {
    input: &'a ChangeInput<'a>,
    patches: &'a Patches,
    /// The room's solution per light ([`room_per_light`]).
    rooms: &'a [Option<Solution>],
}

impl BasisParts<'_> {
    fn solve(
        &self,
        directions: &mut GatherDirections,
        view: &mut Option<crate::radiosity::ObjectView>,
        times: &mut StageTimes,
    ) -> ChangeBasis {
        let n = self.input.scales_with.len();
        // Nothing moves between the parts (nor since the pose's own solve):
        // each vertex's gather rays are kept and summed again over the part's
        // radiosity, what tracing them again gives (trio's four parts'
        // gathers 88 → 15 ms).
        let (scene, bounds) = (self.input.scene, self.input.bounds);
        let still = crate::radiosity::StillSurfaces::between(
            (bounds, self.patches),
            (bounds, self.patches),
            &super::room::unmoved_surfaces(scene, scene),
        );
        directions.since = Some(still);
        let mut part = |scales: &[f64], room: &Solution| {
            let input = ChangeInput {
                scales_with: scales,
                room,
                ..*self.input
            };
            solve_changes(&input, Some(self.patches), directions, view, times)
        };
        let lights = (0..n)
            .map(|l| {
                let room = self.rooms.get(l)?.as_ref()?;
                let mut unit = vec![0.0; n];
                unit[l] = 1.0;
                Some(part(&unit, room))
            })
            .collect();
        let glow = (!self.input.scene.virtual_surface_emission().is_empty())
            .then(|| part(&vec![0.0; n], &dark(self.input.model.patches.patch_count())));
        directions.since = None;
        ChangeBasis { lights, glow }
    }
}

impl ChangeBasis {
    /// Σ scaleₗ · changeₗ, plus the glow's (None: the basis is empty, no
    /// light traced and no glow).
    fn at(&self, scales: &[f64]) -> Option<Solved> {
        let parts = (self.lights.iter().zip(scales))
            .filter_map(|(s, &scale)| Some((s.as_ref().filter(|_| scale > 0.0)?, scale)))
            .chain(self.glow.as_ref().map(|g| (g, 1.0)));
        let first = (self.lights.iter().flatten().chain(&self.glow)).next()?;
        let zero = |v: &[DVec3]| vec![DVec3::ZERO; v.len()];
        let mut out = Solved {
            reflectance: first.reflectance.clone(),
            indirect_with: zero(&first.indirect_with),
            near: first.near.as_ref().map(|n| NearSource {
                radiosity: zero(&n.radiosity),
                coarse: zero(&n.coarse),
            }),
            bytes: first.bytes,
        };
        for (part, scale) in parts {
            add_scaled(&mut out.indirect_with, &part.indirect_with, scale);
            if let (Some(o), Some(p)) = (out.near.as_mut(), part.near.as_ref()) {
                add_scaled(&mut o.radiosity, &p.radiosity, scale);
                add_scaled(&mut o.coarse, &p.coarse, scale);
            }
        }
        Some(out)
    }

    /// Bytes of the parts' vertex and patch values.
    pub(super) fn memory_bytes(&self) -> usize {
        let values = |s: &Solved| {
            s.indirect_with.len()
                + s.near
                    .as_ref()
                    .map_or(0, |n| n.radiosity.len() + n.coarse.len())
        };
        let count: usize = (self.lights.iter().flatten().chain(&self.glow))
            .map(values)
            .sum();
        count * std::mem::size_of::<DVec3>()
    }
}

impl Relight {
    /// Why, in a few words, for a report.
    pub fn describe(&self) -> &'static str {
        match self {
            Relight::NotOnlyScales => "more than their scales changed",
            Relight::LightsTraced => "a light switched on or off that what is kept does not hold",
            Relight::PatchSize => "the room meshed finer or coarser for the new scales",
        }
    }
}

impl Session {
    /// Renders `scene`, which differs from the session's only in its
    /// lights' scales, without tracing a pixel again; the image is what
    /// [`Session::start`] of `scene` gives, to 1e-5 relative. `Err` says why
    /// it cannot (the caller renders in full).
    pub fn relight(
        &mut self,
        scene: &Scene,
        times: &mut StageTimes,
    ) -> std::result::Result<(), Relight> {
        self.check_relight(scene)?;
        // The scales it holds: its image is already theirs, bit for bit
        // (a session standing by for the lights as photographed, taken
        // back at them).
        let scales =
            |lights: &[crate::scene::Light]| lights.iter().map(|l| l.scale).collect::<Vec<_>>();
        if scales(&self.prepared.scene.lights) == scales(&scene.lights) {
            return Ok(());
        }
        self.run.started = std::time::Instant::now();
        for (kept, given) in self.prepared.scene.lights.iter_mut().zip(&scene.lights) {
            kept.scale = given.scale;
        }
        for (light, given) in self.prepared.model.lights.iter_mut().zip(&scene.lights) {
            light.scale = given.scale;
        }
        self.prepared.given_lights.clone_from(&scene.lights);
        self.pose.scales_with = self.prepared.model.lights.iter().map(|l| l.scale).collect();
        let brightens = (self
            .pose
            .scales_with
            .iter()
            .zip(&self.prepared.scales_without))
        .any(|(w, wo)| w > wo);
        let grain = "the photo's grain: no light is added or scaled up";
        self.run.left_out.retain(|l| l != grain);
        if !brightens {
            self.prepared.photo_base = None;
            self.run.left_out.push(grain.to_string());
        } else if self.prepared.photo_base.is_none() {
            let lamps = self.prepared.lamps.as_ref().map(|l| &l.0);
            let photo = &self.prepared.photo;
            self.prepared.photo_base =
                Some(times.time("photo grain", || photo_without_grain(photo, lamps)));
        }
        let (model, active, settings) = (
            &self.prepared.model,
            &self.pose.active,
            &self.prepared.settings,
        );
        let per_light = (self.pose.room_per_light)
            .get_or_insert_with(|| room_per_light(model, active, settings, times));
        let n = model.patches.patch_count();
        self.pose.room = times.time("solve the room", || {
            superposed(per_light, &self.pose.scales_with, n)
        });
        self.relit_change(times);
        // Every real pixel's composite reads the scales: none is kept but
        // the seams.
        self.pose.known = self.pose.known.take().map(RealPixels::for_new_scales);
        // Nothing moved: the shadow edges sampled last hold where the same lights are on.
        self.pose.edges.still = true;
        self.recomposite(times, &[]);
        Ok(())
    }

    /// Solves ahead what the next [`Session::relight`] would: the room per
    /// light, and the objects' change per light at this pose where it is
    /// linear in the scales. Does nothing where a scale change would
    /// render in full (the automatic patch size meshes the room finer once
    /// lights change from the photo's). An interactive session calls it
    /// while idle, so that a slider's first step costs what its others do
    /// (lounge: 0.66–1.1 s solved on that step before). Returns whether
    /// anything was solved.
    pub fn prepare_relights(&mut self, times: &mut StageTimes) -> bool {
        let settings = &self.prepared.settings;
        if settings.patch_size == PatchSize::Auto && !lights_change(&self.prepared.given_lights) {
            return false;
        }
        let mut solved = false;
        let (model, active) = (&self.prepared.model, &self.pose.active);
        if self.pose.room_per_light.is_none() {
            self.pose.room_per_light = Some(room_per_light(model, active, settings, times));
            solved = true;
        }
        let linear = below_gather_clamp(&self.pose.room, model);
        let objects = self.pose.changes.own.take();
        if let (Some(patches), true, None) =
            (objects.as_ref(), linear, &self.pose.changes.per_light)
        {
            self.pose.changes.per_light = self.change_basis(patches, times);
            solved |= self.pose.changes.per_light.is_some();
        }
        self.pose.changes.own = objects;
        solved
    }

    /// The objects' change at the session's scales: the sum of each
    /// light's alone (solved once per pose) where that is the change a full
    /// render computes, else solved at the scales.
    fn relit_change(&mut self, times: &mut StageTimes) {
        let objects = self.pose.changes.own.take();
        let kept = self.pose.changes.per_light.take();
        let linear = below_gather_clamp(&self.pose.room, &self.prepared.model);
        let basis = match (objects.as_ref(), linear) {
            (Some(patches), true) => kept.or_else(|| self.change_basis(patches, times)),
            _ => None,
        };
        let summed = basis.and_then(|basis| {
            let solved = times.time("sum the change per light", || {
                basis.at(&self.pose.scales_with)
            });
            solved.map(|s| (s, basis))
        });
        // The pose is the same: its rays are read with the new radiosity.
        let mut rays = std::mem::take(&mut self.pose.changes.rays);
        let (solved, per_light) = match summed {
            Some((solved, basis)) => (solved, Some(basis)),
            None => {
                let input = self.prepared.change_input(
                    &self.pose.scales_with,
                    &self.pose.bounds,
                    &self.pose.room,
                );
                let directions = &mut self.pose.gather_directions;
                let solved =
                    solve_changes(&input, objects.as_ref(), directions, &mut rays.view, times);
                (solved, None)
            }
        };
        self.pose.changes = solved.with_patches(objects, rays);
        self.pose.changes.per_light = per_light;
    }

    /// The objects' change per light at this pose (`patches`: the pose's
    /// objects, which the caller holds meanwhile); None before the room is
    /// solved per light.
    fn change_basis(&mut self, patches: &Patches, times: &mut StageTimes) -> Option<ChangeBasis> {
        let rooms = self.pose.room_per_light.as_ref()?;
        let input =
            self.prepared
                .change_input(&self.pose.scales_with, &self.pose.bounds, &self.pose.room);
        let parts = BasisParts {
            input: &input,
            patches,
            rooms,
        };
        let (directions, view) = (
            &mut self.pose.gather_directions,
            &mut self.pose.changes.rays.view,
        );
        Some(parts.solve(directions, view, times))
    }

    /// Whether `scene` is the session's but for its lights' scales, with the
    /// same lights traced and the same room mesh as a full render of it.
    fn check_relight(&self, scene: &Scene) -> std::result::Result<(), Relight> {
        let unscaled = |l: &crate::scene::Light| crate::scene::Light {
            scale: 0.0,
            ..l.clone()
        };
        let same_lights = scene.lights.len() == self.prepared.given_lights.len()
            && (scene.lights.iter().zip(&self.prepared.given_lights))
                .all(|(a, b)| unscaled(a) == unscaled(b));
        let same_objects = scene.objects.len() == self.prepared.scene.objects.len()
            && (scene.objects.iter().zip(&self.prepared.scene.objects))
                .all(|(a, b)| a.enabled == b.enabled && a.pose == b.pose);
        if !same_lights
            || !same_objects
            || scene.camera != self.prepared.scene.camera
            || scene.surfaces.len() != self.prepared.scene.surfaces.len()
        {
            return Err(Relight::NotOnlyScales);
        }
        let active = (scene.lights.iter().zip(&self.prepared.scales_without))
            .map(|(l, &without)| l.scale > 0.0 || without > 0.0);
        if !active.eq(self.pose.active.iter().copied()) {
            return Err(Relight::LightsTraced);
        }
        // A goniometric reconstruction or a patch size given in metres keeps
        // the mesh; the automatic one is fine exactly when lights change.
        if self.prepared.settings.patch_size == PatchSize::Auto
            && lights_change(&scene.lights) != lights_change(&self.prepared.given_lights)
        {
            return Err(Relight::PatchSize);
        }
        Ok(())
    }
}
