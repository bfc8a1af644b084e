//! A finely tessellated object takes its patches on a coarse mesh of its
//! shape (`patches::proxy`): the desk's box, each of its 12 triangles split
//! into 1,600 (19,200 in all, 7 mm across), is the same box, so the
//! desk's truths hold for it.

mod common;

use std::sync::Arc;

use arlux::compare::skill;
use arlux::render::RenderSettings;
use glam::{DVec3, Vec3};

type Triangle = [Vec3; 3];

/// Each triangle split into `n`² by a grid of its edges' `n`ths, wound as it.
fn split(triangles: &[Triangle], n: usize) -> Vec<Triangle> {
    let mut out = Vec::with_capacity(triangles.len() * n * n);
    for [a, b, c] in triangles {
        let at = |i: usize, j: usize| {
            *a + (*b - *a) * (i as f32 / n as f32) + (*c - *a) * (j as f32 / n as f32)
        };
        for i in 0..n {
            for j in 0..n - i {
                out.push([at(i, j), at(i + 1, j), at(i, j + 1)]);
                if i + j + 1 < n {
                    out.push([at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
    }
    out
}

fn render(scene: &arlux::scene::Scene, settings: &RenderSettings) -> arlux::render::RenderOutput {
    let photo = scene.load_photo().unwrap();
    let out = arlux::render::render(scene, &photo, settings, &mut Default::default()).unwrap();
    common::assert_layers_sound(&scene.name, &out.composite);
    out
}

#[test]
fn a_finely_split_box_meshed_coarse_renders_as_the_plain_box_against_the_truth() {
    let base = common::desk();
    let mut dense = base.clone();
    let surface = &mut dense.objects[0].surfaces[0];
    let fine = split(&surface.triangles, 40);
    assert_eq!(fine.len(), 19_200);
    let area = |ts: &[Triangle]| -> f64 {
        ts.iter()
            .map(|[a, b, c]| 0.5 * (*b - *a).cross(*c - *a).length() as f64)
            .sum()
    };
    assert!((area(&fine) - area(&surface.triangles)).abs() < 1e-4);
    surface.triangles = Arc::from(fine);
    let defaults = RenderSettings::default();
    // Measured: plain 0.940 / 0.935; split, coarse 0.939 / 0.946 (a patch
    // per pair of triangles: 0.944 on box_floor_a).
    for (variant, bound) in [("box_floor_a", 0.935), ("box_floor_b", 0.928)] {
        let plain = render(&base.with_variant(variant).unwrap(), &defaults);
        let coarse = render(&dense.with_variant(variant).unwrap(), &defaults);
        let truth = common::image("desk", &format!("truth/{variant}.exr"));
        let photo = base.load_photo().unwrap();
        let s = |out: &arlux::render::RenderOutput| {
            skill(&out.composite.image, &truth, &photo).skill.unwrap()
        };
        let (plain_skill, coarse_skill) = (s(&plain), s(&coarse));
        assert!(
            coarse_skill >= bound && coarse_skill >= plain_skill - 0.005,
            "{variant}: skill {coarse_skill:.4} split and coarse, {plain_skill:.4} plain"
        );
    }
    // A patch per pair of triangles (the split's pairs join into quads):
    // 10,060 patches with the room's; coarse, 1,767.
    let scene = dense.with_variant("box_floor_a").unwrap();
    let fine = RenderSettings {
        coarse_objects_from: None,
        ..defaults
    };
    let (coarse, fine) = (render(&scene, &defaults), render(&scene, &fine));
    assert!(
        5 * coarse.patches < fine.patches,
        "{} patches coarse, {} a patch per triangle",
        coarse.patches,
        fine.patches
    ); // A real asset's triangles are spread over its materials: the box as
    // six surfaces of 3,200 triangles, each under the threshold, is meshed
    // coarse as its object is over it.
    let mut six = scene.clone();
    let box_surface = six.objects[0].surfaces[0].clone();
    six.objects[0].surfaces = (box_surface.triangles.chunks(3_200))
        .enumerate()
        .map(|(i, part)| arlux::scene::ObjectSurface {
            name: format!("face_{i}"),
            triangles: Arc::from(part),
            ..box_surface.clone()
        })
        .collect();
    assert_eq!(six.objects[0].surfaces.len(), 6);
    let six = render(&six, &defaults);
    assert!(
        5 * six.patches < fine.patches,
        "{} patches on six surfaces, {} a patch per triangle",
        six.patches,
        fine.patches
    );
}

/// A coarse object's update equals a full render of its pose bit for bit,
/// as every object's does (`tests/update_desk.rs`), and its render is the
/// same on one thread as on three.
#[test]
fn a_coarse_object_updates_as_it_renders() {
    let mut scene = common::desk();
    let surface = &mut scene.objects[0].surfaces[0];
    surface.triangles = Arc::from(split(&surface.triangles, 30));
    let photo = scene.load_photo().unwrap();
    let settings = RenderSettings::default();
    let one = common::image_on_threads(&scene, &photo, &settings, 1);
    let three = common::image_on_threads(&scene, &photo, &settings, 3);
    assert_eq!(common::differing(&one, &three), 0);
    let mut session =
        arlux::render::Session::start(&scene, &photo, &settings, &mut Default::default()).unwrap();
    for step in [DVec3::new(-0.3, 0.0, 0.2), DVec3::new(0.1, 0.0, -0.4)] {
        let mut moved = scene.clone();
        moved.objects[0].pose.translate += step;
        session.update(&moved, &mut Default::default()).unwrap();
        let full = render(&moved, &settings).composite;
        assert_eq!(common::differing(&session.composite.image, &full.image), 0);
        assert_eq!(
            common::differing(&session.composite.direct, &full.direct),
            0
        );
    }
}

/// The texture path meshes the split box coarse too, and renders it as the
/// plain box (measured: skill 0.863 against 0.862; 3,530 leaves against
/// 2,085).
#[test]
fn the_texture_path_renders_the_split_box_as_the_plain_one() {
    use arlux::relight::{TextureSettings, render_texture};
    let base = common::desk().with_variant("box_floor_a").unwrap();
    let mut dense = base.clone();
    let surface = &mut dense.objects[0].surfaces[0];
    surface.triangles = Arc::from(split(&surface.triangles, 40));
    let photo = base.load_photo().unwrap();
    let truth = common::image("desk", "truth/box_floor_a.exr");
    let settings = TextureSettings::default();
    let s = |scene: &arlux::scene::Scene| {
        let out = render_texture(scene, &photo, &settings, &mut Default::default()).unwrap();
        (
            skill(&out.composite.image, &truth, &photo).skill.unwrap(),
            out.patches,
        )
    };
    let ((plain, plain_leaves), (coarse, leaves)) = (s(&base), s(&dense));
    assert!(
        (coarse - plain).abs() < 0.01,
        "skill {coarse:.4} split and coarse, {plain:.4} plain"
    );
    // A leaf per pair of the split's triangles would be 9,600 more.
    assert!(
        leaves < plain_leaves + 2_000,
        "{leaves} leaves with the split box, {plain_leaves} with the plain one"
    );
}

/// A session's light sliders with a coarse object: each relit image is a
/// full render's of the new scales within 1e-5 relative, as with any
/// object (`tests/light_sliders.rs`).
#[test]
fn a_session_relights_a_coarse_object_as_a_render_does() {
    let mut base = common::desk().with_variant("box_floor_a").unwrap();
    let surface = &mut base.objects[0].surfaces[0];
    surface.triangles = Arc::from(split(&surface.triangles, 30));
    // Started with the lights changed, so that the room is meshed for them.
    base.lights[1].scale = 2.0;
    let photo = base.load_photo().unwrap();
    let settings = RenderSettings::default();
    let mut session =
        arlux::render::Session::start(&base, &photo, &settings, &mut Default::default()).unwrap();
    for (panel, spot) in [(0.5, 2.0), (0.0, 1.0)] {
        let mut scene = base.clone();
        scene.lights[0].scale = panel;
        scene.lights[1].scale = spot;
        session.relight(&scene, &mut Default::default()).unwrap();
        let full = render(&scene, &settings).composite;
        for (layer, a, b) in [
            ("image", &session.composite.image, &full.image),
            ("direct", &session.composite.direct, &full.direct),
        ] {
            let d = common::relative_difference(a, b);
            assert!(d <= 1e-5, "{layer} differs by {d:.2e} at ({panel}, {spot})");
        }
    }
}
