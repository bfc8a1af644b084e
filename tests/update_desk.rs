//! Incremental updates along the desk's `box_slide` motion: each update
//! gives the image a full render of that pose gives.

mod common;
use common::{desk, differing};

use arlux::model::StageTimes;
use arlux::render::{RenderSettings, Session, render};

#[test]
fn every_update_equals_a_full_render_of_its_pose() {
    let base = desk();
    let motion = base.motion("box_slide").unwrap().clone();
    let settings = RenderSettings::default();
    let first = base.with_motion_pose("box_slide", 0).unwrap();
    let photo = first.load_photo().unwrap();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    for pose in 1..motion.translations.len() {
        let scene = base.with_motion_pose("box_slide", pose).unwrap();
        let mut times = StageTimes::default();
        let stats = session.update(&scene, &mut times).unwrap();
        let full = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let d = differing(&session.composite.image, &full.composite.image);
        let direct = differing(&session.composite.direct, &full.composite.direct);
        println!(
            "pose {pose}: {} pixels recomputed, {} re-traced, {} shaft tests, {} rays, {:.1} ms; {d} pixels differ from a full render ({direct} in direct light)",
            stats.pixels_recomputed,
            stats.pixels_retraced,
            stats.shaft_tests,
            stats.rays,
            times.total().as_secs_f64() * 1e3
        );
        for (name, d) in &times.0 {
            println!("    {name:<28} {:>7.1} ms", d.as_secs_f64() * 1e3);
        }
        for (name, d) in &times.1 {
            println!("      | {name:<26} {:>7.1} ms", d.as_secs_f64() * 1e3);
        }
        assert_eq!(
            direct, 0,
            "pose {pose}: direct light must match bit for bit"
        );
        assert_eq!(d, 0, "pose {pose}: the image must match");
    }
}

#[test]
fn moving_an_object_far_from_everything_recomputes_no_pixel_and_casts_no_ray() {
    let base = desk();
    let mut here = base.with_variant("box_floor_a").unwrap();
    // Behind the back wall, then further behind it.
    here.objects[0].pose.translate = glam::DVec3::new(0.0, 0.0, -3.0);
    let mut there = here.clone();
    there.objects[0].pose.translate = glam::DVec3::new(0.5, 0.0, -4.0);
    let photo = here.load_photo().unwrap();
    // With the layers, and the image alone (whose composite reads a
    // pixel's band only where its patch's corners say it may keep the photo).
    for image_only in [false, true] {
        let mut session = Session::start(
            &here,
            &photo,
            &RenderSettings::default(),
            &mut StageTimes::default(),
        )
        .unwrap();
        if image_only {
            session.image_only();
        }
        let stats = session.update(&there, &mut StageTimes::default()).unwrap();
        assert_eq!(
            (stats.pixels_recomputed, stats.pixels_retraced, stats.rays),
            (0, 0, 0),
            "{stats:?}"
        );
        assert!(session.composite.image == photo, "the photo, untouched");
        assert_eq!(session.composite.copied, photo.pixels.len());
    }
}

#[test]
fn updates_equal_full_renders_at_other_ray_budgets() {
    // One shadow ray first and 32 in penumbrae (more than the PDA keeps the
    // room's blockers for: those are traced again), 3×3 edge sub-pixels,
    // and the box passing under the table, where real geometry stands in
    // front of it (every pixel of its image tested for edges).
    let base = desk();
    let mut settings = RenderSettings::default();
    settings.pda.min_level = 0;
    settings.pda.penumbra_level = 5;
    settings.pda.supersample = 3;
    let mut first = base.with_motion_pose("box_slide", 0).unwrap();
    first.objects[0].pose.translate = glam::DVec3::new(-0.6, 0.0, -1.2);
    let photo = first.load_photo().unwrap();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    for at in [
        glam::DVec3::new(-0.35, 0.0, -1.4),
        glam::DVec3::new(-0.1, 0.0, -0.9),
        glam::DVec3::new(-0.35, 0.0, -1.4),
    ] {
        let mut scene = first.clone();
        scene.objects[0].pose.translate = at;
        let stats = session.update(&scene, &mut StageTimes::default()).unwrap();
        assert!(stats.pixels_recomputed > 0 && stats.rays > 0, "{stats:?}");
        let full = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        assert_eq!(
            differing(&session.composite.image, &full.composite.image),
            0,
            "box at {at}: the image must match a full render"
        );
    }
}

#[test]
fn an_image_only_session_updates_the_image_a_full_render_gives_and_drops_the_other_layers() {
    let base = desk();
    let settings = RenderSettings::default();
    let first = base.with_motion_pose("box_slide", 2).unwrap();
    let photo = first.load_photo().unwrap();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    session.image_only();
    let scene = base.with_motion_pose("box_slide", 3).unwrap();
    session.update(&scene, &mut StageTimes::default()).unwrap();
    let full = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
    assert_eq!(
        differing(&session.composite.image, &full.composite.image),
        0
    );
    assert!(session.composite.alpha == full.composite.alpha);
    assert_eq!(
        (session.composite.copied, session.composite.clamped),
        (full.composite.copied, full.composite.clamped)
    );
    assert!(
        session.composite.direct.pixels.is_empty()
            && session.composite.indirect.pixels.is_empty()
            && session.composite.change.pixels.is_empty()
    );
}

/// The box slides past a second box that stands still: the rays towards
/// the still one that nothing moved across are kept from the pose before,
/// and every update still equals a full render of its pose, bit for bit.
#[test]
fn an_object_standing_still_keeps_its_rays_and_updates_equal_full_renders() {
    let desk = common::Desk::new();
    desk.edit(
        "scene.toml",
        "[[variant]]",
        "[[virtual]]\nname = \"crate\"\nmesh = \"geometry/box.obj\"\nrgb = [0.3, 0.5, 0.8]\ntranslate = [-0.2, 0.0, 0.75]\nrotate_y_deg = 10.0\n\n[[variant]]",
    );
    let base = arlux::scene::Scene::load(desk.scene()).unwrap();
    let settings = RenderSettings::default();
    let first = base.with_motion_pose("box_slide", 0).unwrap();
    assert!(first.objects.iter().all(|o| o.enabled), "both boxes shown");
    let photo = first.load_photo().unwrap();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    let poses = base.motion("box_slide").unwrap().translations.len();
    let mut partly = 0;
    let mut recomputed = Vec::new();
    for pose in 1..poses {
        let scene = base.with_motion_pose("box_slide", pose).unwrap();
        let stats = session.update(&scene, &mut StageTimes::default()).unwrap();
        recomputed.push(stats.pixels_recomputed);
        let full = render(&scene, &photo, &settings, &mut StageTimes::default()).unwrap();
        let d = differing(&session.composite.image, &full.composite.image);
        let indirect = differing(&session.composite.indirect, &full.composite.indirect);
        println!(
            "pose {pose}: {} bundles, {} gathers kept, {} in part; {d} pixels differ",
            stats.bundles_kept, stats.gathers_kept, stats.gathers_partly_kept
        );
        assert!(
            stats.bundles_kept > 0 && stats.gathers_kept > 0,
            "pose {pose}: nothing kept of the still box's rays"
        );
        partly += stats.gathers_partly_kept;
        assert_eq!((d, indirect), (0, 0), "pose {pose}: the image must match");
    }
    // Vertices whose rays partly see the moving box keep the others.
    assert!(partly > 0, "no gather kept in part");
    // The real pixels whose light is recomputed are the moving box's alone,
    // as in a room without the crate, once the first update has set the
    // crate's apart.
    let plain = common::Desk::new();
    let base = arlux::scene::Scene::load(plain.scene()).unwrap();
    let first = base.with_motion_pose("box_slide", 0).unwrap();
    let mut session =
        Session::start(&first, &photo, &settings, &mut StageTimes::default()).unwrap();
    let alone: Vec<usize> = (1..poses)
        .map(|pose| {
            let scene = base.with_motion_pose("box_slide", pose).unwrap();
            let stats = session.update(&scene, &mut StageTimes::default()).unwrap();
            stats.pixels_recomputed
        })
        .collect();
    println!("real pixels recomputed: {recomputed:?} beside the crate, {alone:?} alone");
    assert!(
        recomputed[0] > alone[0],
        "the first update sets the crate apart"
    );
    assert_eq!(recomputed[1..], alone[1..]);
}
