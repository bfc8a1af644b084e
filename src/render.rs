//! [`render`]: the augmented photo of a scene, stage by stage — the model of
//! the photographed room (estimation), radiosity with the changes (virtual
//! objects taking part, lights at their new scales), the Pixel Data Array,
//! and the differential composite. Stages a scene does not need are left
//! out and listed: no change returns the photo; no virtual object builds no
//! virtual geometry and reuses the room's light transport.

use glam::DVec3;

use crate::composite::{Composite, CompositeInput, CompositeMode, RealPixels, composite_into};
use crate::error::Result;
use crate::image_io::Image;
use crate::lamps::LampPixels;
use crate::model::{Model, ModelSettings};
use crate::object_shading::ObjectShading;
use crate::util::stages::StageTimes;

use crate::inputs::{
    coverage_warning, fine_patch_size, lamps_in_view, resolve_inputs, room_diagonal,
};
pub use crate::output::RenderOutput;
use crate::patches::{ObjectMeshes, Patches};
use crate::pda::{CLEAR_TEST_LIMIT, PdaInput, PdaSettings, PixelDataArray, VirtualBounds};
use crate::radiosity::{Solution, solve_from, total_direct};
use crate::scene::Scene;
use crate::trace::Layer;

/// The room's patch size for a render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PatchSize {
    /// From what the scene changes, relative to the room's size: light
    /// changes alter every pixel's indirect light and need the room's
    /// radiosity fine (its bounding-box diagonal / 24: 0.26 m on the desk,
    /// whose 4 m walls then split into 0.25 m patches);
    /// added objects change the room's light locally and gather their own
    /// from the photo, so a coarse room does (diagonal / 6). Measured on the
    /// desk: object variants 0.0038 at 1 m in 0.43 s against 0.0036 at 0.5 m
    /// in 0.69 s; light variants 0.0068 at 0.25 m against 0.016 at 1 m.
    Auto,
    Metres(f64),
}

/// Render settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// `model.patch_size` is replaced by the resolved `patch_size`.
    pub model: ModelSettings,
    pub patch_size: PatchSize,
    /// Largest patch edge on virtual objects (their indirect light shows directly).
    pub virtual_patch_size: f64,
    pub pda: PdaSettings,
    pub mode: CompositeMode,
    /// Rays per virtual-object vertex gathering indirect light from the
    /// photo (final gathering); 0 keeps the radiosity solution's value.
    /// 144 (12×12 strata): on the desk's box variants the error on the box
    /// is the same as at 256 and 1024 to within ±2.5% (the truth's own
    /// noise), at 4 ms against 7 and 27; 64 and 16 lose up to 3% and 20%.
    /// Vertices on faces turned from the camera take a quarter of them.
    pub gather_rays: u32,
    /// Samples of the objects that have materials ([`crate::object_shading`]).
    pub shading: crate::object_shading::ShadingSettings,
    /// Rounds of per-pixel samples over the kept solution ([`crate::residual`]).
    pub residual: crate::residual::ResidualSettings,
    /// Objects of this many triangles or more are meshed coarse
    /// ([`crate::patches::ObjectMeshes::coarse_from`]; None: never).
    pub coarse_objects_from: Option<usize>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            model: ModelSettings::default(),
            patch_size: PatchSize::Auto,
            virtual_patch_size: 0.1,
            pda: PdaSettings::default(),
            mode: CompositeMode::Ratio,
            gather_rays: 144,
            shading: crate::object_shading::ShadingSettings::default(),
            residual: crate::residual::ResidualSettings::default(),
            coarse_objects_from: Some(crate::scene_tracer::INSTANCE_TRIANGLES),
        }
    }
}

/// Renders `scene` (an effective scene: a variant or motion pose of the
/// loaded one) over `photo`.
pub fn render(
    scene: &Scene,
    photo: &Image,
    settings: &RenderSettings,
    times: &mut StageTimes,
) -> Result<RenderOutput> {
    let (reachable, dropped) = without_unreachable_objects(scene);
    let mut out = render_reachable(reachable.as_ref().unwrap_or(scene), photo, settings, times)?;
    out.left_out.extend(dropped);
    Ok(out)
}

/// `scene` with its enabled virtual objects that can change nothing
/// switched off: an object whose box lies outside the box of the room and
/// its lights cannot shadow or light anything in it, and one outside the
/// camera's view is not seen, so such an object costs no ray and no form
/// factor. `None` when every object stays; the notes say which went.
fn without_unreachable_objects(scene: &Scene) -> (Option<Scene>, Vec<String>) {
    let real = scene
        .surfaces
        .iter()
        .flat_map(|s| s.triangles.iter().flatten())
        .map(|p| p.as_dvec3());
    let lights = scene.lights.iter().filter_map(|l| l.known_position());
    let (lo, hi) = crate::geometry::bounds(real.chain(lights));
    let margin = 0.01 * (hi - lo).length();
    let (lo, hi) = (lo - margin, hi + margin);
    let mut out: Option<Scene> = None;
    let mut notes = Vec::new();
    for (k, object) in scene.objects.iter().enumerate() {
        if !object.enabled {
            continue;
        }
        let points: Vec<DVec3> = (0..object.surfaces.len())
            .flat_map(|i| object.world_triangles(i))
            .flatten()
            .map(|p| p.as_dvec3())
            .collect();
        let (olo, ohi) = crate::geometry::bounds(points.iter().copied());
        let apart = olo.cmpgt(hi).any() || ohi.cmplt(lo).any();
        if apart && !in_view(&scene.camera, olo, ohi) {
            out.get_or_insert_with(|| scene.clone()).objects[k].enabled = false;
            notes.push(format!(
                "virtual object '{}': outside the room and out of view, it can change nothing (no rays, no form factors)",
                object.name
            ));
        }
    }
    (out, notes)
}

/// Whether any part of the box (lo, hi) may be in the camera's view: false
/// only when all its corners lie beyond one side of the view.
fn in_view(camera: &crate::camera::Camera, lo: DVec3, hi: DVec3) -> bool {
    let corners = crate::geometry::box_corners(lo, hi);
    let Some(p) = camera.project_hull(&corners) else {
        // Some corner at or behind the camera: in view unless all are.
        return corners.iter().any(|c| camera.project(*c).is_some());
    };
    let (w, h) = (camera.width as f64, camera.height as f64);
    !(p.iter().all(|q| q.0 < 0.0)
        || p.iter().all(|q| q.0 > w)
        || p.iter().all(|q| q.1 < 0.0)
        || p.iter().all(|q| q.1 > h))
}

/// [`render`] of a scene whose objects may all change something.
fn render_reachable(
    scene: &Scene,
    photo: &Image,
    settings: &RenderSettings,
    times: &mut StageTimes,
) -> Result<RenderOutput> {
    let n = photo.pixels.len();
    if !scene.changes_the_photo() {
        let composite = Composite::unchanged(photo);
        let left_out = vec!["everything: the scene shows the photo's state (no virtual object, lights as photographed)".to_string()];
        return Ok(RenderOutput {
            composite,
            warnings: crate::inputs::input_warnings(photo, None),
            left_out,
            pda_bytes: 0,
            pda_pixels: n,
            rays: 0,
            patches: 0,
            links: 0,
            elements: 0,
            links_bytes: 0,
            room_solution_bytes: 0,
            change_bytes: 0,
            patch_size: 0.0,
            texture: None,
            residual: None,
        });
    }
    Ok(Session::begin(scene, photo, settings, times, false, None)?.into_output())
}

/// A render kept alive for updates: after virtual objects move,
/// [`Session::update`] recomputes only what their old and new places can change.
pub struct Session {
    /// The room as prepared for the photo: what every pose reads.
    prepared: Prepared,
    /// The current pose: the lights' scales, the objects' change, the pixel data.
    pose: Pose,
    /// How the render runs, and what it did.
    run: Run,
    pub composite: Composite,
}

/// A session's room and inputs, prepared once (a relight changes the scales they record).
struct Prepared {
    /// The scene as rendered (a light to reconstruct replaced by what was recovered).
    scene: Scene,
    /// The lights as the caller gave them: updates must keep them.
    given_lights: Vec<crate::scene::Light>,
    /// The photo as the stages read it: lamps in view filled from around them.
    photo: Image,
    /// The photo with its grain smoothed out, where a light is added or
    /// scaled up (see [`crate::composite::grain`]).
    photo_base: Option<Image>,
    /// The lamps in view, and the photo as shot (when there are any).
    lamps: Option<(LampPixels, Image)>,
    /// What is likely wrong with the inputs ([`crate::inputs::input_warnings`]).
    warnings: Vec<String>,
    settings: RenderSettings,
    tracer: crate::trace::Tracer,
    model: Model,
    scales_without: Vec<f64>,
    indirect_without: Vec<DVec3>,
    /// The objects' meshes in their own frames, kept for the next pose.
    meshes: crate::patches::ObjectMeshes,
}

/// A session's current pose and light scales, and what updates keep of it.
struct Pose {
    scales_with: Vec<f64>,
    active: Vec<bool>,
    changes: Changes,
    bounds: VirtualBounds,
    pda: PixelDataArray,
    /// Built for the first update only: a still render does not need it.
    blocks: Option<crate::blocks::BlockHierarchy>,
    /// Each real pixel's composite as prepared (see [`RealPixels`]), kept for updates.
    known: Option<RealPixels>,
    /// The room without the objects at the lights' new scales, kept for every pose.
    room: Solution,
    /// The room's solution per light, once the session's lights are scaled
    /// (see [`Session::relight`]).
    room_per_light: Option<Vec<Option<Solution>>>,
    /// The objects' gather directions, for the next pose.
    gather_directions: GatherDirections,
    /// Per light, the pixels the traversals (an update's, or the
    /// preparation's) reached against the objects where they left them: the
    /// next update's old bounds (empty for a light switched off).
    reached: Vec<pixels::Reached>,
    /// Per light, the blocks' shafts the traversals built so far.
    block_shafts: Vec<crate::blocks::BlockShafts>,
    /// The objects' shaded samples, for the next update.
    shaded: crate::object_shading::kept::KeptShading,
    /// The last composite's shadow edges, for a relight.
    edges: KeptEdges,
}

impl Pose {
    /// The pose a session's first render leaves: no pixel data or blocks yet.
    fn first(
        scales_with: Vec<f64>,
        active: Vec<bool>,
        changes: Changes,
        bounds: VirtualBounds,
        room: Solution,
        gather_directions: GatherDirections,
    ) -> Pose {
        Pose {
            scales_with,
            active,
            changes,
            bounds,
            pda: PixelDataArray::default(),
            blocks: None,
            known: None,
            room,
            room_per_light: None,
            gather_directions,
            reached: Vec::new(),
            block_shafts: Vec::new(),
            shaded: Default::default(),
            edges: KeptEdges::default(),
        }
    }
}

/// How a session renders (band, layers, budget) and its tallies.
struct Run {
    left_out: Vec<String>,
    rays: u64,
    /// Kept for updates (see [`Session::start`]), or a still image.
    for_updates: bool,
    /// The rows of a still rendered band by band (see [`render_bands`]).
    band: Option<(u32, u32)>,
    /// Pixels whose centre sees a real surface, over the bands so far.
    covered: usize,
    /// Which layers composites fill (see [`Session::keep_layers`]).
    layers: crate::composite::Layers,
    /// When the render (or the update) began: a time budget counts from it.
    started: std::time::Instant,
    /// What the last composite's rounds of per-pixel samples did.
    residual_stats: Option<crate::residual::ResidualStats>,
    /// The share of the time left that a composite's rounds may take (a
    /// still's first band: one over the bands).
    time_share: f64,
}

impl Prepared {
    /// What the objects' change reads of the room, at `scales_with` with
    /// the objects within `bounds`, over the room's solution `room`.
    fn change_input<'a>(
        &'a self,
        scales_with: &'a [f64],
        bounds: &'a VirtualBounds,
        room: &'a Solution,
    ) -> ChangeInput<'a> {
        ChangeInput {
            scene: &self.scene,
            photo: &self.photo,
            tracer: &self.tracer,
            model: &self.model,
            scales_with,
            settings: &self.settings,
            bounds,
            room,
        }
    }
}

/// The patches a pose's composite reads: the room's and its objects', or
/// the room's alone without objects.
fn own_or_room<'a>(own: &'a Option<Patches>, model: &'a Model) -> &'a Patches {
    own.as_ref().unwrap_or(&model.patches)
}

/// Bytes a [`Session`] holds for updates.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SessionMemory {
    pub pixel_data: usize,
    /// The pixel-block hierarchy with the shafts kept so far (0 until built).
    pub pixel_blocks: usize,
    /// The room's radiosity without the objects, kept for every pose.
    pub room_solution: usize,
    /// The objects' change to it: what the room sees of them and ΔB.
    pub change: usize,
}

/// Bytes of a solution's radiosity and irradiance.
fn solution_bytes(s: &Solution) -> usize {
    (s.radiosity.len() + s.indirect_irradiance.len()) * std::mem::size_of::<DVec3>()
}

/// What an update did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UpdateStats {
    /// Real pixels whose light terms were recomputed (for some light).
    pub pixels_recomputed: usize,
    /// Pixels re-traced for the objects' own image and edges.
    pub pixels_retraced: u64,
    pub shaft_tests: u64,
    pub rays: u64,
    /// Bundles of rays towards objects that stood still kept from the last
    /// pose rather than traced again (what the room's patches and the
    /// points near the objects see of them).
    pub bundles_kept: u64,
    /// Still objects' vertices whose gather was summed again over kept
    /// rays; and those that traced again only the rays a moved object may cross.
    pub gathers_kept: usize,
    pub gathers_partly_kept: usize,
    /// Still objects' shaded points read again over kept samples.
    pub shaded_kept: usize,
    /// Blocks skipped by one shaft test, per light: (level, x, y).
    pub skipped_blocks: Vec<Vec<(u8, u32, u32)>>,
}

impl Session {
    /// A full render of `scene` over `photo`, kept for updates.
    pub fn start(
        scene: &Scene,
        photo: &Image,
        settings: &RenderSettings,
        times: &mut StageTimes,
    ) -> Result<Session> {
        Session::begin(scene, photo, settings, times, true, None)
    }

    /// A full render; `for_updates`: keep what updates need and a still does not.
    fn begin(
        scene: &Scene,
        photo: &Image,
        settings: &RenderSettings,
        times: &mut StageTimes,
        for_updates: bool,
        band: Option<(u32, u32)>,
    ) -> Result<Session> {
        let started = std::time::Instant::now();
        let mut left_out = Vec::new();
        let mut settings = RenderSettings {
            model: ModelSettings {
                patch_size: room_patch_size(scene, settings.patch_size),
                ..settings.model
            },
            ..*settings
        };
        let tracer = times.time("tracer", || crate::scene_tracer::build_tracer(scene))?;
        let given_lights = scene.lights.clone();
        let (resolved, photo) =
            resolve_inputs(scene, photo, &tracer, &settings.model, times, &mut left_out)?;
        let scene = resolved.as_ref().unwrap_or(scene);
        let (photo, lamps) = lamps_in_view(scene, photo, &tracer, settings.pda.supersample, times)?;
        if lamps.is_none() {
            left_out.push("lamps in view: no rect light is seen".to_string());
        }
        let model = photo_model(scene, &photo, &tracer, &mut settings, times)?;
        let scales_without: Vec<f64> = model.lights.iter().map(|l| l.photo_scale()).collect();
        let scales_with: Vec<f64> = model.lights.iter().map(|l| l.scale).collect();
        let indirect_without = model
            .patches
            .vertex_values(&model.estimate.solution.indirect_irradiance);
        let brightens = (scales_with.iter().zip(&scales_without)).any(|(w, wo)| w > wo);
        let photo_base = brightens.then(|| {
            let lamps = lamps.as_ref().map(|l| &l.0);
            times.time("photo grain", || photo_without_grain(&photo, lamps))
        });
        if !brightens {
            left_out.push("the photo's grain: no light is added or scaled up".to_string());
        }
        if tracer.virtual_objects.is_none() {
            left_out.push("virtual geometry and new form factors: no virtual object (the room's transport is reused)".to_string());
            left_out.push(
                "rays against virtual geometry and edge supersampling: no virtual object"
                    .to_string(),
            );
        }
        let has_objects = tracer.virtual_objects.is_some();
        let room = room_solution(&model, &scales_with, &settings, times);
        let bounds = VirtualBounds::of(&scene.virtual_world_surfaces())
            .with_room(&model.patches.real_root_polygons(), &model.lights);
        let mut meshes = ObjectMeshes::new(for_updates).coarse_from(settings.coarse_objects_from);
        let objects = object_patches(
            (scene, &model.patches, &mut meshes),
            has_objects,
            &settings,
            times,
        );
        let mut gather_directions = GatherDirections::new(for_updates);
        let input = ChangeInput {
            scene,
            photo: &photo,
            tracer: &tracer,
            model: &model,
            scales_with: &scales_with,
            settings: &settings,
            bounds: &bounds,
            room: &room,
        };
        let mut rays = PoseRays::default();
        let changes = solve_changes(
            &input,
            objects.as_ref(),
            &mut gather_directions,
            &mut rays.view,
            times,
        )
        .with_patches(objects, rays);
        let mut warnings = crate::inputs::input_warnings(&photo, Some(&model.estimate));
        warnings.extend(times.time("placement checks", || {
            crate::placement::warnings(scene, &photo, &tracer)
        }));
        let active = scales_with
            .iter()
            .zip(&scales_without)
            .map(|(a, b)| *a > 0.0 || *b > 0.0)
            .collect();
        let mut session = Session {
            prepared: Prepared {
                scene: scene.clone(),
                given_lights,
                photo,
                photo_base,
                lamps,
                warnings,
                settings,
                tracer,
                model,
                scales_without,
                indirect_without,
                meshes,
            },
            pose: Pose::first(
                scales_with,
                active,
                changes,
                bounds,
                room,
                gather_directions,
            ),
            run: Run {
                left_out,
                rays: 0,
                for_updates,
                band,
                covered: 0,
                layers: crate::composite::Layers::All,
                started,
                residual_stats: None,
                // The first band's share of the frame's rows.
                time_share: band.map_or(1.0, |(a, b)| {
                    ((b - a) as f64 / scene.camera.height.max(1) as f64).min(1.0)
                }),
            },
            composite: Composite::empty(),
        };
        session.trace_pixels(times);
        session.recomposite(times, &[]);
        Ok(session)
    }

    /// Builds the Pixel Data Array for the session's pixels (its crop's,
    /// and its band's when rendered by bands).
    fn trace_pixels(&mut self, times: &mut StageTimes) {
        let patches = own_or_room(&self.pose.changes.own, &self.prepared.model);
        let shaded = crate::object_shading::ObjectMaterials::surface_ids(&self.prepared.scene);
        let input = PdaInput {
            camera: &self.prepared.scene.camera,
            tracer: &self.prepared.tracer,
            patches,
            lights: &self.prepared.model.lights,
            active: &self.pose.active,
            bounds: &self.pose.bounds,
            settings: self.prepared.settings.pda,
            for_updates: self.run.for_updates,
            band: self.run.band,
            shaded_per_pixel: &shaded,
        };
        self.pose.pda = times.time("pixel data array", || PixelDataArray::build(&input));
        // The grid near the objects covers the patches these pixels see.
        self.pose.changes.rays.near = None;
        self.run.rays += self.pose.pda.rays;
        // Its own pixels (the crop's, within the band), not the margin.
        self.run.covered += self.pose.pda.covered(self.pose.pda.own);
    }

    /// The pixels of the image: its crop's, or the frame's.
    fn image_pixels(&self) -> crate::image_io::PixelRect {
        let cam = &self.prepared.scene.camera;
        let (w, h) = (cam.width, cam.height);
        (self.prepared.settings.pda.crop)
            .and_then(|c| c.pixels(w, h))
            .unwrap_or(crate::image_io::PixelRect::full(w, h))
    }

    /// From the next update on, composites hold the image and alpha only
    /// (the direct, indirect and change layers are left empty): what a
    /// motion writes, a tenth to a fifth less work in each update's composite.
    pub fn image_only(&mut self) {
        self.keep_layers(crate::composite::Layers::None);
    }

    /// From the next composite on, which layers it fills beside the image
    /// and alpha ([`crate::composite::Layers`]).
    pub fn keep_layers(&mut self, layers: crate::composite::Layers) {
        self.run.layers = layers;
    }

    /// Builds the pixel-block hierarchy updates traverse, and traverses it
    /// against the objects where they stand (done by the first update when
    /// not asked for before).
    pub fn prepare_updates(&mut self, times: &mut StageTimes) {
        if self.pose.blocks.is_none() {
            let (pda, lights, active, bounds) = (
                &self.pose.pda,
                &self.prepared.model.lights,
                &self.pose.active,
                &self.pose.bounds,
            );
            let (blocks, (reached, shafts)) = times.time("pixel blocks", || {
                use rayon::prelude::*;
                let blocks = crate::blocks::BlockHierarchy::build(pda);
                // The pixels the objects reach where they stand: the first update's old bounds.
                let reached = lights
                    .par_iter()
                    .zip(active)
                    .map(|(light, &on)| match on {
                        true => pixels::Reached::prepared(&blocks, light, bounds),
                        false => Default::default(),
                    })
                    .unzip();
                (blocks, reached)
            });
            self.pose.blocks = Some(blocks);
            self.pose.reached = reached;
            self.pose.block_shafts = shafts;
        }
    }

    /// Bytes held by what the session keeps for updates.
    pub fn memory_bytes(&self) -> SessionMemory {
        let shafts: usize = self
            .pose
            .block_shafts
            .iter()
            .map(|s| s.memory_bytes())
            .sum();
        SessionMemory {
            pixel_data: self.pose.pda.memory_bytes(),
            pixel_blocks: (self.pose.blocks.as_ref()).map_or(0, |b| b.memory_bytes() + shafts),
            room_solution: solution_bytes(&self.pose.room),
            change: self.pose.changes.bytes
                + (self.pose.changes.rays.near.as_ref()).map_or(0, |n| n.memory_bytes())
                + (self.pose.changes.per_light.as_ref()).map_or(0, |b| b.memory_bytes()),
        }
    }

    pub fn pda(&self) -> &PixelDataArray {
        &self.pose.pda
    }

    pub fn blocks(&self) -> Option<&crate::blocks::BlockHierarchy> {
        self.pose.blocks.as_ref()
    }

    /// Moves to `scene`, which must differ from the current one only in
    /// where virtual objects are (a motion's next pose): the objects' old and
    /// new bounds are traced through the pixel-block hierarchy and only the
    /// pixels whose shaft to a light may meet them are recomputed; the
    /// objects' image and edges are re-traced; the indirect light is solved
    /// again on the room's links with the objects re-linked.
    pub fn update(&mut self, scene: &Scene, times: &mut StageTimes) -> Result<UpdateStats> {
        let same_lights = scene.lights == self.prepared.given_lights;
        if !same_lights
            || scene.camera != self.prepared.scene.camera
            || scene.surfaces.len() != self.prepared.scene.surfaces.len()
        {
            return Err(crate::error::Error::file(
                &scene.file,
                "an update moves virtual objects only; lights, camera and real geometry must stay",
            ));
        }
        self.run.started = std::time::Instant::now();
        self.prepare_updates(times);
        let mut stats = UpdateStats::default();
        let virt = scene.virtual_world_surfaces();
        let world = crate::scene_tracer::world_triangle_sets(scene, &virt);
        let placed = crate::scene_tracer::object_instances(scene);
        // The tracer's objects, their bounds and their mesh, side by side.
        let has_objects = virt.iter().any(|(_, t)| !t.is_empty());
        let (tracer, model, settings, meshes) = (
            &mut self.prepared.tracer,
            &self.prepared.model,
            &self.prepared.settings,
            &mut self.prepared.meshes,
        );
        let (moved, (bounds, objects)) = times.concurrently(
            "place objects",
            |times| times.time("move objects", || tracer.place_objects(&world, &placed)),
            |times| {
                let bounds = VirtualBounds::of(&virt)
                    .with_room(&model.patches.real_root_polygons(), &model.lights);
                (
                    bounds,
                    object_patches(
                        (scene, &model.patches, meshes),
                        has_objects,
                        settings,
                        times,
                    ),
                )
            },
        );
        moved.map_err(|e| crate::error::Error::file(&scene.file, e.to_string()))?;
        // What the last pose's rays towards the objects that stood still may give.
        let unmoved = room::unmoved_surfaces(&self.prepared.scene, scene);
        let last_rays = std::mem::take(&mut self.pose.changes.rays);
        let still = match (&self.pose.changes.own, &objects) {
            (Some(old), Some(new)) => Some(crate::radiosity::StillSurfaces::between(
                (&self.pose.bounds, old),
                (&bounds, new),
                &unmoved,
            )),
            _ => None,
        };
        // Only the objects move (checked above): the room's surfaces, and the
        // lights as rendered (a reconstructed one stays recovered), are kept.
        self.prepared.scene.objects.clone_from(&scene.objects);
        self.pose.bounds = bounds;
        // The Pixel Data Array does not depend on the radiosity solution:
        // the two are computed side by side, and beside them the rays of the
        // grid near the objects (geometry only; at the points of the pixels
        // that show no object once the pixels are updated).
        let input =
            self.prepared
                .change_input(&self.pose.scales_with, &self.pose.bounds, &self.pose.room);
        let mut pixels = PixelUpdate {
            pda: &mut self.pose.pda,
            blocks: self.pose.blocks.as_ref().expect("prepared above"),
            active: &self.pose.active,
            reached: &mut self.pose.reached,
            block_shafts: &mut self.pose.block_shafts,
            stats: &mut stats,
            movers: still.as_ref().map(|s| s as &dyn crate::objects::Movers),
        };
        let directions = &mut self.pose.gather_directions;
        let objects_ref = objects.as_ref();
        let mut rays = PoseRays::default();
        let view = &mut rays.view;
        let still = still.as_ref();
        directions.since = still.cloned(); // gathers no mover comes near: summed again
        if let Some(s) = still {
            self.pose.shaded.since(Box::new(s.clone()));
        }
        let (solved, ((touched, pixel_rays, retraced), near)) = times.concurrently(
            "radiosity | pixels",
            |times| {
                if let (Some(o), Some(last), Some(still)) = (objects_ref, &last_rays.view, still) {
                    *view = Some(times.time("objects seen from the room", || {
                        changes::view_keeping(&input, o, (last, still))
                    }));
                }
                solve_changes(&input, objects_ref, directions, view, times)
            },
            |times| {
                let out = pixels.run(&input, objects_ref, times);
                let last = last_rays.near.as_ref().zip(still);
                let near = objects_ref.map(|o| {
                    times.time("rays near the objects", || {
                        let read = changes::read_points(&input, pixels.pda);
                        changes::near_rays(&input, o, &read, last)
                    })
                });
                (out, near)
            },
        );
        rays.near = near;
        stats.bundles_kept = (rays.view.iter().map(|v| v.kept))
            .chain(rays.near.iter().map(|v| v.kept))
            .sum();
        let g = &mut self.pose.gather_directions;
        (stats.gathers_kept, stats.gathers_partly_kept, g.since) = (g.reused, g.partly, None);
        self.pose.changes = solved.with_patches(objects, rays);
        stats.rays += pixel_rays;
        stats.pixels_retraced = retraced;
        self.run.rays = stats.rays;
        self.recomposite(times, &touched);
        stats.shaded_kept = self.pose.shaded.kept;
        Ok(stats)
    }

    pub(crate) fn into_output(self) -> RenderOutput {
        let pixels = self.image_pixels().pixel_count();
        let mut warnings = self.prepared.warnings;
        warnings.extend(coverage_warning(self.run.covered, pixels));
        let patches = own_or_room(&self.pose.changes.own, &self.prepared.model);
        let transport = &self.prepared.model.transport;
        RenderOutput {
            pda_bytes: self.pose.pda.memory_bytes(),
            pda_pixels: (self.pose.pda.width * self.pose.pda.height) as usize,
            rays: self.run.rays,
            patches: patches.patch_count(),
            links: transport.link_count(),
            elements: patches.elements.len(),
            links_bytes: transport.memory_bytes(),
            room_solution_bytes: solution_bytes(&self.pose.room),
            change_bytes: self.pose.changes.bytes,
            patch_size: self.prepared.settings.model.patch_size,
            composite: self.composite,
            warnings,
            left_out: self.run.left_out,
            texture: None,
            residual: self.run.residual_stats,
        }
    }
}

mod bands;
mod changes;
mod final_gather;
mod light_scales;
mod pixels;
mod recompose;
mod room;

pub use bands::{
    BYTES_PER_BAND_PIXEL, BYTES_PER_FRAME_PIXEL, BandSink, band_rows, default_memory, parse_memory,
    render_bands,
};
pub use light_scales::Relight;
pub(crate) use room::lights_change;

use changes::*;
use final_gather::*;
use pixels::*;
use recompose::KeptEdges;
use room::*;

#[cfg(test)]
mod tests;
