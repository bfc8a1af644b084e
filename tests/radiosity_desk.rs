//! Radiosity and estimation on `scenes/desk`: hierarchical against the
//! full-matrix oracle, and a known reflectance recovered without being told.

mod common;
use common::desk;

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec3;

use arlux::estimate::{EstimateSettings, PhotoPatches, estimate_reflectances, surface_mean};
use arlux::light::LightSource;

fn photo_scales(lights: &[LightSource]) -> Vec<f64> {
    lights.iter().map(|l| l.photo_scale()).collect()
}
use arlux::patches::{ObjectMeshes, Patches};
use arlux::radiosity::{DEFAULT_LINK_EPSILON, Transport, direct_irradiance, solve, total_direct};
use arlux::scene::Scene;
use arlux::trace::{Layer, TraceRay};

/// The desk's room at 0.5 m patches, with the photo's direct light per patch.
fn desk_at_half_a_metre() -> (Scene, arlux::trace::Tracer, Patches, Vec<DVec3>) {
    let scene = desk();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let lights = LightSource::all(&scene).unwrap();
    let patches = Patches::of_scene(&scene, false, 0.5);
    let e = total_direct(
        patches.patch_count(),
        &photo_scales(&lights),
        &direct_irradiance(&patches, &lights, &tracer, Layer::Real, 4),
    );
    (scene, tracer, patches, e)
}

#[test]
fn hierarchical_agrees_with_the_full_matrix_within_one_percent_per_patch() {
    let (scene, tracer, patches, e) = desk_at_half_a_metre();
    let photo = scene.load_photo().unwrap();
    let measured = PhotoPatches::measure(&scene.camera, &tracer, &patches, &photo);
    let t0 = Instant::now();
    let full = Transport::full(&patches, &tracer, Layer::Real);
    let full_time = t0.elapsed();
    let t0 = Instant::now();
    let hier = Transport::hierarchical(&patches, &tracer, Layer::Real, DEFAULT_LINK_EPSILON);
    let hier_time = t0.elapsed();
    let known: HashMap<u32, DVec3> = scene
        .reflectances
        .iter()
        .map(|k| (k.surface as u32, k.rgb))
        .collect();
    let est = estimate_reflectances(
        &patches,
        &full,
        &e,
        &measured,
        &known,
        EstimateSettings::default(),
    );
    let rho = &est.reflectance;
    let emission: Vec<DVec3> = rho.iter().zip(&e).map(|(r, e)| *r * *e).collect();
    let a = solve(&patches, &full, rho, &emission, 1e-9, 500);
    let b = solve(&patches, &hier, rho, &emission, 1e-9, 500);
    let worst = a
        .radiosity
        .iter()
        .zip(&b.radiosity)
        .map(|(x, y)| ((*x - *y).abs() / x.max(DVec3::splat(1e-6))).max_element())
        .fold(0.0, f64::max);
    println!(
        "desk at 0.5 m: {} patches; full {} form factors in {full_time:.2?}; hierarchical {} links in {hier_time:.2?}; worst per-patch difference {:.3}%",
        patches.patch_count(),
        full.link_count(),
        hier.link_count(),
        100.0 * worst
    );
    assert!(
        worst < 0.01,
        "hierarchical differs by {:.2}%",
        100.0 * worst
    );
}

#[test]
fn the_left_wall_reflectance_is_recovered_without_its_known_value() {
    let mut scene = desk();
    let truth = scene.reflectances[0].clone();
    scene.reflectances.clear();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let lights = LightSource::all(&scene).unwrap();
    let patches = Patches::of_scene(&scene, false, 0.25);
    let e = total_direct(
        patches.patch_count(),
        &photo_scales(&lights),
        &direct_irradiance(&patches, &lights, &tracer, Layer::Real, 6),
    );
    let photo = scene.load_photo().unwrap();
    let measured = PhotoPatches::measure(&scene.camera, &tracer, &patches, &photo);
    let t0 = Instant::now();
    let transport = Transport::hierarchical(&patches, &tracer, Layer::Real, DEFAULT_LINK_EPSILON);
    let est = estimate_reflectances(
        &patches,
        &transport,
        &e,
        &measured,
        &HashMap::new(),
        EstimateSettings::default(),
    );
    let got = surface_mean(&patches, &est.reflectance, truth.surface as u32).unwrap();
    let error = ((got - truth.rgb) / truth.rgb).abs().max_element();
    println!(
        "left wall estimated {got:.4} vs true {:.4}: worst channel off by {:.2}% ({} iterations, {} clamped, {} unseen, {:.2?})",
        truth.rgb,
        100.0 * error,
        est.iterations,
        est.clamped,
        est.unseen,
        t0.elapsed()
    );
    assert!(error < 0.05);
    assert!(
        est.reflectance
            .iter()
            .all(|r| r.is_finite() && r.min_element() >= 0.0 && r.max_element() <= 0.99)
    );
}

#[test]
fn direct_light_with_objects_reuses_the_room_only_where_it_is_the_same() {
    // The room's values are taken wherever a patch's shaft to a light
    // misses the objects, and an object's patch that only its own solid
    // can shadow traces no ray: the result must equal tracing every patch.
    for variant in ["box_floor_a", "box_table"] {
        let scene = desk().with_variant(variant).unwrap();
        let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
        let lights = LightSource::all(&scene).unwrap();
        let room = Patches::of_scene(&scene, false, 0.5);
        let with = Patches::of_scene_with(&scene, true, 0.5, 0.1);
        let room_direct = direct_irradiance(&room, &lights, &tracer, Layer::Real, 4);
        let objects = arlux::pda::VirtualBounds::of(&scene.virtual_world_surfaces())
            .with_room(&room.real_root_polygons(), &lights);
        let input = arlux::radiosity::DirectWithObjects {
            patches: &with,
            lights: &lights,
            tracer: &tracer,
            level: 4,
            room: &room_direct,
            objects: &objects,
        };
        let fast = arlux::radiosity::direct_irradiance_with_objects(&input, None);
        let known = (room.patch_count()..with.patch_count())
            .filter(|&k| {
                (0..lights.len()).any(|l| {
                    objects.only_own_blocks(
                        with.patch(k).surface,
                        with.patch(k).centre,
                        with.patch(k).normal,
                        l,
                        &lights[l],
                    )
                })
            })
            .count();
        println!(
            "{variant}: {known} of the object's {} patches know their rays",
            with.patch_count() - room.patch_count()
        );
        assert!(known > 0, "{variant}: every object patch traced");
        let traced = direct_irradiance(&with, &lights, &tracer, Layer::All, 4);
        assert_eq!(fast, traced, "{variant}");
        // And the objects do darken some room patch, so the test has teeth.
        let darkened = (0..room.patch_count())
            .filter(|&k| (0..lights.len()).any(|l| traced[l][k] != room_direct[l][k]))
            .count();
        println!(
            "{variant}: {darkened} of {} room patches shadowed by the object",
            room.patch_count()
        );
        assert!(
            darkened > 0,
            "{variant}: no room patch in the object's shadow"
        );
    }
}

#[test]
fn what_each_patch_gathers_agrees_with_tracing_its_hemisphere() {
    // An independent estimate of the transport: from 6×6 points of each
    // patch, 32×32 cosine-distributed rays, each taking the radiosity of the
    // patch whose front it meets (the same radiosities for both). Both the
    // full matrix and the hierarchy estimate visibility with a few rays
    // between elements; on average a patch's gathered irradiance must stay
    // within 2% of the traced one (the tracing's own noise is ~0.5%).
    let (_, tracer, patches, e) = desk_at_half_a_metre();
    let full = Transport::full(&patches, &tracer, Layer::Real);
    let hier = Transport::hierarchical(&patches, &tracer, Layer::Real, DEFAULT_LINK_EPSILON);
    let rho = vec![DVec3::splat(0.6); patches.patch_count()];
    let emission: Vec<DVec3> = rho.iter().zip(&e).map(|(r, e)| *r * *e).collect();
    let b = solve(&patches, &full, &rho, &emission, 1e-9, 500).radiosity;
    let (from_full, from_hier) = (full.gather_rgb(&patches, &b), hier.gather_rgb(&patches, &b));
    let (mut full_error, mut hier_error, mut count) = (0.0, 0.0, 0);
    for k in 0..patches.patch_count() {
        let el = patches.patch(k);
        let mut sum = 0.0;
        let mut rays = 0;
        for (i, (x, _)) in el.shape.quadrature(6).into_iter().enumerate() {
            let dirs = arlux::gather::cosine_directions(
                el.normal,
                32,
                arlux::util::rng::hash2(k as u64, i as u64),
            );
            let origin = arlux::light::offset_origin(x, el.normal, x + el.normal);
            let traced: Vec<TraceRay> = dirs
                .iter()
                .map(|d| TraceRay::new(origin.as_vec3(), d.as_vec3()))
                .collect();
            let mut hits = vec![None; traced.len()];
            tracer.intersect_batch(&traced, Layer::Real, &mut hits);
            for (d, hit) in dirs.iter().zip(&hits) {
                rays += 1;
                let Some(hit) = hit else { continue };
                let Some(at) =
                    patches.locate(hit.surface, hit.triangle, origin + *d * hit.t as f64)
                else {
                    continue;
                };
                let q = patches.patch(at.patch as usize);
                if !(q.one_sided && d.dot(q.normal) >= 0.0) {
                    sum += b[at.patch as usize].x;
                }
            }
        }
        let traced = sum / rays as f64;
        if traced > 0.0 {
            full_error += ((from_full[k].x - traced) / traced).abs();
            hier_error += ((from_hier[k].x - traced) / traced).abs();
            count += 1;
        }
    }
    let (full_error, hier_error) = (full_error / count as f64, hier_error / count as f64);
    println!(
        "gathered irradiance against tracing, mean over {count} patches: full matrix {:.2}%, hierarchical {:.2}%",
        100.0 * full_error,
        100.0 * hier_error
    );
    assert!(full_error < 0.02 && hier_error < 0.02);
}

#[test]
fn the_objects_mesh_from_the_rooms_is_the_whole_scenes_mesh() {
    // An update copies the room's mesh and adds the moved objects' to it:
    // the same elements, vertices and numbering as meshing everything anew.
    let base = desk();
    for (variant, size) in [("box_floor_a", 1.0), ("box_table", 0.25)] {
        let scene = base.with_variant(variant).unwrap();
        let room = Patches::of_scene(&scene, false, size);
        let whole = Patches::of_scene_with(&scene, true, size, 0.1);
        let from_room =
            Patches::of_scene_from_room(&room, &scene, 0.1, &mut ObjectMeshes::new(false));
        assert!(
            whole.patch_count() > room.patch_count(),
            "{variant}: the object adds patches"
        );
        assert!(from_room == whole, "{variant}: the meshes differ");
        // A session's kept meshes, made at another pose, give the same mesh.
        let mut kept = ObjectMeshes::new(true);
        let other = base.with_motion_pose("box_slide", 2).unwrap();
        Patches::of_scene_from_room(&room, &other, 0.1, &mut kept);
        let moved = Patches::of_scene_from_room(&room, &scene, 0.1, &mut kept);
        assert!(moved == whole, "{variant}: the kept meshes moved differ");
    }
}

#[test]
fn a_moved_solid_keeps_its_mesh() {
    // Its corners are single precision: moved, a face's two triangles stop
    // forming an exact parallelogram (the box at the slide's second pose
    // was meshed as triangles, twice the patches). Every pose must mesh
    // the box as the first does.
    let base = desk();
    let room = Patches::of_scene(&base.with_motion_pose("box_slide", 0).unwrap(), false, 1.0);
    let poses = base.motion("box_slide").unwrap().translations.len();
    let meshes: Vec<(usize, usize)> = (0..poses)
        .map(|pose| {
            let p = Patches::of_scene_from_room(
                &room,
                &base.with_motion_pose("box_slide", pose).unwrap(),
                0.1,
                &mut ObjectMeshes::new(false),
            );
            (
                p.patch_count() - room.patch_count(),
                p.vertices.len() - room.vertices.len(),
            )
        })
        .collect();
    assert!(
        meshes.iter().all(|m| *m == meshes[0]),
        "patches and vertices per pose: {meshes:?}"
    );
    assert_eq!(
        meshes[0].0, 96,
        "a 0.3 m box at 0.1 m: 6 faces of 4 × 4 patches"
    );
}

#[test]
fn gathering_rays_from_a_solids_faces_meet_through_the_room_alone_what_they_meet_through_both_layers()
 {
    // The final gather traces the room alone from a vertex whose whole
    // solid lies behind its face (`gather::clear_of_solid`): it must find
    // every ray's hit as tracing both layers does.
    use arlux::gather::{clear_of_solid, cosine_directions};
    use arlux::light::offset_origin;
    for variant in ["box_floor_a", "box_table"] {
        let scene = desk().with_variant(variant).unwrap();
        let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
        let with = Patches::of_scene_with(&scene, true, 0.5, 0.1);
        let is_virtual = |s: u32| with.is_virtual_surface(s);
        let corners: Vec<DVec3> = with
            .roots
            .iter()
            .map(|&r| &with.elements[r as usize])
            .filter(|e| is_virtual(e.surface))
            .flat_map(|e| e.shape.corners().to_vec())
            .collect();
        let trace = |p: DVec3, n: DVec3, layer: Layer| {
            let origin = offset_origin(p, n, p + n);
            let rays: Vec<TraceRay> = cosine_directions(n, 12, 7)
                .iter()
                .map(|d| TraceRay::new(origin.as_vec3(), d.as_vec3()))
                .collect();
            let mut hits = vec![None; rays.len()];
            tracer.intersect_batch(&rays, layer, &mut hits);
            hits
        };
        let mut vertices = 0;
        for k in (0..with.patch_count()).filter(|&k| is_virtual(with.patch(k).surface)) {
            let n = with.patch(k).normal;
            for &v in with.patch_vertices[k].iter().filter(|&&v| v != u32::MAX) {
                let p = with.vertices[v as usize];
                // A box: every face has the whole box behind it.
                assert!(
                    clear_of_solid(&corners, p, n),
                    "{variant}: vertex {v} not clear of its own box"
                );
                assert_eq!(
                    trace(p, n, Layer::Real),
                    trace(p, n, Layer::All),
                    "{variant}: vertex {v}"
                );
                vertices += 1;
            }
        }
        assert!(vertices > 50, "{variant}: {vertices} vertices");
        // Facing into the box instead, the rule refuses, and rightly: the box is in the way.
        let k = (0..with.patch_count())
            .find(|&k| is_virtual(with.patch(k).surface))
            .unwrap();
        let (p, n) = (with.patch(k).centre, -with.patch(k).normal);
        assert!(
            !clear_of_solid(&corners, p, n),
            "{variant}: clear facing into the box"
        );
        assert!(
            trace(p, n, Layer::All)
                .iter()
                .flatten()
                .any(|h| h.is_virtual),
            "{variant}: no ray into the box met it"
        );
    }
}

#[test]
fn links_per_element_grow_slowly_as_the_room_is_meshed_finer() {
    // Hierarchical radiosity links each receiver to the sources at the
    // level its oracle asks for, not to every patch: meshed 4× finer, the
    // links per element may grow only by the few extra levels the oracle
    // now reaches (a full matrix's grow 4×).
    let scene = desk();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let per_element = |size: f64| {
        let patches = Patches::of_scene(&scene, false, size);
        let hier = Transport::hierarchical(&patches, &tracer, Layer::Real, DEFAULT_LINK_EPSILON);
        let ratio = hier.link_count() as f64 / patches.elements.len() as f64;
        println!(
            "{size} m: {} elements, {} links, {ratio:.1} per element",
            patches.elements.len(),
            hier.link_count()
        );
        ratio
    };
    let (coarse, fine) = (per_element(0.25), per_element(0.125));
    assert!(fine < 150.0, "{fine:.1} links per element at 0.125 m");
    assert!(
        fine < 1.3 * coarse,
        "links per element {coarse:.1} → {fine:.1} when meshed 4× finer"
    );
}

#[test]
fn an_object_walking_and_turning_keeps_its_patches() {
    // The objects are meshed in their own frame and moved: the stool (2k
    // triangles) has the same patches at every pose of its walk, turned
    // too, as rigid copies (meshed in the world, rounding moved a few).
    let base = common::load("lounge", "scene.toml");
    let room = Patches::of_scene(&base, false, 1.0);
    let poses = base.motion("stool_walk").unwrap().translations.len();
    let mut kept = ObjectMeshes::new(true);
    let shapes: Vec<(usize, usize, f64)> = (0..poses)
        .flat_map(|pose| [0.0f64, 37.0].map(move |deg| (pose, deg)))
        .map(|(pose, deg)| {
            let mut scene = base.with_motion_pose("stool_walk", pose).unwrap();
            let stool = scene
                .objects
                .iter_mut()
                .find(|o| o.name == "stool")
                .unwrap();
            stool.pose.rotation =
                glam::DMat3::from_rotation_y(deg.to_radians()) * stool.pose.rotation;
            let p = Patches::of_scene_from_room(&room, &scene, 0.1, &mut kept);
            let fresh =
                Patches::of_scene_from_room(&room, &scene, 0.1, &mut ObjectMeshes::new(false));
            assert!(
                p == fresh,
                "pose {pose}, {deg}°: kept and fresh meshes differ"
            );
            // The distance between the first two vertices of each patch: a
            // rigid move keeps it.
            let spans: f64 = (room.patch_count()..p.patch_count())
                .map(|k| {
                    let ids = p.patch_vertices[k];
                    (p.vertices[ids[0] as usize] - p.vertices[ids[1] as usize]).length()
                })
                .sum();
            (
                p.patch_count() - room.patch_count(),
                p.vertices.len() - room.vertices.len(),
                spans,
            )
        })
        .collect();
    for s in &shapes {
        assert_eq!(
            (s.0, s.1),
            (shapes[0].0, shapes[0].1),
            "patches, vertices: {shapes:?}"
        );
        assert!(
            (s.2 - shapes[0].2).abs() < 1e-9 * shapes[0].2,
            "edge lengths: {shapes:?}"
        );
    }
}

/// The desk at `box_floor_a`: its tracer, the room's patches at 0.5 m,
/// and the room's with the box's at 0.1 m after them.
fn desk_with_box() -> (Scene, arlux::trace::Tracer, Patches, Patches) {
    let scene = desk().with_variant("box_floor_a").unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let room = Patches::of_scene(&scene, false, 0.5);
    let with = Patches::of_scene_from_room(&room, &scene, 0.1, &mut ObjectMeshes::new(false));
    (scene, tracer, room, with)
}

/// The texture path's objects gather their light by rays in groups
/// ([`arlux::radiosity::GatherRows`]): a leaf's row is the fraction of its
/// rays meeting each element, so the light a side of the box gathers from
/// the floor alone (radiosity 1 there, 0 elsewhere) is its form factor to
/// the floor, and nothing reaches the box from its own faces (convex).
#[test]
fn objects_gathering_by_rays_see_the_room_s_form_factors() {
    use arlux::radiosity::{GatherRows, GatherRowsSettings};
    let (_, tracer, room, with) = desk_with_box();
    let links = Transport::hierarchical(&room, &tracer, arlux::trace::Layer::Real, 0.02);
    let settings = GatherRowsSettings {
        rays: 4096,
        within: 0.025,
    };
    let groups = GatherRows::groups_of(&with, settings.within);
    let rows = GatherRows::trace(&with, &tracer, &groups, settings.rays);
    assert!(rows.group_count() > 0 && rows.rays == rows.group_count() as u64 * 4096);
    let transport = links.with_gather_rows(rows);
    let (n, m) = (with.patch_count(), room.patch_count());
    let element = |k: usize| &with.elements[with.patches[k] as usize];
    let gather = |lit: &dyn Fn(usize) -> bool| {
        let b: Vec<f64> = (0..n).map(|k| f64::from(u8::from(lit(k)))).collect();
        let mut h = vec![0.0; n];
        transport.gather(&with, &b, &mut h);
        h
    };
    let from_floor = gather(&|k| k < m && element(k).centre.y < 0.01);
    let from_itself = gather(&|k| k >= m);
    let floor_polygons: Vec<Vec<DVec3>> = (room.roots.iter())
        .map(|&r| &room.elements[r as usize])
        .filter(|e| e.centre.y < 0.01 && e.normal.y > 0.9)
        .map(|e| e.shape.corners().to_vec())
        .collect();
    let mut sides = 0;
    for k in m..n {
        assert_eq!(from_itself[k], 0.0, "patch {k} sees its own box");
        let e = element(k);
        if e.normal.y.abs() > 0.1 {
            continue;
        }
        // A side of the box: its view of the floor, unoccluded.
        let expected: f64 = (floor_polygons.iter())
            .map(|p| arlux::light::polygon_form_factor_sided(e.centre, e.normal, p, false))
            .sum();
        assert!(
            (from_floor[k] - expected).abs() < 0.02,
            "patch {k}: {} against {expected}",
            from_floor[k]
        );
        sides += 1;
    }
    assert!(sides > 8, "{sides} side patches checked");
}

/// The room's rows ([`arlux::radiosity::GatherRows::of_view`]): a ray from
/// a room patch that meets an object reads the object's radiosity less the
/// room's behind it. With every patch at radiosity 1 a box as bright as the
/// room changes only what a patch sees of it where the room behind it is
/// open (the camera's side: nothing there to hide), and never darkens; a
/// black box takes from a patch what it hides, between nothing and the
/// box's share of its view.
#[test]
fn the_room_s_rows_change_nothing_where_the_objects_look_like_the_room() {
    use arlux::radiosity::{GatherRows, ObjectView};
    let (scene, tracer, room, with) = desk_with_box();
    let (n, m) = (with.patch_count(), room.patch_count());
    let bounds = arlux::objects::VirtualBounds::of(&scene.virtual_world_surfaces());
    let view = ObjectView::trace(&with, m, &tracer, &bounds);
    let rows = GatherRows::of_view(&with, &view);
    let seeing = rows.group_count();
    assert!(seeing > m / 4, "{seeing} of {m} patches see the box");
    let links = Transport::hierarchical(&room, &tracer, arlux::trace::Layer::Real, 0.02);
    let with_rows = links.clone().with_gather_rows(rows);
    let gather = |t: &Transport, lit: &dyn Fn(usize) -> bool| {
        let b: Vec<f64> = (0..n).map(|k| f64::from(u8::from(lit(k)))).collect();
        let mut h = vec![0.0; n];
        t.gather(&with, &b, &mut h);
        h
    };
    let (base, bright, black) = (
        gather(&links, &|k| k < m),
        gather(&with_rows, &|_| true),
        gather(&with_rows, &|k| k < m),
    );
    let (mut unchanged, mut darkened) = (0, 0);
    for k in 0..m {
        let gained = bright[k] - base[k];
        let lost = base[k] - black[k];
        assert!(
            gained > -1e-6,
            "patch {k}: a box as bright as the room darkens it by {gained}"
        );
        assert!(
            lost > -1e-6 && lost < 0.5,
            "patch {k} loses {lost} to a black box"
        );
        unchanged += usize::from(gained.abs() < 1e-6);
        darkened += usize::from(lost > 1e-4);
    }
    assert!(unchanged >= m - seeing / 2, "{unchanged} of {m} unchanged");
    assert!(
        darkened > 10,
        "{darkened} patches lose light to a black box"
    );
}

/// One pass over the links and rows gathers the three channels as three
/// single-channel gathers do, bit for bit (the solves gather RGB at once).
#[test]
fn an_rgb_gather_equals_three_single_channel_gathers_bit_for_bit() {
    use arlux::radiosity::GatherRows;
    let (_, tracer, room, with) = desk_with_box();
    let rows = GatherRows::trace(&with, &tracer, &GatherRows::groups_of(&with, 0.025), 256);
    let links = Transport::hierarchical(&room, &tracer, arlux::trace::Layer::Real, 0.02);
    let transport = links.with_gather_rows(rows);
    let n = with.patch_count();
    // Uneven radiosities, one channel negative (a GMRES vector may be).
    let b: Vec<DVec3> = (0..n)
        .map(|k| {
            let x = (k as f64 * 0.618_033_988_7).fract();
            DVec3::new(x, 1.0 - x * x, -0.3 * x)
        })
        .collect();
    let rgb = transport.gather_rgb(&with, &b);
    for c in 0..3 {
        let channel: Vec<f64> = b.iter().map(|v| v[c]).collect();
        let mut h = vec![0.0; n];
        transport.gather(&with, &channel, &mut h);
        assert!(
            h.iter().any(|h| h.abs() > 1e-3),
            "channel {c} gathers light"
        );
        for (k, (one, three)) in h.iter().zip(&rgb).enumerate() {
            assert_eq!(one.to_bits(), three[c].to_bits(), "patch {k}, channel {c}");
        }
    }
}
