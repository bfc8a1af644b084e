use super::*;
use crate::camera::Projection;
use crate::light::test_panel;
use crate::trace::SurfaceTriangles;

/// A ceiling (the plane y = 2, 4 m square) seen from below by a 32×32
/// camera at the origin, and the 0.6 m test panel 5 cm under it facing
/// down, in the middle of the view.
fn ceiling_and_panel() -> (Camera, Tracer, LightSource) {
    let c = |x: f32, z: f32| Vec3::new(x, 2.0, z);
    let ceiling = vec![
        [c(-2.0, -2.0), c(2.0, -2.0), c(2.0, 2.0)],
        [c(-2.0, -2.0), c(2.0, 2.0), c(-2.0, 2.0)],
    ];
    let tracer = Tracer::build(
        &[SurfaceTriangles {
            surface: 0,
            triangles: &ceiling,
            mask: None,
        }],
        &[],
    )
    .unwrap();
    let camera = Camera::new(
        32,
        32,
        DVec3::ZERO,
        DVec3::new(0.0, 2.0, 0.0),
        DVec3::Z,
        Projection::FovY { degrees: 60.0 },
    )
    .unwrap();
    let mut panel = test_panel(DVec3::new(0.0, 1.95, 0.0));
    panel.real = true;
    (camera, tracer, panel)
}

/// A photo of the scene: the ceiling at radiance 0.2, the panel's pixels
/// at its radiance times the share of their sub-pixels that see it.
fn photo_of(camera: &Camera, lamps: &LampPixels) -> Image {
    let mut photo = Image::new(camera.width, camera.height);
    photo.pixels.iter_mut().for_each(|p| *p = Vec3::splat(0.2));
    let n = lamps.per_pixel as f32;
    for p in &lamps.pixels {
        let s = lamps.samples_of(p);
        let lamp: Vec3 = s.iter().map(|q| q.emitted).sum::<Vec3>() / n;
        photo.pixels[p.index as usize] = Vec3::splat(0.2) * (1.0 - s.len() as f32 / n) + lamp;
    }
    photo
}

#[test]
fn a_point_in_a_slanted_rectangle_gets_its_parameters() {
    let (u, v) = (DVec3::new(2.0, 0.0, 0.0), DVec3::new(1.0, 1.0, 0.0));
    let c = DVec3::new(1.0, 2.0, 3.0);
    let (a, b) = rect_coordinates(c + u * 0.3 - v * 0.45, c, u, v);
    assert!(
        (a - 0.3).abs() < 1e-12 && (b + 0.45).abs() < 1e-12,
        "{a} {b}"
    );
}

#[test]
fn the_front_of_a_lamp_is_seen_against_its_normal_and_its_back_is_dark() {
    let (_, _, panel) = ceiling_and_panel();
    let (t, front) = meet(&panel, DVec3::ZERO, DVec3::Y).unwrap();
    assert!((t - 1.95).abs() < 1e-12 && front);
    let (_, front) = meet(&panel, DVec3::new(0.0, 3.0, 0.0), DVec3::NEG_Y).unwrap();
    assert!(!front);
    assert!(meet(&panel, DVec3::new(1.0, 0.0, 0.0), DVec3::Y).is_none());
    // Lambertian radiance is the intensity along the normal over the area.
    let l = model_radiance(&panel, DVec3::Y);
    assert!(
        (l - DVec3::splat(4.0 / 0.36)).abs().max_element() < 1e-9,
        "{l}"
    );
}

#[test]
fn a_lamp_out_of_view_costs_nothing() {
    let (camera, tracer, mut panel) = ceiling_and_panel();
    panel.position = DVec3::new(0.0, -1.0, 0.0);
    assert!(LampPixels::find(&camera, &[panel], &tracer, 4).is_none());
}

#[test]
fn a_lamp_follows_its_scale_and_the_photo_stays_where_nothing_changed() {
    let (camera, tracer, panel) = ceiling_and_panel();
    let lamps = LampPixels::find(&camera, &[panel], &tracer, 8).unwrap();
    // The panel spans ±0.3 m at 1.95 m: ±8.7° of the 60° view, ~9 of 32 pixels.
    let whole = lamps
        .pixels
        .iter()
        .filter(|p| p.count == lamps.per_pixel)
        .count();
    assert!((49..=81).contains(&whole), "{whole} whole pixels");
    let photo = photo_of(&camera, &lamps);
    let filled = lamps.photo_without_lamps(&photo);
    assert!(filled.pixels.iter().all(|p| *p == Vec3::splat(0.2)));
    let render = |scale: f64| {
        // The ceiling's change: it keeps its radiance (the composite of the filled photo).
        let mut composite = Composite {
            first_row: 0,
            image: filled.clone(),
            change: Image::new(camera.width, camera.height),
            ..Composite::empty()
        };
        lamps.apply(&mut composite, &photo, &filled, &[scale], &tracer);
        composite.image
    };
    assert_eq!(
        render(1.0).pixels,
        photo.pixels,
        "unchanged: the photo, bit for bit"
    );
    let off = render(0.0);
    let times4 = render(4.0);
    for p in &lamps.pixels {
        let i = p.index as usize;
        let share = p.count as f32 / lamps.per_pixel as f32;
        // Off: the ceiling over what the lamp leaves uncovered, its black body elsewhere.
        assert!((off.pixels[i].x - 0.2 * (1.0 - share)).abs() < 1e-5);
        let lamp = photo.pixels[i].x - 0.2 * (1.0 - share);
        assert!((times4.pixels[i].x - (0.2 * (1.0 - share) + 4.0 * lamp)).abs() < 1e-3);
    }
}

#[test]
fn an_object_in_front_of_a_lamp_hides_it() {
    let (camera, _, panel) = ceiling_and_panel();
    let c = |x: f32, z: f32| Vec3::new(x, 2.0, z);
    let ceiling = vec![
        [c(-2.0, -2.0), c(2.0, -2.0), c(2.0, 2.0)],
        [c(-2.0, -2.0), c(2.0, 2.0), c(-2.0, 2.0)],
    ];
    // A board at 1 m covering the whole view.
    let b = |x: f32, z: f32| Vec3::new(x, 1.0, z);
    let board = vec![
        [b(-2.0, -2.0), b(2.0, -2.0), b(2.0, 2.0)],
        [b(-2.0, -2.0), b(2.0, 2.0), b(-2.0, 2.0)],
    ];
    let tracer = Tracer::build(
        &[SurfaceTriangles {
            surface: 0,
            triangles: &ceiling,
            mask: None,
        }],
        &[SurfaceTriangles {
            surface: 1,
            triangles: &board,
            mask: None,
        }],
    )
    .unwrap();
    let lamps = LampPixels::find(&camera, &[panel], &tracer, 4).unwrap();
    let photo = photo_of(&camera, &lamps);
    let filled = lamps.photo_without_lamps(&photo);
    let shaded = Vec3::splat(0.05);
    let mut composite = Composite {
        first_row: 0,
        image: Image {
            pixels: vec![shaded; photo.pixels.len()],
            ..filled.clone()
        },
        change: Image::new(camera.width, camera.height),
        ..Composite::empty()
    };
    lamps.apply(&mut composite, &photo, &filled, &[1.0], &tracer);
    assert!(composite.image.pixels.iter().all(|p| *p == shaded));
}
