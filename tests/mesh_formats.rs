//! A glTF and a PLY export of the desk's room render the desk exactly as
//! its OBJ does, bit for bit.

mod common;

use arlux::geometry::load_obj;

fn render(desk: &common::Desk) -> Vec<u8> {
    let out = desk.path("out.exr");
    common::render_box_floor_a(desk, &out);
    std::fs::read(out).unwrap()
}

#[test]
fn gltf_and_ply_exports_of_the_room_render_as_the_obj_does() {
    let obj = common::Desk::new();
    let expected = render(&obj);
    let room = load_obj(&obj.path("geometry/room.obj")).unwrap();

    // glTF: one node and mesh per surface, positions in a .bin beside it.
    let gltf = common::Desk::new();
    let (mut bin, mut nodes, mut meshes, mut accessors, mut views) =
        (Vec::new(), vec![], vec![], vec![], vec![]);
    for (i, s) in room.surfaces.iter().enumerate() {
        let offset = bin.len();
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in s.triangles.iter().flatten() {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
                bin.extend(p[c].to_le_bytes());
            }
        }
        let count = s.triangles.len() * 3;
        views.push(
            serde_json::json!({ "buffer": 0, "byteOffset": offset, "byteLength": count * 12 }),
        );
        accessors.push(serde_json::json!({ "bufferView": i, "componentType": 5126, "count": count, "type": "VEC3", "min": lo, "max": hi }));
        meshes.push(serde_json::json!({ "primitives": [{ "attributes": { "POSITION": i } }] }));
        nodes.push(serde_json::json!({ "name": s.name, "mesh": i }));
    }
    let doc = serde_json::json!({
        "asset": { "version": "2.0" },
        "scene": 0, "scenes": [{ "nodes": (0..nodes.len()).collect::<Vec<_>>() }],
        "nodes": nodes, "meshes": meshes, "accessors": accessors, "bufferViews": views,
        "buffers": [{ "uri": "room.bin", "byteLength": bin.len() }],
    });
    std::fs::write(gltf.path("geometry/room.bin"), &bin).unwrap();
    std::fs::write(gltf.path("geometry/room.gltf"), doc.to_string()).unwrap();
    gltf.edit("scene.toml", "geometry/room.obj", "geometry/room.gltf");
    assert!(
        render(&gltf) == expected,
        "the glTF room renders differently"
    );

    // PLY: one ASCII file per surface (PLY names no objects: the file's stem does).
    let ply = common::Desk::new();
    let mut reals = String::new();
    for s in &room.surfaces {
        let mut text = format!(
            "ply\nformat ascii 1.0\ncomment exported from room.obj\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
            s.triangles.len() * 3,
            s.triangles.len()
        );
        for p in s.triangles.iter().flatten() {
            text.push_str(&format!("{:?} {:?} {:?}\n", p.x, p.y, p.z));
        }
        for t in 0..s.triangles.len() {
            text.push_str(&format!("3 {} {} {}\n", 3 * t, 3 * t + 1, 3 * t + 2));
        }
        std::fs::write(ply.path(&format!("geometry/{}.ply", s.name)), text).unwrap();
        reals.push_str(&format!("[[real]]\nmesh = \"geometry/{}.ply\"\n\n", s.name));
    }
    ply.edit(
        "scene.toml",
        "[[real]]\nmesh = \"geometry/room.obj\"\n\n",
        &reals,
    );
    assert!(render(&ply) == expected, "the PLY room renders differently");
}

#[test]
fn a_broken_gltf_or_ply_names_its_file() {
    let desk = common::Desk::new();
    std::fs::write(
        desk.path("geometry/room.ply"),
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0.5\n",
    )
    .unwrap();
    desk.edit("scene.toml", "geometry/room.obj", "geometry/room.ply");
    let run = common::arlux(&["info", &desk.scene()]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("room.ply") && stderr.contains("real[1].mesh"),
        "{stderr}"
    );
    let desk = common::Desk::new();
    std::fs::write(desk.path("geometry/room.gltf"), "{ \"asset\": {} }").unwrap();
    desk.edit("scene.toml", "geometry/room.obj", "geometry/room.gltf");
    let run = common::arlux(&["info", &desk.scene()]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("room.gltf: malformed glTF"), "{stderr}");
    // Inputs that once made the glTF reader panic: an error, no backtrace.
    for seed in ["broken_float_indices.gltf", "broken_position_accessor.gltf"] {
        let desk = common::Desk::new();
        let corpus =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_corpus/gltf");
        std::fs::copy(corpus.join(seed), desk.path("geometry/room.gltf")).unwrap();
        desk.edit("scene.toml", "geometry/room.obj", "geometry/room.gltf");
        let run = common::arlux(&["info", &desk.scene()]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{seed}: {stderr}");
        assert!(
            stderr.contains("malformed glTF") && !stderr.contains("panicked"),
            "{seed}: {stderr}"
        );
    }
}
