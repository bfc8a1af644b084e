//! Property tests over every parser of user input (scene TOML, OBJ, glTF,
//! PLY, IES, EXR, COLMAP models, fSpy projects): whatever the bytes, a
//! parser returns a value or an error, never a panic or an abort. Each
//! input is a seed of the parser's corpus (`tests/fuzz_corpus/<parser>/`:
//! valid files covering the format, and inputs that once broke a parser)
//! mutated: bytes flipped, inserted, deleted, or the file cut. CI runs a few hundred cases per parser; a long run:
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

/// The seed files of one parser's corpus (`tests/fuzz_corpus/<parser>/`),
/// sorted by name: valid files covering the format's constructs, and the
/// inputs that once broke a parser.
fn corpus(parser: &str) -> Vec<(String, Vec<u8>)> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz_corpus")
        .join(parser);
    let mut seeds: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    seeds.sort();
    assert!(!seeds.is_empty(), "no seeds in {}", dir.display());
    seeds
}

/// A seed of `parser`'s corpus.
fn seed(parser: &'static str) -> impl Strategy<Value = Vec<u8>> {
    prop::sample::select(corpus(parser)).prop_map(|(_, bytes)| bytes)
}

/// A temporary copy of the desk whose `scene.toml` holds `bytes`, with the
/// IES file the corpus's scenes name.
fn desk_with_scene(bytes: &[u8]) -> common::Desk {
    let desk = common::Desk::new();
    std::fs::write(desk.path("scene.toml"), bytes).unwrap();
    let ies = corpus("ies")
        .into_iter()
        .find(|(n, _)| n == "type_c_tilt_none.ies")
        .unwrap();
    std::fs::write(desk.path("lamp.ies"), ies.1).unwrap();
    desk
}

fn read_ies(bytes: &[u8]) -> Result<arlux::ies::IesProfile, arlux::error::Error> {
    arlux::ies::IesProfile::parse(
        &String::from_utf8_lossy(bytes),
        std::path::Path::new("lamp.ies"),
    )
}

/// Writes `bytes` to a file `name` in a fresh folder and reads it with `read`.
fn read_as<T>(name: &str, bytes: &[u8], read: impl Fn(&std::path::Path) -> T) -> T {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    read(&path)
}

/// Seeds are only useful if the parser accepts them: every seed but the
/// recorded breakers (named `huge_*` or `broken_*`: inputs that once
/// crashed a parser, now refused with an error) parses.
#[test]
fn every_seed_but_the_recorded_breakers_parses() {
    for (name, bytes) in corpus("scene_toml") {
        let desk = desk_with_scene(&bytes);
        if let Err(e) = arlux::scene::Scene::load(desk.path("scene.toml")) {
            panic!("{name}: {e}");
        }
    }
    for (name, bytes) in corpus("obj") {
        read_as("mesh.obj", &bytes, arlux::geometry::load_obj)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    for kind in ["gltf", "ply"] {
        for (name, bytes) in corpus(kind) {
            let read = read_as(&name, &bytes, arlux::geometry::load_mesh);
            assert_eq!(
                read.is_ok(),
                !name.starts_with("broken_"),
                "{name}: {:?}",
                read.err()
            );
        }
    }
    for (name, bytes) in corpus("ies") {
        read_ies(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    for (name, bytes) in corpus("exr") {
        let read = read_as("photo.exr", &bytes, arlux::image_io::read_image);
        assert_eq!(
            read.is_ok(),
            !name.starts_with("huge_"),
            "{name}: {:?}",
            read.err()
        );
    }
}

/// A COLMAP model (`colmap_text` or `colmap_binary` corpus) in a fresh
/// folder, its file `mutated` (0: cameras, 1: images) edited; reads both
/// images it names.
fn read_colmap(kind: &str, mutated: usize, edits: &[Edit], token: &[u8]) -> Vec<bool> {
    let dir = tempfile::tempdir().unwrap();
    for (i, (name, bytes)) in corpus(kind).into_iter().enumerate() {
        let bytes = if i == mutated {
            apply(bytes, edits, token)
        } else {
            bytes
        };
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    ["photo.exr", "side view.jpg"]
        .iter()
        .map(|image| arlux::scene::calibration::from_colmap(dir.path(), image).is_ok())
        .collect()
}

/// The COLMAP models and the fSpy project of the corpus read.
#[test]
fn the_camera_seeds_read() {
    for kind in ["colmap_text", "colmap_binary"] {
        assert_eq!(read_colmap(kind, 2, &[], b""), [true, true], "{kind}");
    }
    for (name, bytes) in corpus("fspy") {
        let read = read_as("p.fspy", &bytes, arlux::scene::calibration::from_fspy);
        assert!(read.is_ok(), "{name}: {:?}", read.err());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn colmap_never_panics(binary in any::<bool>(), mutated in 0usize..2, edits in edits(), token in tokens()) {
        let kind = if binary { "colmap_binary" } else { "colmap_text" };
        let _ = read_colmap(kind, mutated, &edits, &token);
    }

    #[test]
    fn gltf_never_panics(seed in prop::sample::select(corpus("gltf")), edits in edits(), token in tokens()) {
        let (name, bytes) = seed;
        let _ = read_as(&name, &apply(bytes, &edits, &token), arlux::geometry::load_mesh);
    }

    #[test]
    fn ply_never_panics(seed in prop::sample::select(corpus("ply")), edits in edits(), token in tokens()) {
        let (name, bytes) = seed;
        let _ = read_as(&name, &apply(bytes, &edits, &token), arlux::geometry::load_mesh);
    }

    #[test]
    fn fspy_never_panics(bytes in seed("fspy"), edits in edits(), token in tokens()) {
        let _ = read_as("p.fspy", &apply(bytes, &edits, &token), arlux::scene::calibration::from_fspy);
    }

    #[test]
    fn scene_toml_never_panics(text in seed("scene_toml"), edits in edits(), token in tokens()) {
        let desk = desk_with_scene(&apply(text, &edits, &token));
        let _ = arlux::scene::Scene::load(desk.path("scene.toml"));
    }

    #[test]
    fn obj_never_panics(text in seed("obj"), edits in edits(), token in tokens()) {
        let _ = read_as("mesh.obj", &apply(text, &edits, &token), arlux::geometry::load_obj);
    }

    #[test]
    fn ies_never_panics(text in seed("ies"), edits in edits(), token in tokens()) {
        let _ = read_ies(&apply(text, &edits, &token));
    }

    #[test]
    fn exr_never_panics(bytes in seed("exr"), edits in header_edits(), token in tokens()) {
        let _ = read_as("photo.exr", &apply(bytes, &edits, &token), arlux::image_io::read_image);
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
