//! Scene loading: the desk loads with its meanings, and every kind of bad
//! input is refused with an error naming the file and the key.

use super::*;

const DESK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/desk");

/// A temporary copy of the desk's scene.toml with text replaced, resolving
/// paths against the real desk folder (files are only read).
struct Edited {
    _dir: tempfile::TempDir,
    file: PathBuf,
}

fn desk_text() -> String {
    std::fs::read_to_string(Path::new(DESK).join("scene.toml")).unwrap()
}

fn edited(edits: &[(&str, &str)]) -> Edited {
    let mut text = desk_text();
    for (old, new) in edits {
        assert!(text.contains(old), "the desk's scene.toml has no '{old}'");
        text = text.replacen(old, new, 1);
    }
    let dir = tempfile::tempdir().unwrap();
    for sub in ["geometry", "truth"] {
        std::os::unix::fs::symlink(Path::new(DESK).join(sub), dir.path().join(sub)).unwrap();
    }
    std::os::unix::fs::symlink(
        Path::new(DESK).join("photo.exr"),
        dir.path().join("photo.exr"),
    )
    .unwrap();
    let file = dir.path().join("scene.toml");
    std::fs::write(&file, text).unwrap();
    Edited { _dir: dir, file }
}

/// Loads with the edits and returns the error text, which must name the file.
fn error_of(edits: &[(&str, &str)]) -> String {
    let e = edited(edits);
    let err = Scene::load(&e.file)
        .expect_err("must be refused")
        .to_string();
    assert!(
        err.contains("scene.toml"),
        "error does not name the file: {err}"
    );
    err
}

#[test]
fn the_desk_loads_with_its_meanings() {
    let s = Scene::load(Path::new(DESK).join("scene.toml")).unwrap();
    assert_eq!(s.name, "desk");
    let names: Vec<_> = s.surfaces.iter().map(|x| x.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "table_top",
            "table_legs",
            "floor",
            "back_wall",
            "left_wall",
            "ceiling"
        ]
    );
    assert_eq!(
        s.reflectances,
        vec![KnownReflectance {
            surface: 4,
            rgb: DVec3::new(0.55, 0.62, 0.7)
        }]
    );
    assert_eq!(s.lights.len(), 3);
    assert!(!s.lights[2].real && s.lights[2].scale == 0.0);
    assert!(matches!(s.lights[0].shape, LightShape::Rect { .. }));
    match &s.lights[1].intensity {
        Intensity::Spot {
            direction,
            beam_deg,
            cutoff_deg,
            ..
        } => {
            assert!((direction.length() - 1.0).abs() < 1e-12);
            assert_eq!((*beam_deg, *cutoff_deg), (15.0, 30.0));
        }
        other => panic!("spot expected, got {other:?}"),
    }
    assert_eq!(s.objects[0].surfaces[0].rgb, DVec3::new(0.8, 0.32, 0.06));
    assert_eq!(s.variants.len(), 6);
    assert_eq!(s.motions[0].translations.len(), 8);
    assert_eq!(s.motions[0].references.len(), 8);
    assert!(s.warnings.is_empty());
}

#[test]
fn variants_set_scales_pose_objects_and_hide() {
    let s = Scene::load(Path::new(DESK).join("scene.toml")).unwrap();
    let b = s.with_variant("box_floor_b").unwrap();
    assert_eq!(b.objects[0].pose.translate, DVec3::new(-1.2, 0.0, 0.7));
    assert_eq!(b.objects[0].pose.rotation, Pose::about_y(-15.0));
    assert!(b.objects[0].enabled);
    let v = s.with_variant("virtual_light_only").unwrap();
    assert_eq!(
        v.lights.iter().map(|l| l.scale).collect::<Vec<_>>(),
        [0.0, 0.0, 1.0]
    );
    assert!(!v.objects[0].enabled);
    assert!(
        v.virtual_world_surfaces().is_empty(),
        "a hidden object builds no virtual geometry"
    );
    // A virtual light moved and scaled by a table: the same scene as the
    // light declared there.
    let e = edited(&[(
        "lights = { panel = 0.0, spot = 0.0, bulb = 1.0 }",
        "lights = { panel = 0.0, spot = 0.0, bulb = { scale = 1.0, position = [0.2, 1.7, -0.4] } }",
    )]);
    let moved = Scene::load(&e.file)
        .unwrap()
        .with_variant("virtual_light_only")
        .unwrap();
    assert_eq!(
        moved.lights[2].known_position(),
        Some(DVec3::new(0.2, 1.7, -0.4))
    );
    let mut expected = v.clone();
    expected.lights[2].position = LightPosition::Known(DVec3::new(0.2, 1.7, -0.4));
    assert_eq!(moved.lights, expected.lights);
    let x2 = s.with_variant("spot_x2").unwrap();
    assert_eq!(
        x2.lights[1].scale, 2.0,
        "a variant sets the scale, it does not multiply"
    );
    let e = s.with_variant("nope").unwrap_err().to_string();
    assert!(
        e.contains("no variant named 'nope'") && e.contains("box_floor_a"),
        "{e}"
    );
}

#[test]
fn motion_poses_translate_and_keep_rotation() {
    let s = Scene::load(Path::new(DESK).join("scene.toml")).unwrap();
    let p = s.with_motion_pose("box_slide", 3).unwrap();
    assert_eq!(
        p.objects[0].pose.translate,
        DVec3::new(-0.2714, 0.0, 0.1143)
    );
    assert_eq!(p.objects[0].pose.rotation, Pose::about_y(20.0));
    assert!(s.with_motion_pose("box_slide", 8).is_err());
}

#[test]
fn rotation_is_counter_clockwise_seen_from_above() {
    let pose = Pose {
        translate: DVec3::new(1.0, 0.0, 0.0),
        rotation: Pose::about_y(90.0),
        scale: 2.0,
    };
    // +x turns towards -z when rotating counter-clockwise about +y seen from above.
    let p = pose.apply(Vec3::new(1.0, 0.5, 0.0));
    assert!((p - Vec3::new(1.0, 1.0, -2.0)).length() < 1e-6, "{p}");
}

#[test]
fn intrinsics_replace_the_field_of_view() {
    let e = edited(&[(
        "fov_y_deg = 55.0",
        "intrinsics = { fx = 400.0, fy = 401.0, cx = 250.0, cy = 190.0 }",
    )]);
    let s = Scene::load(&e.file).unwrap();
    assert_eq!(
        (s.camera.fx, s.camera.fy, s.camera.cx, s.camera.cy),
        (400.0, 401.0, 250.0, 190.0)
    );
}

/// Edits of the desk's scene file and the error each must give.
#[allow(clippy::type_complexity)]
const BAD_VALUES: &[(&[(&str, &str)], &str)] = &[
    (
        &[(
            "beam_deg = 15.0, cutoff_deg = 30.0",
            "beam_deg = 35.0, cutoff_deg = 30.0",
        )],
        "light[1].intensity.spot.cutoff_deg: must be greater than beam_deg",
    ),
    (
        &[("name = \"desk\"", "name = \"desk\"\nexposure = 2")],
        "exposure: unknown key",
    ),
    (
        &[("fov_y_deg = 55.0", "fov_y_deg = nan")],
        "camera.fov_y_deg: must be finite",
    ),
    (
        &[(
            "fov_y_deg = 55.0",
            "fov_y_deg = 55.0\nintrinsics = { fx = 1.0, fy = 1.0, cx = 0.0, cy = 0.0 }",
        )],
        "camera.intrinsics: give fov_y_deg or intrinsics",
    ),
    (
        &[("position = [0.7, 1.45, 2.7]", "position = [0.7, 1.45]")],
        "camera.position: must be an array of 3 numbers",
    ),
    (
        &[("look_at = [-0.45, 0.6, -1.0]", "look_at = [0.7, 1.45, 2.7]")],
        "camera.look_at: must differ from position",
    ),
    (
        &[("width = 512", "width = -4")],
        "camera.width: must be a positive whole number",
    ),
    (
        &[("image = \"photo.exr\"", "image = \"missing.exr\"")],
        "photo.image: file not found",
    ),
    (
        &[(
            "mesh = \"geometry/room.obj\"",
            "mesh = \"geometry/nope.obj\"",
        )],
        "real[1].mesh: file not found",
    ),
    (
        &[("surface = \"left_wall\"", "surface = \"right_wall\"")],
        "reflectance[0].surface: no real surface named 'right_wall'",
    ),
    (
        &[("rgb = [0.55, 0.62, 0.7]", "rgb = [0.55, 1.62, 0.7]")],
        "reflectance[0].rgb: a reflectance lies in [0, 1]",
    ),
    (
        &[(
            "intensity = { uniform = [6.0, 5.5, 5.0] }",
            "intensity = { uniform = [6.0, -5.5, 5.0] }",
        )],
        "light[2].intensity.uniform: components must not be negative",
    ),
    (
        &[(
            "intensity = { uniform = [6.0, 5.5, 5.0] }",
            "intensity = { uniform = [6.0, 5.5, 5.0], spot = {} }",
        )],
        "light[2].intensity: must have exactly one of",
    ),
    (
        &[(
            "intensity = { uniform = [6.0, 5.5, 5.0] }",
            "intensity = { uniforn = [6.0, 5.5, 5.0] }",
        )],
        "light[2].intensity.uniforn: unknown key",
    ),
    (
        &[("normal = [0.0, -1.0, 0.0]", "normal = [0.0, 1.0, 0.0]")],
        "light[0].intensity.lambertian.normal: disagrees with the shape",
    ),
    (
        &[("v = [0.0, 0.0, 0.6]", "v = [1.2, 0.0, 0.0]")],
        "light[0].shape.rect.v: is parallel to u: u and v must span a rectangle",
    ),
    (
        &[("scale = 0.0\nintensity", "scale = -1.0\nintensity")],
        "light[2].scale: must not be negative",
    ),
    (
        &[("name = \"bulb\"", "name = \"spot\"")],
        "light[2].name: light name 'spot' is used twice",
    ),
    (
        &[("lights = { spot = 2.0 }", "lights = { sopt = 2.0 }")],
        "variant[4].lights.sopt: no light named 'sopt'",
    ),
    (
        &[("hide = [\"box\"]", "hide = [\"bx\"]")],
        "variant[3].hide[0]: no virtual object or light named 'bx'",
    ),
    (
        &[("object = \"box\"", "object = \"crate\"")],
        "motion[0].object: no virtual object named 'crate'",
    ),
    (
        &[("\"truth/box_slide_7.exr\"]", "]")],
        "motion[0].references: 7 references for 8 poses",
    ),
    (
        &[("[-1.3, 0.0, 0.5], ", "[-1.3, inf, 0.5], ")],
        "motion[0].translations[0]: must be finite",
    ),
    (
        &[("rgb = [0.8, 0.32, 0.06]\n", "")],
        "virtual[0].rgb: missing, and surface 'box'",
    ),
    (
        &[("scale = 1.0\nenabled", "scale = 0.0\nenabled")],
        "virtual[0].scale: must be positive",
    ),
    (
        &[(
            "intensity = { uniform = [6.0, 5.5, 5.0] }",
            "intensity = { ies = \"lamp.ies\", rgb = [1.0, 1.0, 1.0], direction = [0.0, -1.0, 0.0], reference = [1.0, 0.0, 0.0] }",
        )],
        "light[2].intensity.ies: file not found",
    ),
    (
        &[
            (
                "intensity = { uniform = [6.0, 5.5, 5.0] }",
                "intensity = \"reconstruct\"",
            ),
            (
                "[[reflectance]]\nsurface = \"left_wall\"\nrgb = [0.55, 0.62, 0.7]\n",
                "",
            ),
        ],
        "light[2].intensity: \"reconstruct\" needs at least one [[reflectance]]",
    ),
    (
        &[(
            "image = \"photo.exr\"",
            "brackets = [{ image = \"photo.exr\", ev = 0.0 }]",
        )],
        "photo.brackets: 1 exposure(s)",
    ),
    (
        &[(
            "image = \"photo.exr\"",
            "brackets = [{ image = \"photo.exr\", ev = 0.0 }, { image = \"photo.exr\", ev = 0.0 }]",
        )],
        "photo.brackets[1].ev: two brackets have ev = 0",
    ),
    (
        &[(
            "image = \"photo.exr\"",
            "image = \"photo.exr\"\nbrackets = []",
        )],
        "photo.brackets: give image or brackets, not both",
    ),
    (
        &[(
            "position = [0.9, 1.9, 0.3]",
            "position = { shadow_lines = [] }",
        )],
        "light[2].position: needs shadow_lines or shadow_planes",
    ),
    (
        &[(
            "[[light]]\nname = \"panel\"",
            "[[texture_reference]]\nsurface = \"flor\"\npoint = [0.0, 0.0, 0.0]\n\n[[light]]\nname = \"panel\"",
        )],
        "texture_reference[0].surface: no real surface named 'flor'",
    ),
    (
        &[(
            "[[light]]\nname = \"panel\"",
            "[[texture_reference]]\nsurface = \"floor\"\npoint = [0.0, 0.0]\n\n[[light]]\nname = \"panel\"",
        )],
        "texture_reference[0].point: must be an array of 3 numbers",
    ),
    (
        &[(
            "lights = { spot = 2.0 }",
            "lights = { spot = { position = [0.0, 1.0, 0.0] } }",
        )],
        "lights.spot.position: 'spot' is a real light: it stays where the photo has it",
    ),
    (
        &[("lights = { spot = 2.0 }", "lights = { spot = {} }")],
        "lights.spot: give scale, position or both",
    ),
    (
        &[(
            "lights = { spot = 2.0 }",
            "lights = { spot = { scale = 2.0, colour = 1 } }",
        )],
        "lights.spot.colour: unknown key",
    ),
    (
        &[(
            "lights = { spot = 2.0 }",
            "lights = { spot = { scale = -2.0 } }",
        )],
        "lights.spot: a light's scale must not be negative",
    ),
];

#[test]
fn bad_values_name_the_key_path() {
    let cases = BAD_VALUES;
    for (edits, expected) in cases {
        let err = error_of(edits);
        assert!(err.contains(expected), "expected '{expected}' in: {err}");
    }
}

#[test]
fn malformed_toml_is_reported_with_its_line() {
    let err = error_of(&[("fov_y_deg = 55.0", "fov_y_deg = = 55.0")]);
    assert!(err.contains("scene.toml: line 9: malformed TOML"), "{err}");
}

#[test]
fn lights_on_or_inside_surfaces_are_refused_but_millimetres_away_is_fine() {
    let on_floor = error_of(&[("position = [0.9, 1.9, 0.3]", "position = [0.9, 0.0, 0.3]")]);
    assert!(
        on_floor.contains("light[2].position: light 'bulb' lies on surface 'floor'"),
        "{on_floor}"
    );
    let in_table = error_of(&[(
        "position = [0.9, 1.9, 0.3]",
        "position = [-0.4, 0.73, -1.4]",
    )]);
    assert!(
        in_table
            .contains("light[2].position: light 'bulb' lies inside the closed surface 'table_top'"),
        "{in_table}"
    );
    let e = edited(&[("position = [0.9, 1.9, 0.3]", "position = [0.9, 0.002, 0.3]")]);
    assert!(
        Scene::load(&e.file).is_ok(),
        "2 mm above the floor is a valid (stiff) light"
    );
    // Moving the box over a light is caught when the variant is applied.
    let e = edited(&[("position = [0.9, 1.9, 0.3]", "position = [-1.2, 0.1, 0.7]")]);
    let s = Scene::load(&e.file).unwrap();
    let err = s.with_variant("box_floor_b").unwrap_err().to_string();
    assert!(
        err.contains("variant[1]") && err.contains("inside the closed surface 'box/box'"),
        "{err}"
    );
}

/// A missing reference stops only what compares against it: the scene
/// loads with a warning naming the variant, and reading that reference is
/// an error naming its key.
#[test]
fn a_missing_reference_warns_and_stops_only_its_comparison() {
    let e = edited(&[(
        "reference = \"truth/spot_x2.exr\"",
        "reference = \"truth/spot_x3.exr\"",
    )]);
    let s = Scene::load(&e.file).unwrap();
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].starts_with("variant 'spot_x2'.reference: file not found: ")
            && s.warnings[0].contains("spot_x3.exr"),
        "{}",
        s.warnings[0]
    );
    let missing = s.variant("spot_x2").unwrap().reference.clone().unwrap();
    let err = (s.check_reference("variant 'spot_x2'.reference", &missing))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("scene.toml: variant 'spot_x2'.reference: file not found"),
        "{err}"
    );
    let present = s.variant("panel_off").unwrap().reference.clone().unwrap();
    s.check_reference("variant 'panel_off'.reference", &present)
        .unwrap();
}

#[test]
fn degenerate_triangles_are_dropped_with_a_warning_and_bad_obj_names_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("extra.obj");
    std::fs::write(
        &obj,
        "o shelf\nv -1 1 -1.9\nv 0 1 -1.9\nv 0 1 -1.5\nv 0.5 1 -1.5\nf 1 2 3\nf 1 2 2\nf 3 3 1\n",
    )
    .unwrap();
    let text = desk_text().replace(
        "[[real]]\nmesh = \"geometry/room.obj\"",
        &format!(
            "[[real]]\nmesh = \"{}/geometry/room.obj\"\n\n[[real]]\nmesh = \"{}\"",
            DESK,
            obj.display()
        ),
    );
    let text = text
        .replace("\"photo.exr\"", &format!("\"{DESK}/photo.exr\""))
        .replace("\"geometry/", &format!("\"{DESK}/geometry/"))
        .replace("\"truth/", &format!("\"{DESK}/truth/"));
    let file = dir.path().join("scene.toml");
    std::fs::write(&file, &text).unwrap();
    let s = Scene::load(&file).unwrap();
    assert_eq!(s.surfaces.last().unwrap().triangles.len(), 1);
    assert_eq!(s.warnings.len(), 1);
    assert!(
        s.warnings[0].contains("dropped 2 degenerate"),
        "{:?}",
        s.warnings
    );

    std::fs::write(
        &obj,
        "o shelf\nv -1 1 -1.9\nv 0 1 -1.9\nv 0 1 oops\nf 1 2 3\n",
    )
    .unwrap();
    let err = Scene::load(&file).unwrap_err().to_string();
    assert!(
        err.contains("scene.toml: real[2].mesh:")
            && err.contains("extra.obj: line 4: vertex: 'oops' is not a number"),
        "{err}"
    );
}

/// The desk's box placed by `keys` (TOML inside `[[virtual]]`), or the error.
fn box_placed(keys: &str) -> Result<Pose> {
    let dir = tempfile::tempdir().unwrap();
    let photo = Path::new(DESK).join("photo.exr");
    std::fs::copy(photo, dir.path().join("photo.exr")).unwrap();
    std::fs::create_dir(dir.path().join("geometry")).unwrap();
    for f in ["room.obj", "furniture.obj", "box.obj"] {
        let from = Path::new(DESK).join("geometry").join(f);
        std::fs::copy(from, dir.path().join("geometry").join(f)).unwrap();
    }
    let text = std::fs::read_to_string(Path::new(DESK).join("scene.toml")).unwrap();
    let text = text.replace(
        "translate = [0.35, 0.0, -0.25]\nrotate_y_deg = 20.0\nscale = 1.0\n",
        &format!("{keys}\n"),
    );
    let cut = text.find("[[variant]]").unwrap();
    std::fs::write(dir.path().join("scene.toml"), &text[..cut]).unwrap();
    Scene::load(dir.path().join("scene.toml")).map(|s| s.objects[0].pose)
}

#[test]
fn rotations_given_as_euler_angles_a_quaternion_or_a_matrix_agree() {
    let close = |a: &Pose, b: &Pose| {
        let p = Vec3::new(0.3, -0.2, 0.7);
        (a.apply(p) - b.apply(p)).length() < 1e-6
    };
    let y = box_placed("rotate_y_deg = 30.0").unwrap();
    let euler = box_placed("rotate = [0.0, 30.0, 0.0]").unwrap();
    let (s, c) = (15f64.to_radians().sin(), 15f64.to_radians().cos());
    let quat = box_placed(&format!("quaternion = [{c}, 0.0, {s}, 0.0]")).unwrap();
    assert!(close(&y, &euler) && close(&y, &quat));
    // Blender's XYZ Euler: x first, then y, then z; read back the same.
    let xyz = box_placed("rotate = [10.0, -20.0, 35.0]\ntranslate = [0.1, 0.2, 0.3]\nscale = 2.0")
        .unwrap();
    let e = xyz.euler_xyz_deg();
    assert!(
        (e[0] - 10.0).abs() < 1e-9 && (e[1] + 20.0).abs() < 1e-9 && (e[2] - 35.0).abs() < 1e-9,
        "{e:?}"
    );
    // The same placement as a 4×4 matrix, rows, scale folded in.
    let r = |i: usize| (xyz.rotation.row(i) * 2.0).to_array();
    let t = [0.1, 0.2, 0.3];
    let m = format!(
        "matrix = [[{}, {}, {}, {}], [{}, {}, {}, {}], [{}, {}, {}, {}], [0.0, 0.0, 0.0, 1.0]]",
        r(0)[0],
        r(0)[1],
        r(0)[2],
        t[0],
        r(1)[0],
        r(1)[1],
        r(1)[2],
        t[1],
        r(2)[0],
        r(2)[1],
        r(2)[2],
        t[2]
    );
    let from_matrix = box_placed(&m).unwrap();
    assert!(close(&xyz, &from_matrix), "{from_matrix:?}");
    assert!((from_matrix.scale - 2.0).abs() < 1e-12);
    // Shear, a mirror, two rotations: refused at their key.
    let shear = box_placed(
        "matrix = [[1.0, 0.5, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]",
    );
    assert!(
        shear
            .unwrap_err()
            .to_string()
            .contains("virtual[0].matrix: its 3×3 part is not a rotation")
    );
    let mirror = box_placed(
        "matrix = [[-1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]",
    );
    assert!(mirror.unwrap_err().to_string().contains("mirrors"));
    let two = box_placed("rotate_y_deg = 10.0\nrotate = [0.0, 1.0, 0.0]");
    assert!(two.unwrap_err().to_string().contains("give one rotation"));
}
