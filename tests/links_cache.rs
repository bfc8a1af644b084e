//! The room's links kept in `.arlux-cache/`: read back bit for bit, on
//! both paths, refined again when damaged or not asked for, pruned. In its
//! own test binary: its renders would otherwise share the machine with the
//! timing tests of `commands.rs`.

mod common;

use common::{Desk, arlux_json, arlux_ok, stage_names};

#[test]
fn a_second_render_of_the_room_reads_its_links_from_the_cache() {
    let desk = Desk::new();
    let render = |variant: &str, out: &str, extra: &[&str]| {
        let out = desk.path(out);
        let mut args = vec![
            "render",
            &desk.scene(),
            "--variant",
            variant,
            "-o",
            out.to_str().unwrap(),
            "--json",
        ]
        .into_iter()
        .map(str::to_string)
        .collect::<Vec<_>>();
        args.extend(extra.iter().map(|a| a.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let report = arlux_json(&args);
        (stage_names(&report), std::fs::read(out).unwrap())
    };
    let cache = desk.path(".arlux-cache");
    let entries = || -> Vec<std::path::PathBuf> {
        std::fs::read_dir(&cache)
            .map(|d| d.map(|e| e.unwrap().path()).collect())
            .unwrap_or_default()
    };
    let (first, image) = render("panel_off", "a.exr", &["--no-cache"]);
    assert!(first.iter().any(|s| s == "form factors"), "{first:?}");
    assert!(entries().is_empty(), "--no-cache wrote {:?}", entries());
    let (cold, cold_image) = render("panel_off", "b.exr", &[]);
    assert!(cold.iter().any(|s| s == "form factors"), "{cold:?}");
    assert_eq!(entries().len(), 1, "{:?}", entries());
    // Another variant of the same room reads the links; the image is the
    // one refinement gives, bit for bit.
    let (warm, warm_image) = render("panel_off", "c.exr", &[]);
    assert!(
        warm.iter().any(|s| s == "links from the cache")
            && !warm.iter().any(|s| s == "form factors"),
        "{warm:?}"
    );
    assert!(image == cold_image && image == warm_image);
    let (spot, _) = render("spot_x2", "d.exr", &[]);
    assert!(spot.iter().any(|s| s == "links from the cache"), "{spot:?}");
    // A damaged entry is refined again, and the image is still the same.
    let entry = &entries()[0];
    let bytes = std::fs::read(entry).unwrap();
    std::fs::write(entry, &bytes[..bytes.len() - 5]).unwrap();
    let (damaged, damaged_image) = render("panel_off", "e.exr", &[]);
    assert!(damaged.iter().any(|s| s == "form factors"), "{damaged:?}");
    assert!(damaged_image == image);
    // Another mesh size is another entry.
    render("panel_off", "f.exr", &["--patch-size", "0.5"]);
    assert_eq!(entries().len(), 2, "{:?}", entries());
    // The texture path's mesh, refined from the photo, is another again,
    // read back the same way.
    let texture = ["--method", "texture"];
    let (cold, cold_image) = render("panel_off", "g.exr", &texture);
    let (warm, warm_image) = render("panel_off", "h.exr", &texture);
    assert!(cold.iter().any(|s| s == "form factors"), "{cold:?}");
    assert!(warm.iter().any(|s| s == "links from the cache"), "{warm:?}");
    assert!(cold_image == warm_image);
    assert_eq!(entries().len(), 3, "{:?}", entries());
    // A folder keeps the four entries used last: older ones go when a new
    // one is written.
    let long_ago = std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_000_000);
    let stale: Vec<_> = (0..3)
        .map(|i| cache.join(format!("links-{i:016x}.bin")))
        .collect();
    for path in &stale {
        std::fs::write(path, b"old").unwrap();
        let file = std::fs::File::options().write(true).open(path).unwrap();
        file.set_modified(long_ago).unwrap();
    }
    render("panel_off", "i.exr", &["--patch-size", "0.35"]);
    assert_eq!(entries().len(), 4, "{:?}", entries());
    assert!(stale.iter().all(|p| !p.exists()), "{:?}", entries());
}

#[test]
fn a_motion_s_first_pose_reads_the_room_s_links_from_the_cache() {
    let desk = Desk::new();
    let scene = desk.scene();
    let run = |out: &str, extra: &[&str]| {
        let dir = desk.path(out);
        let dir_arg = dir.display().to_string();
        let mut args = vec![
            "--timings",
            "motion",
            &scene,
            "--motion",
            "box_slide",
            "--frames",
            "0..2",
            "-o",
            &dir_arg,
        ];
        args.extend_from_slice(extra);
        let run = arlux_ok(&args);
        let frames: Vec<Vec<u8>> = (0..2)
            .map(|i| std::fs::read(dir.join(format!("box_slide_{i:03}.exr"))).unwrap())
            .collect();
        (String::from_utf8_lossy(&run.stderr).into_owned(), frames)
    };
    let (uncached, frames) = run("a", &["--no-cache"]);
    assert!(!desk.path(".arlux-cache").exists(), "{uncached}");
    let (cold, cold_frames) = run("b", &[]);
    let (warm, warm_frames) = run("c", &[]);
    assert!(!cold.contains("links from the cache"), "{cold}");
    assert!(warm.contains("links from the cache"), "{warm}");
    assert!(frames == cold_frames && frames == warm_frames);
}

#[test]
fn the_rooms_automatic_patch_size_is_read_from_the_cache() {
    // A white room refines its coarse mesh (the size found from a coarse
    // model); a second render reads the size instead of building that
    // model, and renders the same image bit for bit.
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/whitebox");
    let files = [
        "scene.toml",
        "photo.exr",
        "geometry/room.obj",
        "geometry/cube.obj",
    ];
    let dir = common::writable_copy(&src, &files);
    let scene = dir.path().join("scene.toml").display().to_string();
    let render = |out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec!["render", &scene, "--variant", "cube_close", "-o"];
        let out_arg = out.display().to_string();
        args.push(&out_arg);
        args.push("--json");
        args.extend_from_slice(extra);
        let report = arlux_json(&args);
        let meshes = report["stages"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["stage"] == "mesh")
            .map_or(0, |s| s["runs"].as_u64().unwrap());
        (meshes, std::fs::read(out).unwrap())
    };
    let sizes = || -> usize {
        std::fs::read_dir(dir.path().join(".arlux-cache"))
            .map(|d| {
                d.filter(|e| {
                    let name = e.as_ref().unwrap().file_name();
                    name.to_string_lossy().starts_with("room-size-")
                })
                .count()
            })
            .unwrap_or(0)
    };
    let (uncached, image) = render("a.exr", &["--no-cache"]);
    assert_eq!(
        (uncached, sizes()),
        (2, 0),
        "coarse then fine, nothing kept"
    );
    let (cold, cold_image) = render("b.exr", &[]);
    let (warm, warm_image) = render("c.exr", &[]);
    assert_eq!((cold, warm, sizes()), (2, 1, 1), "the size read back");
    assert!(image == cold_image && image == warm_image);
    // Another photo is another entry.
    let mut photo = arlux::image_io::read_image(&dir.path().join("photo.exr")).unwrap();
    photo.pixels.iter_mut().for_each(|p| *p *= 1.25);
    let layer = arlux::image_io::ExrLayer::Rgb("", &photo);
    let (w, h) = (photo.width, photo.height);
    arlux::image_io::write_exr(&dir.path().join("photo.exr"), w, h, &[layer]).unwrap();
    let (other, _) = render("d.exr", &[]);
    assert_eq!((other, sizes()), (2, 2));
}
