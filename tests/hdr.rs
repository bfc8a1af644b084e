//! HDR from the desk's exposure brackets: the recovered response against
//! the true one, and the merged map against photo.exr.

use std::path::{Path, PathBuf};

use arlux::hdr::{Exposure, check_brackets, merge, recover_response};
use arlux::image_io::read_image;

const DESK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/desk");

fn brackets() -> Vec<Exposure> {
    [-2.0, -1.0, 0.0, 1.0, 2.0]
        .iter()
        .map(|&ev| {
            let name = if ev < 0.0 {
                format!("ev{ev}")
            } else {
                format!("ev+{ev}")
            };
            Exposure::read(&Path::new(DESK).join(format!("brackets/{name}.png")), ev).unwrap()
        })
        .collect()
}

#[test]
fn recovered_response_and_merged_map_match_the_truth() {
    let exposures = brackets();
    let response = recover_response(&exposures, 64, 20.0).unwrap();
    // True response: code -> normalised exposure (response.csv).
    let csv = std::fs::read_to_string(Path::new(DESK).join("brackets/response.csv")).unwrap();
    let truth: Vec<f64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    // Up to the method's scale: aligned at code 128 (g(128) = 0). Relative
    // error over codes 16..=250 (below 16 a code spans too wide a range of
    // exposures to pin the toe down), and over every code as a fraction of
    // full scale.
    let (mut relative, mut absolute): (f64, f64) = (0.0, 0.0);
    for channel in &response {
        let scale = truth[128] / channel[128].exp();
        for (z, g) in channel.iter().enumerate() {
            let ours = g.exp() * scale;
            absolute = absolute.max((ours - truth[z]).abs() / truth[255]);
            if (16..=250).contains(&z) {
                relative = relative.max((ours / truth[z] - 1.0).abs());
            }
        }
    }
    println!(
        "response: worst relative error {:.2}% over codes 16..250; worst error {:.2}% of full scale over all codes",
        100.0 * relative,
        100.0 * absolute
    );
    assert!(relative < 0.02 && absolute < 0.02, "{relative} {absolute}");

    let merged = merge(&exposures, &response).unwrap();
    let photo = read_image(&Path::new(DESK).join("photo.exr")).unwrap();
    // One global factor: least squares over pixels.
    let (mut num, mut den) = (0.0, 0.0);
    for (m, p) in merged.image.pixels.iter().zip(&photo.pixels) {
        num += m.as_dvec3().dot(p.as_dvec3());
        den += m.as_dvec3().length_squared();
    }
    let s = num / den;
    let longest = exposures
        .iter()
        .max_by(|a, b| a.ev.total_cmp(&b.ev))
        .unwrap();
    let rel = |mask: &dyn Fn(usize) -> bool| {
        let (mut se, mut sum, mut n) = (0.0, 0.0, 0usize);
        for i in 0..photo.pixels.len() {
            if mask(i) {
                let d = merged.image.pixels[i].as_dvec3() * s - photo.pixels[i].as_dvec3();
                se += d.length_squared();
                sum += photo.pixels[i].as_dvec3().element_sum();
                n += 3;
            }
        }
        (se / n as f64).sqrt() / (sum / n as f64)
    };
    let all = rel(&|_| true);
    let unsaturated = rel(&|i| longest.codes[i].iter().all(|&c| c < 255));
    println!(
        "merged vs photo.exr after one global factor: relative RMSE {:.2}% over all pixels, {:.2}% where the longest exposure is not saturated; {} saturated everywhere",
        100.0 * all,
        100.0 * unsaturated,
        merged.saturated.iter().filter(|s| **s).count()
    );
    assert!(all < 0.01 && unsaturated < 0.01);
}

#[test]
fn bad_brackets_are_refused_clearly() {
    let mut e = brackets();
    let e1 = vec![e[0].clone()];
    assert!(
        check_brackets(&e1)
            .unwrap_err()
            .to_string()
            .contains("a single exposure")
    );
    e[1].ev = e[0].ev;
    assert!(
        check_brackets(&e)
            .unwrap_err()
            .to_string()
            .contains("same EV")
    );
    let mut e = brackets();
    e[2].width = 256;
    let msg = check_brackets(&e).unwrap_err().to_string();
    assert!(
        msg.contains("ev+0.png") && msg.contains("must be aligned"),
        "{msg}"
    );
    let _ = PathBuf::new();
}

#[test]
fn the_box_rendered_from_brackets_is_within_a_quarter_of_the_exr_render() {
    use arlux::model::StageTimes;
    use arlux::render::{RenderSettings, render};
    // A private copy, so that the cache next to the scene starts empty.
    let dir = tempfile::tempdir().unwrap();
    for sub in ["geometry", "truth", "brackets"] {
        std::os::unix::fs::symlink(Path::new(DESK).join(sub), dir.path().join(sub)).unwrap();
    }
    for f in ["scene_brackets.toml", "scene.toml", "photo.exr"] {
        std::fs::copy(Path::new(DESK).join(f), dir.path().join(f)).unwrap();
    }
    let error = |file: &str| {
        let base = arlux::scene::Scene::load(dir.path().join(file)).unwrap();
        let scene = base.with_variant("box_floor_a").unwrap();
        let photo = scene.load_photo().unwrap();
        let out = render(
            &scene,
            &photo,
            &RenderSettings::default(),
            &mut StageTimes::default(),
        )
        .unwrap();
        let truth = read_image(&dir.path().join("truth/box_floor_a.exr")).unwrap();
        arlux::compare::compare(&out.composite.image, &truth, None).rmse
    };
    let exr = error("scene.toml");
    let merged = error("scene_brackets.toml");
    println!(
        "box_floor_a from photo.exr: RMSE {exr:.5}; from the brackets: {merged:.5} ({:+.0}%)",
        100.0 * (merged / exr - 1.0)
    );
    assert!(merged <= 1.25 * exr, "{merged} vs {exr}");
    let cached: Vec<String> = std::fs::read_dir(dir.path().join(".arlux-cache"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        cached.iter().any(|f| f.starts_with("merged-"))
            && cached.iter().any(|f| f.starts_with("scale-")),
        "{cached:?}"
    );
}

/// An 8×8 grey JPEG whose EXIF records an exposure time of num/den s.
fn jpeg_exposed(num: u32, den: u32) -> Vec<u8> {
    let img = image::GrayImage::from_pixel(8, 8, image::Luma([128]));
    let mut jpeg = std::io::Cursor::new(Vec::new());
    img.write_to(&mut jpeg, image::ImageFormat::Jpeg).unwrap();
    let jpeg = jpeg.into_inner();
    // TIFF: IFD0 points to the Exif IFD, which holds ExposureTime (RATIONAL).
    let mut tiff: Vec<u8> = b"II*\0".to_vec();
    tiff.extend(8u32.to_le_bytes());
    tiff.extend(1u16.to_le_bytes());
    tiff.extend([0x69, 0x87, 4, 0]);
    tiff.extend(1u32.to_le_bytes());
    tiff.extend(26u32.to_le_bytes());
    tiff.extend(0u32.to_le_bytes());
    tiff.extend(1u16.to_le_bytes());
    tiff.extend([0x9A, 0x82, 5, 0]);
    tiff.extend(1u32.to_le_bytes());
    tiff.extend(44u32.to_le_bytes());
    tiff.extend(0u32.to_le_bytes());
    tiff.extend(num.to_le_bytes());
    tiff.extend(den.to_le_bytes());
    let mut app1 = vec![0xFF, 0xE1];
    app1.extend(((2 + 6 + tiff.len()) as u16).to_be_bytes());
    app1.extend(b"Exif\0\0");
    app1.extend(tiff);
    jpeg[..2]
        .iter()
        .chain(&app1)
        .chain(&jpeg[2..])
        .copied()
        .collect()
}

#[test]
fn brackets_without_ev_take_it_from_their_exif_exposure_times() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(Path::new(DESK).join("scene_brackets.toml")).unwrap();
    let start = text.find("brackets = [").unwrap();
    let end = start + text[start..].find('\n').unwrap();
    let scene = format!(
        "{}brackets = [{{ image = \"a.jpg\" }}, {{ image = \"b.jpg\" }}, {{ image = \"c.jpg\" }}]{}",
        &text[..start],
        &text[end..]
    );
    std::fs::write(dir.path().join("scene.toml"), scene).unwrap();
    for (name, den) in [("a.jpg", 400), ("b.jpg", 100), ("c.jpg", 50)] {
        std::fs::write(dir.path().join(name), jpeg_exposed(1, den)).unwrap();
    }
    std::os::unix::fs::symlink(Path::new(DESK).join("truth"), dir.path().join("truth")).unwrap();
    std::fs::create_dir(dir.path().join("geometry")).unwrap();
    for f in ["room.obj", "furniture.obj", "box.obj"] {
        let from = Path::new(DESK).join("geometry").join(f);
        std::fs::copy(from, dir.path().join("geometry").join(f)).unwrap();
    }
    let loaded = arlux::scene::Scene::load(dir.path().join("scene.toml")).unwrap();
    let arlux::scene::Photo::Brackets(b) = &loaded.photo else {
        panic!("brackets expected")
    };
    let evs: Vec<f64> = b.iter().map(|b| b.ev).collect();
    // 1/400, 1/100 and 1/50 s: 0, 2 and 3 stops above the first.
    for (got, want) in evs.iter().zip([0.0, 2.0, 3.0]) {
        assert!((got - want).abs() < 1e-12, "{evs:?}");
    }
    // A JPEG without the time: the error names the bracket and the file.
    let bare = image::GrayImage::from_pixel(8, 8, image::Luma([128]));
    bare.save(dir.path().join("c.jpg")).unwrap();
    let e = arlux::scene::Scene::load(dir.path().join("scene.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("photo.brackets[2].ev") && e.contains("c.jpg"),
        "{e}"
    );
}
