//! The surface seen at each pixel centre of `scenes/desk` against the
//! dataset's independent ray caster (`truth/ids.exr`, channel Y).

mod common;

use arlux::image_io::read_exr_channel;
use arlux::scene::Scene;
use arlux::surface_ids::SurfaceIds;
use arlux::trace::Layer;

fn desk() -> std::path::PathBuf {
    common::scene_dir("desk")
}

#[test]
fn surface_ids_agree_with_the_independent_ray_caster() {
    let scene = Scene::load(desk().join("scene.toml")).unwrap();
    // The numbering is the dataset's: ids.txt lists "index name" per line.
    let listed = std::fs::read_to_string(desk().join("truth/ids.txt")).unwrap();
    for line in listed
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
    {
        let (index, name) = line.split_once(' ').unwrap();
        assert_eq!(
            scene.surfaces[index.parse::<usize>().unwrap()].name,
            name.trim()
        );
    }

    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let ids = SurfaceIds::at_pixel_centres(&scene.camera, &tracer, Layer::Real);
    let (w, h, truth) = read_exr_channel(&desk().join("truth/ids.exr"), "Y").unwrap();
    assert_eq!((w, h), (scene.camera.width, scene.camera.height));
    let agree = ids
        .ids
        .iter()
        .zip(&truth)
        .filter(|(a, t)| **a == t.round() as i32)
        .count();
    let fraction = agree as f64 / truth.len() as f64;
    println!(
        "surface ids agree at {agree} of {} pixels ({:.4}%)",
        truth.len(),
        100.0 * fraction
    );
    assert!(
        fraction >= 0.995,
        "only {:.3}% of pixels agree",
        100.0 * fraction
    );
}
