//! Property tests over every parser of user input: whatever the bytes, a
//! parser returns a value or an error, never a panic or an abort. Each
//! input is a valid file mutated (bytes flipped, inserted, deleted, lines
//! cut) or noise. CI runs a few hundred cases per parser; a long run:
//! `ARLUX_FUZZ_CASES=200000 cargo test --release --test fuzz_parsers`
//! (see docs/CONTRIBUTING.md). Failing cases proptest finds are kept in
//! `tests/fuzz_parsers.proptest-regressions` and replayed first.

mod common;

use proptest::prelude::*;

fn cases() -> u32 {
    std::env::var("ARLUX_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(256)
}

/// An edit of a byte string: flip, insert, delete, or cut at a position.
#[derive(Debug, Clone)]
enum Edit {
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Cut(usize),
}

fn edits() -> impl Strategy<Value = Vec<Edit>> {
    let edit = prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Flip(i, b)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..12))
            .prop_map(|(i, b)| Edit::Insert(i, b)),
        (any::<usize>(), 1usize..40).prop_map(|(i, n)| Edit::Delete(i, n)),
        any::<usize>().prop_map(Edit::Cut),
    ];
    prop::collection::vec(edit, 1..6)
}

/// Tokens that parsers treat specially, so that mutations reach past the
/// first syntax check.
fn tokens() -> impl Strategy<Value = Vec<u8>> {
    prop::sample::select(vec![
        "nan",
        "inf",
        "-1e300",
        "1e39",
        "0",
        "-0",
        "1e15",
        "\n",
        "=",
        "[",
        "]",
        "{",
        "}",
        "\"",
        "/",
        "f ",
        "v ",
        "vn ",
        "vt ",
        "o ",
        "g ",
        "-1",
        "999999999999",
        "TILT=",
        "INCLUDE",
        "\u{fffd}",
    ])
    .prop_map(|s| s.as_bytes().to_vec())
}

fn apply(mut bytes: Vec<u8>, edits: &[Edit], token: &[u8]) -> Vec<u8> {
    for e in edits {
        let n = bytes.len().max(1);
        match e {
            Edit::Flip(i, b) => {
                if !bytes.is_empty() {
                    bytes[i % n] = *b;
                }
            }
            Edit::Insert(i, b) => {
                let at = i % (bytes.len() + 1);
                let what = if b[0] % 2 == 0 {
                    token.to_vec()
                } else {
                    b.clone()
                };
                bytes.splice(at..at, what);
            }
            Edit::Delete(i, len) => {
                let at = i % n;
                let end = (at + len).min(bytes.len());
                if at < end {
                    bytes.drain(at..end);
                }
            }
            Edit::Cut(i) => bytes.truncate(i % n),
        }
    }
    bytes
}

/// A temporary copy of the desk whose `file` holds `bytes`.
fn desk_with(file: &str, bytes: &[u8]) -> common::Desk {
    let desk = common::Desk::new();
    std::fs::write(desk.path(file), bytes).unwrap();
    desk
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn scene_toml_never_panics(edits in edits(), token in tokens()) {
        let text = std::fs::read(common::scene_dir("desk").join("scene.toml")).unwrap();
        let desk = desk_with("scene.toml", &apply(text, &edits, &token));
        let _ = arlux::scene::Scene::load(desk.path("scene.toml"));
    }

    #[test]
    fn obj_never_panics(edits in edits(), token in tokens()) {
        let text = std::fs::read(common::scene_dir("desk").join("geometry/furniture.obj")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mesh.obj");
        std::fs::write(&path, apply(text, &edits, &token)).unwrap();
        let _ = arlux::geometry::load_obj(&path);
    }

    #[test]
    fn ies_never_panics(edits in edits(), token in tokens()) {
        let text = IES.as_bytes().to_vec();
        let bytes = apply(text, &edits, &token);
        let _ = arlux::ies::IesProfile::parse(&String::from_utf8_lossy(&bytes), std::path::Path::new("lamp.ies"));
    }

    #[test]
    fn exr_never_panics(edits in header_edits(), token in tokens()) {
        let bytes = small_exr();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("photo.exr");
        std::fs::write(&path, apply(bytes, &edits, &token)).unwrap();
        let _ = arlux::image_io::read_image(&path);
    }
}

/// Edits within an EXR's header (its first few hundred bytes), where a
/// reader decides how much to allocate and where to look.
fn header_edits() -> impl Strategy<Value = Vec<Edit>> {
    edits().prop_map(|es| {
        es.into_iter()
            .map(|e| match e {
                Edit::Flip(i, b) => Edit::Flip(i % 400, b),
                Edit::Insert(i, b) => Edit::Insert(i % 400, b),
                Edit::Delete(i, n) => Edit::Delete(i % 400, n),
                Edit::Cut(i) => Edit::Cut(i),
            })
            .collect()
    })
}

/// A 16×8 RGB EXR.
fn small_exr() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("small.exr");
    let mut img = arlux::image_io::Image::new(16, 8);
    for (i, p) in img.pixels.iter_mut().enumerate() {
        *p = glam::Vec3::splat(i as f32 / 128.0);
    }
    arlux::image_io::write_exr(&path, 16, 8, &[arlux::image_io::ExrLayer::Rgb("", &img)]).unwrap();
    std::fs::read(&path).unwrap()
}

const IES: &str = "IESNA:LM-63-2002
[TEST] T-1
[MANUFAC] arlux
TILT=NONE
1 -1 1 3 2 1 2 0.1 0.1 0
1 1 100
0 45 90
0 90
100 80 20
100 70 10
";
