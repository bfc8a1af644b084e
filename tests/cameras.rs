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
            "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n3 SIMPLE_RADIAL 512 384 300 256 192 0.1\n1 PINHOLE 512 384 {:.17} {:.17} {:.17} {:.17}\n",
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
            && e.contains("SIMPLE_RADIAL")
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
    let run = common::arlux(&[
        "render",
        &desk.scene(),
        "--variant",
        "box_floor_a",
        "-o",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
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
