//! What the virtual objects change in the room's radiosity: the room
//! solved once without them and kept, and the objects as a change ΔB to
//! it, computed from the objects alone (see [`crate::radiosity::ObjectView`]):
//! the direct light they block, the room's light they hide and the light
//! they reflect, as seen from the room's patches; its bounces through the
//! room's own links; the objects' own light gathered from the photo.

use super::*;

/// The radiosity of the augmented scene.
pub(super) struct Changes {
    /// The room's patches and then the objects' (None: no object, the room's are used).
    pub(super) own: Option<Patches>,
    pub(super) reflectance: Vec<DVec3>,
    pub(super) indirect_with: Vec<DVec3>,
    /// What the objects' change near them is computed from (None: no object).
    pub(super) near: Option<NearSource>,
    /// Bytes of the change: the rays' record of what the room sees of the
    /// objects and the change's solution.
    pub(super) bytes: usize,
    /// The pose's rays, which depend on geometry only: kept for a relight
    /// of the same pose (see [`super::Session::relight`]).
    pub(super) rays: PoseRays,
    /// The change of each light alone, once the pose has been relit.
    pub(super) per_light: Option<super::light_scales::ChangeBasis>,
}

/// What a pose's rays found, whatever the radiosity they are read with.
#[derive(Default)]
pub(super) struct PoseRays {
    /// From the room's patches towards the objects.
    pub(super) view: Option<crate::radiosity::ObjectView>,
    /// From the points near the objects that the camera sees.
    pub(super) near: Option<crate::radiosity::NearView>,
}

/// Final gathering's directions per virtual vertex (its number, normal
/// and strata per side): they depend on nothing else, so a moved object's
/// vertices, numbered and facing as before, reuse them (computing them
/// took about a tenth of the gather).
/// A still render keeps none (`kept` false): each gathering vertex makes
/// its own as it gathers (an 80k-triangle object's kept directions were
/// ~70 MB).
/// A session also keeps what each gathering vertex's rays met
/// (`traced`): a vertex of an object that stood still, whose rays no moved
/// object comes near (`since`: what moved since they were traced), sums
/// them again over the new radiosity instead of tracing them (beside a
/// still 2 m object, its gathers were most of a moving stool's).
#[derive(Debug, Default)]
pub(super) struct GatherDirections {
    pub(super) of: crate::util::FastMap<(u32, [u64; 3], u32), Vec<DVec3>>,
    pub(super) kept: bool,
    pub(super) traced: crate::util::FastMap<(u32, [u64; 3], u32), super::final_gather::Traced>,
    /// What moved since `traced` was traced (None: trace every vertex).
    pub(super) since: Option<crate::radiosity::StillSurfaces>,
    /// How many vertices the last gather summed again without tracing, and
    /// how many traced again only the rays a moved object may cross.
    pub(super) reused: usize,
    pub(super) partly: usize,
    /// The lights on and their direct light per patch, for the next pose.
    pub(super) direct: Option<(Vec<usize>, Vec<Vec<DVec3>>)>,
}

impl GatherDirections {
    /// `kept`: keep each vertex's directions for the next pose.
    pub(super) fn new(kept: bool) -> GatherDirections {
        GatherDirections {
            kept,
            ..GatherDirections::default()
        }
    }

    pub(super) fn key(v: u32, n: DVec3, side: u32) -> (u32, [u64; 3], u32) {
        (v, n.to_array().map(f64::to_bits), side)
    }

    /// Makes the directions of `vertices` (vertex, normal, side) that are
    /// missing. Others are kept for later poses (a face turning to or from
    /// the camera changes its vertices' side back when it turns back), up to
    /// four sets per vertex: an object that turns gives new normals every
    /// pose, and those are dropped then.
    pub(super) fn keep(&mut self, vertices: &[(u32, DVec3, u32)]) {
        use rayon::prelude::*;
        if self.of.len() > 4 * vertices.len() {
            self.of.clear();
        }
        let missing: Vec<_> = vertices
            .iter()
            .filter(|&&(v, n, side)| !self.of.contains_key(&GatherDirections::key(v, n, side)))
            .collect();
        let made: Vec<_> = missing
            .into_par_iter()
            .map(|&(v, n, side)| (GatherDirections::key(v, n, side), Self::make(v, n, side)))
            .collect();
        self.of.extend(made);
    }

    /// The directions vertex `v` gathers along, with `side`² strata about `n`.
    fn make(v: u32, n: DVec3, side: u32) -> Vec<DVec3> {
        crate::gather::cosine_directions(n, side, crate::util::rng::hash2(v as u64, 0x6A7E))
    }

    /// Vertex `v`'s directions: the kept ones, else made now.
    pub(super) fn of(&self, v: u32, n: DVec3, side: u32) -> std::borrow::Cow<'_, [DVec3]> {
        match self.kept {
            true => std::borrow::Cow::Borrowed(&self.of[&GatherDirections::key(v, n, side)]),
            false => std::borrow::Cow::Owned(Self::make(v, n, side)),
        }
    }
}

/// The room's patches and then the virtual objects' (None: no object),
/// the objects' meshes taken from and kept in `meshes`.
pub(super) fn object_patches(
    (scene, room, meshes): (&Scene, &Patches, &mut crate::patches::ObjectMeshes),
    has_objects: bool,
    settings: &RenderSettings,
    times: &mut StageTimes,
) -> Option<Patches> {
    has_objects.then(|| {
        times.time("virtual mesh", || {
            Patches::of_scene_from_room(room, scene, settings.virtual_patch_size, meshes)
        })
    })
}

/// [`Changes`] but for the objects' patches, which the caller keeps while
/// it is solved (an update builds the Pixel Data Array's virtual part on
/// them meanwhile).
#[derive(Clone)]
pub(super) struct Solved {
    pub(super) reflectance: Vec<DVec3>,
    pub(super) indirect_with: Vec<DVec3>,
    pub(super) near: Option<NearSource>,
    pub(super) bytes: usize,
}

/// What [`near_field`] reads of a pose's change: the radiosity of the room
/// and the objects, and the patch means' change to the room's indirect
/// light as vertex values.
#[derive(Clone)]
pub(super) struct NearSource {
    pub(super) radiosity: Vec<DVec3>,
    pub(super) coarse: Vec<DVec3>,
}

/// The objects' change near them, finer than the room's patches
/// ([`crate::radiosity::NearField`]), traced where the pixel data's plain
/// real points read it (see [`read_points`]): an update pays for what the
/// camera sees near the objects.
/// `kept`: the pose's rays from an earlier composite (traced and kept when None).
pub(super) fn near_field(
    input: &ChangeInput,
    objects: &Patches,
    source: &NearSource,
    pda: &crate::pda::PixelDataArray,
    kept: &mut Option<crate::radiosity::NearView>,
) -> crate::radiosity::NearField {
    let view =
        kept.get_or_insert_with(|| near_rays(input, objects, &read_points(input, pda), None));
    view.field(
        objects,
        &source.radiosity,
        &input.room.radiosity,
        &source.coarse,
    )
}

/// The real points at which a composite of `pda` reads the near field, by
/// room patch: those of the pixels that show no object (a pixel that does
/// reads the object's light; see [`crate::composite`]'s near pass), on the
/// patches near the objects (no other holds a grid).
pub(super) fn read_points(
    input: &ChangeInput,
    pda: &crate::pda::PixelDataArray,
) -> crate::radiosity::ReadPoints {
    let patches = &input.model.patches;
    let room_count = patches.patch_count();
    let near = crate::radiosity::NearView::patches_near(patches, room_count, input.bounds);
    let by_patch = pda.real_by_patch();
    let shown = || {
        (0..room_count).filter(|&k| near[k]).flat_map(move |k| {
            (by_patch.of(k).iter())
                .filter(|&&(i, _)| {
                    pda.virtual_index
                        .get(i as usize)
                        .is_none_or(|&v| v == u32::MAX)
                })
                .map(move |&(_, p)| (k as u32, pda.real.points[p as usize].position))
        })
    };
    crate::radiosity::ReadPoints::of(room_count, shown)
}

/// The rays of the grid near the objects at the room points `read`
/// (geometry only: any radiosity reads them).
pub(super) fn near_rays(
    input: &ChangeInput,
    objects: &Patches,
    read: &crate::radiosity::ReadPoints,
    last: Option<(
        &crate::radiosity::NearView,
        &crate::radiosity::StillSurfaces,
    )>,
) -> crate::radiosity::NearView {
    let cell = input.settings.virtual_patch_size;
    let bounds = (input.bounds, cell);
    crate::radiosity::NearView::trace_keeping(objects, read, input.tracer, bounds, last)
}

/// What the room's patches see of the objects, keeping the last pose's
/// bundles towards the objects that stood still where nothing moved
/// between (see [`crate::radiosity::StillSurfaces`]).
pub(super) fn view_keeping(
    input: &ChangeInput,
    objects: &Patches,
    last: (
        &crate::radiosity::ObjectView,
        &crate::radiosity::StillSurfaces,
    ),
) -> crate::radiosity::ObjectView {
    let room_count = input.model.patches.patch_count();
    crate::radiosity::ObjectView::trace_keeping(
        objects,
        room_count,
        input.tracer,
        input.bounds,
        Some(last),
    )
}

impl Solved {
    /// The change of a pose as `rays` found it, with its patches.
    pub(super) fn with_patches(self, patches: Option<Patches>, rays: PoseRays) -> Changes {
        Changes {
            own: patches,
            reflectance: self.reflectance,
            indirect_with: self.indirect_with,
            near: self.near,
            bytes: self.bytes,
            rays,
            per_light: None,
        }
    }
}

/// What the radiosity with changes reads besides the objects' patches.
pub(super) struct ChangeInput<'a> {
    pub(super) scene: &'a Scene,
    pub(super) photo: &'a Image,
    pub(super) tracer: &'a crate::trace::Tracer,
    pub(super) model: &'a Model,
    pub(super) scales_with: &'a [f64],
    pub(super) settings: &'a RenderSettings,
    pub(super) bounds: &'a VirtualBounds,
    /// The room without the objects, solved at the new scales ([`room_solution`]).
    pub(super) room: &'a Solution,
}

/// The room without the virtual objects, at the lights' new scales: solved
/// once per room and light set, from the photo's model, and kept.
pub(super) fn room_solution(
    model: &Model,
    scales_with: &[f64],
    settings: &RenderSettings,
    times: &mut StageTimes,
) -> Solution {
    times.time("solve the room", || {
        let e = total_direct(
            model.patches.patch_count(),
            scales_with,
            &model.direct_per_light,
        );
        let reflectance = &model.estimate.reflectance;
        let b: Vec<DVec3> = reflectance.iter().zip(&e).map(|(r, e)| *r * *e).collect();
        solve_from(
            &model.patches,
            &model.transport,
            reflectance,
            &b,
            Some(&model.estimate.solution.radiosity),
            settings.model.estimate.solve_tolerance,
            500,
        )
    })
}

/// Radiosity with the changes: the kept room solution (`input.room`), and
/// with virtual objects (`objects`, from [`object_patches`]) the change
/// they make to it, their radiosity, and their own indirect light
/// gathered from the photo.
/// `view`: the pose's rays from the room towards the objects, traced
/// before at the same pose (traced and kept there when None).
pub(super) fn solve_changes(
    input: &ChangeInput,
    objects: Option<&Patches>,
    directions: &mut GatherDirections,
    view: &mut Option<crate::radiosity::ObjectView>,
    times: &mut StageTimes,
) -> Solved {
    let model = input.model;
    let Some(patches) = objects else {
        return Solved {
            reflectance: model.estimate.reflectance.clone(),
            indirect_with: model.patches.vertex_values(&input.room.indirect_irradiance),
            near: None,
            bytes: 0,
        };
    };
    let room_count = model.patches.patch_count();
    // Lights off with the change send nothing for the objects to block.
    let on: Vec<usize> = (0..model.lights.len())
        .filter(|&l| input.scales_with[l] > 0.0)
        .collect();
    // The pose before's values, for the same lights, where nothing moved across.
    let last = (directions.direct.as_ref()).filter(|(lights, _)| *lights == on);
    let kept = directions.since.as_ref().zip(last.map(|(_, d)| &d[..]));
    let lights: Vec<_> = on.iter().map(|&l| model.lights[l].clone()).collect();
    let room: Vec<_> = (on.iter())
        .map(|&l| model.direct_per_light[l].clone())
        .collect();
    let direct = times.time("direct light with objects", || {
        let with = crate::radiosity::DirectWithObjects {
            patches,
            lights: &lights,
            tracer: input.tracer,
            level: input.settings.model.light_level,
            room: &room,
            objects: input.bounds,
        };
        crate::radiosity::direct_irradiance_with_objects(&with, kept)
    });
    if directions.kept {
        directions.direct = Some((on.clone(), direct.clone()));
    }
    let scales_on: Vec<f64> = on.iter().map(|&l| input.scales_with[l]).collect();
    if view.is_none() {
        *view = Some(times.time("objects seen from the room", || {
            crate::radiosity::ObjectView::trace(patches, room_count, input.tracer, input.bounds)
        }));
    }
    let view = view.as_ref().expect("traced above");
    let mut reflectance = model.estimate.reflectance[..room_count].to_vec();
    reflectance.extend(times.time("objects' albedo", || {
        crate::radiosity::object_reflectances(input.scene, patches, room_count)
    }));
    // Objects whose material glows light the room as lamps of their shape.
    let glowing = input.scene.virtual_surface_emission();
    let emission: Vec<DVec3> = (0..patches.patch_count())
        .map(|k| match k < room_count || glowing.is_empty() {
            true => DVec3::ZERO,
            false => glowing
                .get(&patches.patch(k).surface)
                .copied()
                .unwrap_or(DVec3::ZERO),
        })
        .collect();
    let system = ChangeSystem {
        input,
        view,
        direct: total_direct(patches.patch_count(), &scales_on, &direct),
        room_direct: total_direct(room_count, input.scales_with, &model.direct_per_light),
        reflectance: &reflectance,
    };
    // The objects' radiosity from their direct light, the room's as kept.
    let mut radiosity: Vec<DVec3> = (input.room.radiosity.iter().copied())
        .chain(
            (room_count..patches.patch_count())
                .map(|k| reflectance[k] * system.direct[k] + emission[k]),
        )
        .collect();
    // The change without its bounces, ρ·(ΔE + ΔH): what the objects'
    // gather sees of the room they darken, and where the solve starts.
    let first = system.first_order(&radiosity);
    let mut indirect_with = vec![DVec3::ZERO; patches.vertices.len()];
    if input.settings.gather_rays > 0 {
        for (b, (room, d)) in radiosity
            .iter_mut()
            .zip(input.room.radiosity.iter().zip(&first))
        {
            *b = *room + *d;
        }
        let lit = Lit {
            system: &system,
            emission: &emission,
            patches,
        };
        gather_objects(&lit, &radiosity, &mut indirect_with, directions, times);
        for (k, b) in radiosity.iter_mut().enumerate().skip(room_count) {
            let h = corner_mean(patches, k, &indirect_with);
            *b = reflectance[k] * (system.direct[k] + h) + emission[k];
        }
    }
    let (solution, seen) = times.time("solve the change", || {
        system.solve(&radiosity, Some(&first))
    });
    // The room's indirect light: as kept, plus the change's bounces, plus
    // what it sees of the objects in place of what they hide.
    let room: Vec<DVec3> = (input.room.indirect_irradiance.iter())
        .zip(&solution.indirect_irradiance)
        .zip(&seen)
        .map(|((h, bounced), seen)| *h + *bounced + *seen)
        .collect();
    let room_vertices = model.patches.vertices.len();
    indirect_with[..room_vertices].copy_from_slice(&model.patches.vertex_values(&room));
    let coarse = model.patches.vertex_values(&seen);
    let bytes = view.memory_bytes()
        + (solution.radiosity.len() + solution.indirect_irradiance.len() + seen.len())
            * std::mem::size_of::<DVec3>();
    Solved {
        reflectance,
        indirect_with,
        bytes: bytes + (radiosity.len() + coarse.len()) * std::mem::size_of::<DVec3>(),
        near: Some(NearSource { radiosity, coarse }),
    }
}

/// The change the objects make to the room's radiosity, ΔB = ρ·(ΔE + ΔH +
/// T·ΔB): ΔE the direct light they block, ΔH what the room sees of them
/// less what they hide, T the room's own links, unchanged. Solved from
/// zero (or a previous change) to the tolerance relative to the change.
struct ChangeSystem<'a> {
    input: &'a ChangeInput<'a>,
    view: &'a crate::radiosity::ObjectView,
    /// Direct irradiance per patch (the room's and the objects') with the objects.
    direct: Vec<DVec3>,
    /// The room's without them.
    room_direct: Vec<DVec3>,
    reflectance: &'a [DVec3],
}

impl ChangeSystem<'_> {
    /// ΔH, what the room's patches see of the objects less what they hide,
    /// for the objects' radiosity in `radiosity` (per patch of room and
    /// objects), and the change's source term ρ·(ΔE + ΔH).
    fn source(&self, radiosity: &[DVec3]) -> (Vec<DVec3>, Vec<DVec3>) {
        let room_count = self.input.model.patches.patch_count();
        let seen = (self.view).irradiance_change(room_count, radiosity, &self.input.room.radiosity);
        let b = (0..room_count)
            .map(|k| self.reflectance[k] * (self.direct[k] - self.room_direct[k] + seen[k]))
            .collect();
        (seen, b)
    }

    /// The change before it bounces: ρ·(ΔE + ΔH).
    fn first_order(&self, radiosity: &[DVec3]) -> Vec<DVec3> {
        self.source(radiosity).1
    }

    /// ΔB over the room's patches (its bounces hidden by the objects as
    /// the room's light is), and the ΔH it was solved with.
    fn solve(&self, radiosity: &[DVec3], guess: Option<&[DVec3]>) -> (Solution, Vec<DVec3>) {
        let model = self.input.model;
        let (seen, b) = self.source(radiosity);
        let solution = crate::radiosity::solve_change(
            &model.patches,
            &model.transport,
            &self.reflectance[..model.patches.patch_count()],
            &b,
            guess,
            self.view,
            CHANGE_TOLERANCE,
        );
        (solution, seen)
    }
}

/// The relative residual a change's solve stops at: relative to the
/// change, which is itself a small part of the room's light (the room's own
/// solve stops at 1e-7 of B).
const CHANGE_TOLERANCE: f64 = 1e-5;

/// The objects' light: their direct light, emission and patches.
struct Lit<'a> {
    system: &'a ChangeSystem<'a>,
    emission: &'a [DVec3],
    patches: &'a Patches,
}

/// The objects' indirect light gathered from the photo into
/// `indirect_with` (vertex values), with the room's radiosity changed by
/// the light they block in `radiosity_with`, and the bounces between them.
fn gather_objects(
    lit: &Lit,
    radiosity_with: &[DVec3],
    indirect_with: &mut [DVec3],
    directions: &mut GatherDirections,
    times: &mut StageTimes,
) {
    let input = lit.system.input;
    let model = input.model;
    let real_vertices = model.patches.vertices.len();
    let gathered = times.time("final gather on objects", || {
        let gather = Gather {
            camera: &input.scene.camera,
            tracer: input.tracer,
            patches: lit.patches,
            real_vertices,
            photo: input.photo,
            radiosity_with,
            radiosity_without: &model.estimate.solution.radiosity,
            rays: input.settings.gather_rays,
            share_within: input.settings.virtual_patch_size / 4.0,
            bounce_only: &crate::object_shading::ObjectMaterials::metal_ids(input.scene),
        };
        final_gather(&gather, directions)
    });
    times.time("bounces between objects", || {
        object_bounces(lit, model.patches.patch_count(), &gathered, indirect_with)
    });
}

/// The mean of patch `k`'s corner values in a vertex table.
fn corner_mean(patches: &Patches, k: usize, vertex_values: &[DVec3]) -> DVec3 {
    let corners = patches.patch_vertices[k].iter().filter(|&&v| v != u32::MAX);
    let sum: DVec3 = corners.clone().map(|&v| vertex_values[v as usize]).sum();
    sum / corners.count().max(1) as f64
}

/// Light bouncing between the objects: a ray from one object that meets
/// another (or itself: a ball on a seat, a seat under a ball) first
/// gathered that object's radiosity as the first solve left it, its
/// direct light alone (objects have no links). Each round takes the
/// objects' radiosity from what their vertices gathered, ρ·(E + H), and
/// gathers it again along the same rays: no ray is traced again. Rounds
/// stop when no vertex moves by more than 1e-6 of its irradiance (at 1e-4
/// the rounds a light's part took differed from the whole's, and a
/// session's sum of its lights' parts missed a full render by 1.2e-5 on
/// the stool, against the solvers' 1e-5).
fn object_bounces(lit: &Lit, real_count: usize, gathers: &Gathers, indirect: &mut [DVec3]) {
    let (patches, system) = (lit.patches, lit.system);
    for g in &gathers.each {
        indirect[g.vertex as usize] = g.irradiance;
    }
    if gathers.met.iter().all(|m| m.objects.is_empty()) {
        return;
    }
    let mut radiosity = vec![DVec3::ZERO; patches.patch_count()];
    for _ in 0..16 {
        for (k, b) in radiosity.iter_mut().enumerate().skip(real_count) {
            let h = corner_mean(patches, k, indirect);
            *b = system.reflectance[k] * (system.direct[k] + h) + lit.emission[k];
        }
        // What each gathering vertex's rays meet of the objects, once.
        let met: Vec<DVec3> = (gathers.met.iter())
            .map(|m| {
                let objects: DVec3 = m.objects.iter().map(|&k| radiosity[k as usize]).sum();
                objects / m.rays.max(1) as f64
            })
            .collect();
        let mut moved = 0.0f64;
        for g in &gathers.each {
            let h = g.from_room + met[g.objects_of as usize];
            let was = indirect[g.vertex as usize];
            moved = moved.max(((h - was).abs() / was.abs().max(DVec3::splat(1e-12))).max_element());
            indirect[g.vertex as usize] = h;
        }
        if moved < 1e-6 {
            break;
        }
    }
}
