//! Latency of `arlux serve` per drag step: the time from a place request
//! to the new image being available to the page (the edit's reply, then the
//! tone-mapped image fetched), beside the update's own time as the session
//! reports it; the difference is what the server adds. Desk's box and
//! lounge's stool, dragged over the floor, and a light's slider moved on
//! `lounge` with the stool shown; median and 95th percentile.
//! `cargo bench --bench serve`.

#[path = "../tests/common/serve.rs"]
#[allow(dead_code)] // the tests' helpers this bench does not call
mod serve;

use std::path::Path;
use std::time::Instant;

use glam::DVec3;
use serde_json::json;

/// Copies a scene's files into `to` (its folders linked: a session writes
/// only beside its scene file).
fn copy_scene(name: &str, to: &Path) {
    let from = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name);
    for entry in std::fs::read_dir(&from).unwrap() {
        let e = entry.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            std::os::unix::fs::symlink(e.path(), target).unwrap();
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// One edit, awaited with its new image: the reply and the milliseconds
/// from the request to the image (None: the edit was refused).
fn edit(
    server: &serve::Server,
    path: &str,
    body: &serde_json::Value,
) -> Option<(serde_json::Value, f64)> {
    let start = Instant::now();
    let r = server.post(path, body);
    if r.status != 200 {
        return None;
    }
    let reply = r.json();
    let image = server.get("/api/image?view=final");
    assert_eq!(image.status, 200);
    Some((reply, start.elapsed().as_secs_f64() * 1e3))
}

/// Drags `object` in `steps` steps from `a` to `b` on the floor of scene `name`.
fn drag(name: &str, object: &str, a: DVec3, b: DVec3, steps: usize) {
    let dir = tempfile::tempdir().unwrap();
    copy_scene(name, dir.path());
    let file = dir.path().join("scene.toml");
    let scene = arlux::scene::Scene::load(&file).unwrap();
    let server = serve::Server::start(file.to_str().unwrap(), &[]);
    server.wait_ready();
    let (mut total, mut update, mut server_ms) = (vec![], vec![], vec![]);
    let mut refused = 0;
    // The first steps build the pixel-block hierarchy: left out.
    let warm = 3;
    for k in 0..steps + warm {
        let f = (k % steps) as f64 / steps as f64;
        let (x, y, _) = scene.camera.project(a.lerp(b, f)).unwrap();
        let body = json!({ "object": object, "x": x, "y": y });
        let Some((reply, ms)) = edit(&server, "/api/place", &body) else {
            // A step over what the object cannot stand on (a table's edge).
            refused += 1;
            continue;
        };
        if k >= warm {
            total.push(ms);
            update.push(reply["update_ms"].as_f64().unwrap());
            server_ms.push(reply["server_ms"].as_f64().unwrap());
        }
    }
    let added: Vec<f64> = total.iter().zip(&update).map(|(t, u)| t - u).collect();
    let row = |label: &str, v: &[f64]| {
        let mut v = v.to_vec();
        println!(
            "{name:<7} {label:<34} median {:>7.1} ms   p95 {:>7.1} ms",
            percentile(&mut v, 0.5),
            percentile(&mut v, 0.95)
        );
    };
    assert!(
        total.len() >= steps / 2,
        "{refused} of {steps} steps refused"
    );
    println!(
        "{name}: {} drag steps of '{object}' ({refused} refused: off the floor)",
        total.len()
    );
    row("request → image available", &total);
    row("update (the session's own time)", &update);
    row("added by the server", &added);
    row("request → reply (inside the server)", &server_ms);
}

/// Moves `light`'s slider in `steps` steps between 1.2 and 2.0 on scene
/// `name` as its file has it. The first two moves are left
/// out: the first renders in full (the room meshed for light changes), the
/// second solves the room and the objects' change per light (the moves
/// come back to back: the session, never idle, does not solve them ahead).
fn slide(name: &str, light: &str, steps: usize) {
    let dir = tempfile::tempdir().unwrap();
    copy_scene(name, dir.path());
    let file = dir.path().join("scene.toml");
    let server = serve::Server::start(file.to_str().unwrap(), &[]);
    server.wait_ready();
    let (mut total, mut update, mut kinds) = (vec![], vec![], Vec::new());
    let warm = 2;
    for k in 0..steps + warm {
        let scale = 1.2 + 0.8 * (k % 5) as f64 / 4.0;
        let body = json!({ "light": light, "scale": scale });
        let (reply, ms) = edit(&server, "/api/light", &body).expect("the slider's edit refused");
        if k >= warm {
            total.push(ms);
            update.push(reply["update_ms"].as_f64().unwrap());
            kinds.push(reply["path"]["kind"].as_str().unwrap_or("").to_string());
        } else {
            println!(
                "{name}: '{light}' to {scale}: {:?} in {ms:.0} ms",
                reply["path"]["kind"]
            );
        }
    }
    let relit = kinds.iter().filter(|k| *k == "relight").count();
    println!(
        "{name}: {} steps of '{light}''s slider ({relit} relit)",
        total.len()
    );
    for (label, v) in [
        ("request → image available", &total),
        ("relight (the session's own time)", &update),
    ] {
        let mut v = v.to_vec();
        println!(
            "{name:<7} {label:<34} median {:>7.1} ms   p95 {:>7.1} ms",
            percentile(&mut v, 0.5),
            percentile(&mut v, 0.95)
        );
    }
}

fn main() {
    // `cargo test --benches` runs benches with --bench absent: one short pass.
    let steps = if std::env::args().any(|a| a == "--bench") {
        60
    } else {
        5
    };
    drag(
        "desk",
        "box",
        DVec3::new(-1.2, 0.0, 0.8),
        DVec3::new(0.8, 0.0, -0.2),
        steps,
    );
    drag(
        "lounge",
        "stool",
        DVec3::new(-1.8, 0.0, -1.2),
        DVec3::new(-0.2, 0.0, 0.9),
        steps,
    );
    slide("lounge", "panel_2", steps);
}
