//! A white room (every wall ρ = 0.9, light bouncing ten times and more) lit
//! by a 5 cm lamp 4 cm from the wall: `scenes/whitebox`. Stiff for the
//! estimation (the unseen walls feed back on the seen ones with a gain
//! above one) and for the radiosity mesh (an object's change of the
//! indirect light reaches the whole room).

mod common;

use arlux::compare::skill;
use arlux::model::{Model, ModelSettings, StageTimes};

#[test]
fn reflectances_near_one_are_estimated_and_converge() {
    let scene = common::load("whitebox", "scene.toml");
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let mut times = StageTimes::default();
    let (photo, _) =
        arlux::inputs::lamps_in_view(&scene, scene.load_photo().unwrap(), &tracer, 4, &mut times)
            .unwrap();
    let settings = ModelSettings {
        patch_size: 0.25,
        ..ModelSettings::default()
    };
    let model = Model::build(&scene, &photo, &tracer, &settings, &mut times).unwrap();
    let estimate = &model.estimate;
    assert!(
        estimate.iterations < settings.estimate.max_iterations,
        "no convergence: last change {}",
        estimate.change
    );
    // The truth: every wall, the floor and the ceiling 0.9, the table 0.03.
    for (s, surface) in scene.surfaces.iter().enumerate() {
        let (mut sum, mut area) = (0.0, 0.0);
        for k in 0..model.patches.patch_count() {
            let p = model.patches.patch(k);
            if p.surface == s as u32 {
                sum += p.area * estimate.reflectance[k].element_sum() / 3.0;
                area += p.area;
            }
        }
        let (mean, truth) = (
            sum / area,
            if surface.name == "dark_table" {
                0.03
            } else {
                0.9
            },
        );
        // Measured: floor 0.903, ceiling 0.880, back wall 0.908, front wall
        // (behind the camera, mostly unseen) 0.865, right wall 0.903, table
        // 0.034 (0.65-0.75 while the fixed point oscillated).
        assert!(
            (mean - truth).abs() < 0.05 * truth.max(0.1),
            "{}: {mean:.3} against {truth}",
            surface.name
        );
    }
}

#[test]
fn a_cube_inserted_near_the_lamp_darkens_the_white_room() {
    let base = common::load("whitebox", "scene.toml");
    // Measured 0.861, 0.793, 0.706 (0.62-0.79 before, with the room's
    // mesh as coarse as in a grey room and the estimate oscillating).
    for (variant, bound) in [
        ("cube_near", 0.83),
        ("cube_far", 0.75),
        ("cube_close", 0.68),
    ] {
        let (image, truth, photo) = common::rendered(&base, variant);
        let s = skill(&image, &truth, &photo).skill.unwrap();
        assert!(s >= bound, "{variant}: skill {s:.3}");
    }
}
