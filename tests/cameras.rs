//! Cameras solved by other tools: a COLMAP sparse model (text and binary)
//! and an fSpy project written from the desk's known camera give the same
//! rays as the camera written in `scene.toml`, to 1e-4 px.

mod common;

use glam::{DMat3, DQuat, DVec3};

use arlux::camera::Camera;
use arlux::scene::Scene;

const CAMERA: &str = "[camera]
width = 512
height = 384
position = [0.7, 1.45, 2.7]
look_at = [-0.45, 0.6, -1.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 55.0
";

/// The desk with its `[camera]` table replaced by `camera`.
fn desk_with_camera(camera: &str) -> common::Desk {
    let desk = common::Desk::new();
    desk.edit("scene.toml", CAMERA, camera);
    desk
}

fn known() -> Camera {
    Scene::load(common::scene_dir("desk").join("scene.toml"))
        .unwrap()
        .camera
}

/// World to camera as COLMAP keeps it: rows right, down, forward; t = −R c.
fn colmap_pose(c: &Camera) -> (DQuat, DVec3) {
    let r = DMat3::from_cols(c.right, -c.up, c.forward).transpose();
    (DQuat::from_mat3(&r), -(r * c.position))
}

/// Where the rays of `solved` land in `known`'s image: at most `tolerance` px away.
fn same_rays(known: &Camera, solved: &Camera) {
    assert_eq!((known.width, known.height), (solved.width, solved.height));
    for (x, y) in [
        (0.0, 0.0),
        (512.0, 384.0),
        (0.5, 383.5),
        (256.0, 192.0),
        (100.3, 17.9),
        (511.0, 2.0),
    ] {
        let ray = solved.ray(x, y);
        let (u, v, _) = known.project(ray.origin + ray.direction * 3.0).unwrap();
        assert!(
            (u - x).abs() < 1e-4 && (v - y).abs() < 1e-4,
            "({x}, {y}) lands at ({u}, {v})"
        );
    }
}

#[test]
fn a_colmap_text_model_gives_the_scene_s_rays() {
    let c = known();
    let (q, t) = colmap_pose(&c);
    let desk =
        desk_with_camera("[camera]\ncolmap = { dir = \"sparse\", image = \"IMG_0001.JPG\" }\n");
    std::fs::create_dir(desk.path("sparse")).unwrap();
    std::fs::write(
        desk.path("sparse/cameras.txt"),
        format!(
            "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n3 OPENCV_FISHEYE 512 384 300 300 256 192 0.1 0 0 0\n1 PINHOLE 512 384 {:.17} {:.17} {:.17} {:.17}\n",
            c.fx, c.fy, c.cx, c.cy
        ),
    )
    .unwrap();
    std::fs::write(
        desk.path("sparse/images.txt"),
        format!(
            "# Image list with two lines of data per image:\n2 1 0 0 0 0 0 0 3 other.jpg\n\n1 {:.17} {:.17} {:.17} {:.17} {:.17} {:.17} {:.17} 1 IMG_0001.JPG\n10.0 20.0 -1\n",
            q.w, q.x, q.y, q.z, t.x, t.y, t.z
        ),
    )
    .unwrap();
    same_rays(&c, &Scene::load(desk.path("scene.toml")).unwrap().camera);

    // A model whose camera bends rays is refused with what to do.
    desk.edit("scene.toml", "IMG_0001.JPG", "other.jpg");
    let e = Scene::load(desk.path("scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("camera.colmap")
            && e.contains("OPENCV_FISHEYE")
            && e.contains("image_undistorter"),
        "{e}"
    );
}

#[test]
fn a_colmap_binary_model_gives_the_scene_s_rays() {
    let c = known();
    let (q, t) = colmap_pose(&c);
    let desk = desk_with_camera("[camera]\ncolmap = { dir = \"sparse\", image = \"photo.png\" }\n");
    std::fs::create_dir(desk.path("sparse")).unwrap();
    let mut cameras = Vec::new();
    cameras.extend(1u64.to_le_bytes());
    cameras.extend(7i32.to_le_bytes());
    cameras.extend(1i32.to_le_bytes()); // PINHOLE
    cameras.extend(512u64.to_le_bytes());
    cameras.extend(384u64.to_le_bytes());
    for p in [c.fx, c.fy, c.cx, c.cy] {
        cameras.extend(p.to_le_bytes());
    }
    std::fs::write(desk.path("sparse/cameras.bin"), cameras).unwrap();
    let mut images = Vec::new();
    images.extend(1u64.to_le_bytes());
    images.extend(5i32.to_le_bytes());
    for v in [q.w, q.x, q.y, q.z, t.x, t.y, t.z] {
        images.extend(v.to_le_bytes());
    }
    images.extend(7i32.to_le_bytes());
    images.extend(b"photo.png\0");
    images.extend(1u64.to_le_bytes());
    for v in [1.0f64, 2.0] {
        images.extend(v.to_le_bytes());
    }
    images.extend((-1i64).to_le_bytes());
    std::fs::write(desk.path("sparse/images.bin"), &images).unwrap();
    same_rays(&c, &Scene::load(desk.path("scene.toml")).unwrap().camera);

    // Cut short: an error naming the file, not a panic.
    std::fs::write(desk.path("sparse/images.bin"), &images[..40]).unwrap();
    let e = Scene::load(desk.path("scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("images.bin") && e.contains("cut short"), "{e}");
}

#[test]
fn an_fspy_project_gives_the_scene_s_rays() {
    let c = known();
    let (w, h) = (c.width as f64, c.height as f64);
    let half = 0.5 * w.max(h);
    let back = -c.forward;
    let state = serde_json::json!({
        "calibrationSettingsBase": { "referenceDistanceUnit": "Meters" },
        "cameraParameters": {
            "principalPoint": { "x": (c.cx - 0.5 * w) / half, "y": -(c.cy - 0.5 * h) / half },
            "horizontalFieldOfView": 2.0 * (0.5 * w / c.fx).atan(),
            "verticalFieldOfView": 2.0 * (0.5 * h / c.fy).atan(),
            "imageWidth": c.width, "imageHeight": c.height,
            "cameraTransform": { "rows": [
                [c.right.x, c.up.x, back.x, c.position.x],
                [c.right.y, c.up.y, back.y, c.position.y],
                [c.right.z, c.up.z, back.z, c.position.z],
                [0.0, 0.0, 0.0, 1.0]
            ] }
        }
    })
    .to_string();
    let mut file = Vec::new();
    file.extend(b"fspy");
    file.extend(1u32.to_le_bytes());
    file.extend((state.len() as u32).to_le_bytes());
    file.extend(0u32.to_le_bytes());
    file.extend(state.as_bytes());
    let desk = desk_with_camera("[camera]\nfspy = \"room.fspy\"\nwidth = 512\n");
    std::fs::write(desk.path("room.fspy"), &file).unwrap();
    same_rays(&c, &Scene::load(desk.path("scene.toml")).unwrap().camera);

    // Keys the project decides are refused, naming them.
    desk.edit("scene.toml", "width = 512", "width = 512\nfov_y_deg = 50.0");
    let e = Scene::load(desk.path("scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("camera.fov_y_deg") && e.contains("comes from fspy"),
        "{e}"
    );
}

#[test]
fn a_camera_at_half_scale_renders_the_photo_averaged_down_as_accurately() {
    let desk = common::Desk::new();
    desk.edit(
        "scene.toml",
        "fov_y_deg = 55.0\n",
        "fov_y_deg = 55.0\nscale = 0.5\n",
    );
    let out = desk.path("half.exr");
    let report = common::render_box_floor_a(&desk, &out);
    let image = arlux::image_io::read_image(&out).unwrap();
    assert_eq!((image.width, image.height), (256, 192));
    // The full-size render's skill is 0.895; the reference is averaged
    // down as the photo is.
    let skill = report["skill"]["skill"].as_f64().unwrap();
    assert!(skill > 0.85, "skill {skill}");
    desk.edit("scene.toml", "scale = 0.5", "scale = 1.5");
    let e = Scene::load(desk.path("scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera.scale: must lie in (0, 1]"), "{e}");
}

/// OpenCV's fixed-point undistortion (not the library's Newton steps): the
/// normalised point a lens with k1, k2, p1, p2 shows at (xd, yd).
fn undistort(k: [f64; 4], xd: f64, yd: f64) -> (f64, f64) {
    let [k1, k2, p1, p2] = k;
    let (mut x, mut y) = (xd, yd);
    for _ in 0..200 {
        let r2 = x * x + y * y;
        let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
        let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        (x, y) = ((xd - dx) / radial, (yd - dy) / radial);
    }
    (x, y)
}

#[test]
fn a_photo_shot_through_a_lens_registers_with_the_model() {
    use arlux::surface_ids::SurfaceIds;
    use arlux::trace::Layer;
    let k = [-0.18, 0.03, 0.002, -0.001];
    let desk = desk_with_camera(&format!(
        "{CAMERA}distortion = {{ k1 = {}, k2 = {}, p1 = {}, p2 = {} }}\n",
        k[0], k[1], k[2], k[3]
    ));
    let scene = Scene::load(desk.path("scene.toml")).unwrap();
    let tracer = arlux::scene_tracer::build_tracer(&scene).unwrap();
    let lens = SurfaceIds::at_pixel_centres(&scene.camera, &tracer, Layer::Real);
    let pinhole = known();
    // The truth: the pinhole camera's ids at 4× resolution, looked up where
    // each pixel of the distorted photo sees (OpenCV's own inversion).
    let fine = pinhole.scaled(4.0);
    let truth_ids = SurfaceIds::at_pixel_centres(&fine, &tracer, Layer::Real);
    let plain = SurfaceIds::at_pixel_centres(&pinhole, &tracer, Layer::Real);
    let (w, h) = (pinhole.width, pinhole.height);
    let (mut compared, mut agree, mut agree_plain) = (0, 0, 0);
    for y in 0..h {
        for x in 0..w {
            let xd = (x as f64 + 0.5 - pinhole.cx) / pinhole.fx;
            let yd = (y as f64 + 0.5 - pinhole.cy) / pinhole.fy;
            let (u, v) = undistort(k, xd, yd);
            let (fx, fy) = (fine.cx + fine.fx * u, fine.cy + fine.fy * v);
            if fx < 0.0 || fy < 0.0 || fx >= fine.width as f64 || fy >= fine.height as f64 {
                continue;
            }
            let truth = truth_ids.ids[fy as usize * fine.width as usize + fx as usize];
            let i = (y * w + x) as usize;
            compared += 1;
            agree += usize::from(lens.ids[i] == truth);
            agree_plain += usize::from(plain.ids[i] == truth);
        }
    }
    let share = agree as f64 / compared as f64;
    let plain_share = agree_plain as f64 / compared as f64;
    assert!(compared > 150_000, "{compared}");
    assert!(
        share >= 0.99,
        "the lens camera agrees on {share:.4} of the pixels"
    );
    // The lens matters: a pinhole camera misregisters the same photo.
    assert!(plain_share < 0.97, "a pinhole agrees on {plain_share:.4}");
}

#[test]
fn a_lens_that_folds_the_image_back_is_refused() {
    // k1 = −1: the radius stops growing at r² = 1/3, inside the desk's corners.
    let desk = desk_with_camera(&format!("{CAMERA}distortion = {{ k1 = -1.0 }}\n"));
    let e = Scene::load(desk.path("scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("camera.distortion") && e.contains("folds the image back"),
        "{e}"
    );
}
