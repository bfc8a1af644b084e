use super::*;
use crate::image_io::{ExrLayer, ExrMeta, Image, write_exr_with};

/// A frame whose every sample differs, with a second layer.
fn frame(w: u32, h: u32) -> (Image, Vec<f32>) {
    let mut img = Image::new(w, h);
    for (i, p) in img.pixels.iter_mut().enumerate() {
        let v = i as f32;
        *p = glam::Vec3::new(v.sin(), 0.5 * v, (v * 0.37).cos() + 2.0);
    }
    let alpha = (0..w * h).map(|i| (i % 7) as f32 / 7.0).collect();
    (img, alpha)
}

/// The window's rows `y0..y1` of every channel, in `stream`'s order.
fn planes(
    img: &Image,
    alpha: &[f32],
    window: PixelRect,
    y0: u32,
    y1: u32,
    names: &[String],
) -> Vec<Vec<f32>> {
    names
        .iter()
        .map(|name| {
            let mut out = Vec::new();
            for y in window.y0 + y0..window.y0 + y1 {
                for x in window.x0..window.x1 {
                    let i = (y * img.width + x) as usize;
                    out.push(match name.as_str() {
                        "R" => img.pixels[i].x,
                        "G" => img.pixels[i].y,
                        "B" => img.pixels[i].z,
                        _ => alpha[i],
                    });
                }
            }
            out
        })
        .collect()
}

#[test]
fn bands_of_any_height_write_the_bytes_of_a_whole_write() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (150, 203);
    let (img, alpha) = frame(w, h);
    let names: Vec<String> = ["R", "G", "B", "A"].map(String::from).to_vec();
    for window in [
        None,
        Some(PixelRect {
            x0: 7,
            y0: 30,
            x1: 140,
            y1: 200,
        }),
    ] {
        let meta = ExrMeta {
            window,
            arlux: Some("{\"scene\":\"t\"}".into()),
            ..ExrMeta::default()
        };
        let whole = dir.path().join("whole.exr");
        let layers = [ExrLayer::Rgb("", &img), ExrLayer::Channel("A", &alpha)];
        write_exr_with(&whole, w, h, &layers, &meta).unwrap();
        let r = window.unwrap_or(PixelRect::full(w, h));
        for bands in [
            vec![r.height()],
            vec![64, 64, r.height() - 128],
            vec![1, 90, 13, r.height() - 104],
        ] {
            let path = dir.path().join("stream.exr");
            let mut s = ExrStream::create(&path, w, h, &names, &meta).unwrap();
            let order = s.channels().to_vec();
            let mut y = 0;
            for rows in bands {
                s.push(rows, planes(&img, &alpha, r, y, y + rows, &order))
                    .unwrap();
                y += rows;
            }
            s.finish().unwrap();
            assert_eq!(
                std::fs::read(&path).unwrap(),
                std::fs::read(&whole).unwrap()
            );
        }
    }
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 2, "no temporary left: {left:?}");
}

#[test]
fn an_unfinished_stream_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.exr");
    let names = vec!["R".to_string()];
    let mut s = ExrStream::create(&path, 64, 100, &names, &ExrMeta::default()).unwrap();
    s.push(64, vec![vec![1.0; 64 * 64]]).unwrap();
    let err = s.finish().unwrap_err().to_string();
    assert!(err.contains("64 of 100 rows"), "{err}");
    let s = ExrStream::create(&path, 64, 100, &names, &ExrMeta::default()).unwrap();
    drop(s);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}
