//! The API of `arlux serve` under bad input: 2,000 random and malformed
//! requests (bad JSON, wrong types, unknown names, out-of-range and huge
//! numbers, unknown fields and paths, oversized bodies, missing tokens,
//! foreign origins, garbage bytes) are each refused with a well-formed
//! reply, the server stays up, and its state renders the same image as
//! before them. Then drags queued behind a slow full render are coalesced:
//! the latest wins.

mod common;
use common::Desk;
use common::serve::{Reply, Server, crate_folder, light_in};

use std::io::{Read as _, Write as _};
use std::time::Duration;

use rand::{RngExt, SeedableRng};
use serde_json::{Value, json};

fn validator() -> jsonschema::Validator {
    let file = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/schema/serve.schema.json");
    let schema: Value = serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    jsonschema::validator_for(&schema).unwrap()
}

/// A request that must be refused, drawn at random.
fn bad_request(rng: &mut impl rand::Rng) -> (&'static str, Vec<u8>) {
    let numbers = [
        json!(1e308),
        json!(-1e308),
        json!(-1),
        json!(1e9),
        json!("NaN"),
        json!(null),
        json!([1, 2]),
        json!({"x": 1}),
        json!(true),
        json!(""),
    ];
    let number = |rng: &mut dyn rand::Rng| numbers[rng.random_range(0..numbers.len())].clone();
    let name = |rng: &mut dyn rand::Rng| {
        ["nobody", "", "box ", "BOX", "../scene.toml", "panel"][rng.random_range(0..6)]
    };
    match rng.random_range(0..12) {
        0 => (
            "/api/place",
            json!({ "object": "box", "x": number(rng), "y": 100 })
                .to_string()
                .into_bytes(),
        ),
        1 => (
            "/api/place",
            json!({ "object": name(rng), "x": 100, "y": 200 })
                .to_string()
                .into_bytes(),
        ),
        2 => (
            "/api/place",
            json!({ "object": "box", "x": 100, "y": 200, "z": 1 })
                .to_string()
                .into_bytes(),
        ),
        3 => (
            "/api/object",
            json!({ "object": "box", "scale": number(rng) })
                .to_string()
                .into_bytes(),
        ),
        4 => {
            // -1° is a valid heading: the others are not.
            let yaw = Some(number(rng))
                .filter(|n| n != &json!(-1))
                .unwrap_or(json!(1e5));
            (
                "/api/object",
                json!({ "object": "box", "yaw_deg": yaw })
                    .to_string()
                    .into_bytes(),
            )
        }
        5 => (
            "/api/object",
            json!({ "object": "box", "yaw_deg": 10, "scale": 2 })
                .to_string()
                .into_bytes(),
        ),
        6 => {
            let light = ["nobody", "", "panel ", "PANEL", "box"][rng.random_range(0..5)];
            (
                "/api/light",
                json!({ "light": light, "scale": 1 })
                    .to_string()
                    .into_bytes(),
            )
        }
        7 => (
            "/api/light",
            json!({ "light": "panel", "scale": number(rng) })
                .to_string()
                .into_bytes(),
        ),
        8 => {
            let bad = ["../x", "a b", "", "box_floor_a", "é"][rng.random_range(0..5)];
            ("/api/save", json!({ "name": bad }).to_string().into_bytes())
        }
        9 => {
            // Truncated or random bytes as JSON.
            let text = json!({ "object": "box", "x": 100, "y": 200 }).to_string();
            let cut = rng.random_range(0..text.len());
            let mut b = text.into_bytes()[..cut].to_vec();
            if rng.random_bool(0.5) {
                b.extend((0..rng.random_range(1..40)).map(|_| rng.random::<u8>()));
            }
            (
                ["/api/place", "/api/object", "/api/light"][rng.random_range(0..3)],
                b,
            )
        }
        10 => ("/api/place", vec![b'['; 20_000]),
        _ => (
            ["/api/nothing", "/api/../scene.toml", "/api/image/x"][rng.random_range(0..3)],
            b"{}".to_vec(),
        ),
    }
}

/// Raw bytes on a new connection; the status line of the reply, if any.
fn raw(server: &Server, bytes: &[u8]) -> Option<String> {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", server.port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let _ = s.write_all(bytes);
    let _ = s.shutdown(std::net::Shutdown::Write);
    let mut reply = Vec::new();
    let _ = s.read_to_end(&mut reply);
    let text = String::from_utf8_lossy(&reply);
    text.lines().next().map(str::to_string)
}

fn check_refused(r: &Reply, what: &str, validator: &jsonschema::Validator) {
    assert!(
        (400..500).contains(&r.status),
        "{what}: status {}",
        r.status
    );
    let body = r.json();
    assert!(
        validator.is_valid(&body),
        "{what}: reply off the schema: {body}"
    );
    assert!(body["error"]["field"].is_string(), "{what}: {body}");
}

#[test]
fn two_thousand_bad_requests_are_refused_and_change_nothing() {
    let desk = Desk::new();
    let mut server = Server::start(&desk.scene(), &[]);
    let validator = validator();
    let ready = server.wait_ready();
    assert!(validator.is_valid(&ready), "{ready}");
    let (before, version) = server.linear();
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let mut counts = std::collections::BTreeMap::<u16, usize>::new();
    for k in 0..2000 {
        let r = match k % 10 {
            // Without the token, or from a foreign page.
            0 => server.post_raw("/api/place", br#"{"object":"box","x":100,"y":300}"#, false),
            1 => {
                let line = raw(
                    &server,
                    format!(
                        "POST /api/light HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nOrigin: http://evil.example\r\nx-arlux-token: {}\r\nContent-Length: 30\r\n\r\n{{\"light\":\"panel\",\"scale\":0.0}}",
                        server.port, server.token
                    )
                    .as_bytes(),
                );
                assert!(
                    line.as_deref().is_some_and(|l| l.contains(" 403 ")),
                    "{line:?}"
                );
                continue;
            }
            2 => {
                // Garbage where HTTP should be: refused or closed, never a crash.
                let junk: Vec<u8> = (0..rng.random_range(1..200))
                    .map(|_| rng.random())
                    .collect();
                if let Some(line) = raw(&server, &junk) {
                    assert!(line.starts_with("HTTP/1.1 4"), "{line:?}");
                }
                continue;
            }
            _ => {
                let (path, body) = bad_request(&mut rng);
                server.post_raw(path, &body, true)
            }
        };
        *counts.entry(r.status).or_default() += 1;
        check_refused(
            &r,
            &format!("request {k} ({})", String::from_utf8_lossy(&r.body)),
            &validator,
        );
        // Within the rate the server allows.
        std::thread::sleep(Duration::from_millis(3));
    }
    println!("replies by status: {counts:?}");
    assert!(server.alive(), "the server is still up");
    let (after, version_after) = server.linear();
    assert_eq!(version_after, version, "no bad request changed the state");
    assert!(
        before
            .iter()
            .zip(&after)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "the image is the one before the bad requests"
    );
    // And it still works: a good edit goes through.
    let r = server.post("/api/object", &json!({ "object": "box", "yaw_deg": 45.0 }));
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert!(validator.is_valid(&r.json()), "{}", r.json());
}

#[test]
fn drags_queued_behind_an_update_are_coalesced_the_latest_winning() {
    let desk = Desk::new();
    let server = std::sync::Arc::new(Server::start(&desk.scene(), &[]));
    server.wait_ready();
    let scene = arlux::scene::Scene::load(desk.scene()).unwrap();
    // A virtual light switched on is a full render (its terms were never
    // traced): the drags sent meanwhile queue up.
    let slow = {
        let s = std::sync::Arc::clone(&server);
        std::thread::spawn(move || s.post("/api/light", &json!({ "light": "bulb", "scale": 2.0 })))
    };
    std::thread::sleep(Duration::from_millis(50));
    let points: Vec<(f64, f64)> = (0..8)
        .map(|k| {
            let p = glam::DVec3::new(-0.8 + 0.15 * k as f64, 0.0, 0.5);
            let (x, y, _) = scene.camera.project(p).unwrap();
            (x, y)
        })
        .collect();
    let mut moves = Vec::new();
    for &(x, y) in &points {
        let s = std::sync::Arc::clone(&server);
        moves.push(std::thread::spawn(move || {
            s.post(
                "/api/place",
                &json!({ "object": "box", "x": x, "y": y, "drag": true }),
            )
        }));
        std::thread::sleep(Duration::from_millis(15));
    }
    assert_eq!(slow.join().unwrap().status, 200);
    let replies: Vec<Value> = moves
        .into_iter()
        .map(|m| m.join().unwrap().json())
        .collect();
    let superseded = replies.iter().filter(|r| r["superseded"] == true).count();
    println!("{superseded} of {} moves superseded", replies.len());
    assert!(
        superseded >= 1,
        "moves queued behind a render are coalesced: {replies:?}"
    );
    assert!(
        replies.last().unwrap()["superseded"].is_null(),
        "the latest move wins"
    );
    let state = server.get("/api/state").json();
    let t: Vec<f64> = state["objects"][0]["translate"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let (x, y, _) = scene
        .camera
        .project(glam::DVec3::new(t[0], t[1], t[2]))
        .unwrap();
    let last = points.last().unwrap();
    assert!(
        (x - last.0).abs() < 40.0 && (y - last.1).abs() < 40.0,
        "the box is near the last move's point: {x:.0},{y:.0} against {last:?}"
    );
}

#[test]
fn with_samples_the_image_refines_after_an_edit_and_the_next_edit_starts_again() {
    let validator = validator();
    let desk = Desk::new();
    let server = Server::start(&desk.scene(), &["--samples", "4"]);
    server.wait_ready();
    let wait_refined = |rounds: u64| {
        for _ in 0..200 {
            let s = server.get("/api/state").json();
            assert!(validator.is_valid(&s), "{s}");
            assert_eq!(s["refined"]["target"], 4);
            if s["refined"]["rounds"] == rounds {
                return s;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        panic!("the image did not reach {rounds} rounds");
    };
    let (plain, version) = server.linear();
    let refined = wait_refined(4);
    assert!(refined["refined"]["noise_rms"].as_f64().unwrap() > 0.0);
    let (image, same_version) = server.linear();
    assert_eq!(same_version, version, "refining is not an edit");
    assert!(
        plain.iter().zip(&image).any(|(a, b)| a != b),
        "the refined image differs from the first"
    );
    // An edit: its reply is the session's own image again, then it refines.
    let r = server.post("/api/object", &json!({ "object": "box", "yaw_deg": 30.0 }));
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert!(validator.is_valid(&r.json()), "{}", r.json());
    assert_eq!(r.json()["state"]["refined"]["rounds"], 0, "{}", r.json());
    wait_refined(4);
}

#[test]
fn requests_without_the_token_cannot_use_up_the_users_rate() {
    let desk = Desk::new();
    let server = std::sync::Arc::new(Server::start(&desk.scene(), &[]));
    server.wait_ready();
    // Eight threads sending requests without the token, as fast as they
    // go, until 10,000 have been sent; the user edits meanwhile.
    let sent = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let floods: Vec<_> = (0..8)
        .map(|_| {
            let (s, sent) = (std::sync::Arc::clone(&server), std::sync::Arc::clone(&sent));
            std::thread::spawn(move || {
                let request = format!(
                    "POST /api/object HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nContent-Type: application/json\r\nContent-Length: 30\r\n\r\n{{\"object\":\"box\",\"yaw_deg\":10}}",
                    s.port
                );
                while sent.load(std::sync::atomic::Ordering::Relaxed) < 10_000 {
                    let line = raw(&s, request.as_bytes());
                    assert!(line.as_deref().is_some_and(|l| l.contains(" 401 ")), "{line:?}");
                    sent.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let (mut edits, mut refused) = (0, 0);
    while edits < 40 || sent.load(std::sync::atomic::Ordering::Relaxed) < 10_000 {
        let r = server.post(
            "/api/object",
            &json!({ "object": "box", "yaw_deg": (edits % 90) as f64 }),
        );
        if r.status == 429 {
            refused += 1;
        } else {
            assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
        }
        edits += 1;
    }
    for t in floods {
        t.join().unwrap();
    }
    let sent = sent.load(std::sync::atomic::Ordering::Relaxed);
    println!("{sent} requests without the token during {edits} edits");
    assert!(sent >= 10_000, "the flood sent only {sent}");
    assert_eq!(
        refused, 0,
        "{refused} of {edits} edits were refused for the rate"
    );
    // A declared body beyond the limit, one byte of it sent and the
    // connection left open: refused at once, not awaited.
    let mut s = std::net::TcpStream::connect(("127.0.0.1", server.port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    s.write_all(
        format!(
            "POST /api/light HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nx-arlux-token: {}\r\nContent-Type: application/json\r\nContent-Length: 999999999\r\n\r\n{{",
            server.port, server.token
        )
        .as_bytes(),
    )
    .unwrap();
    let mut reply = [0u8; 64];
    let n = s.read(&mut reply).expect("a reply within 3 s");
    let line = String::from_utf8_lossy(&reply[..n]).into_owned();
    assert!(line.starts_with("HTTP/1.1 413"), "{line:?}");
}

#[test]
fn half_sent_requests_neither_block_the_user_nor_stay_open() {
    let desk = Desk::new();
    let server = Server::start(&desk.scene(), &[]);
    server.wait_ready();
    // 2,000 connections, each with half a request's headers, left open.
    let mut open: Vec<std::net::TcpStream> = (0..2000)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(("127.0.0.1", server.port)).unwrap();
            s.write_all(b"GET /api/state HTTP/1.1\r\nHost: 127.0")
                .unwrap();
            s
        })
        .collect();
    let t0 = std::time::Instant::now();
    let r = server.get("/api/state");
    let took = t0.elapsed();
    assert_eq!(r.status, 200);
    assert!(took < Duration::from_secs(1), "answered in {took:?}");
    // Within the header timeout (10 s) each of them is closed.
    std::thread::sleep(Duration::from_secs(11));
    let closed = (open.iter_mut())
        .map(|s| {
            s.set_read_timeout(Some(Duration::from_millis(200)))
                .unwrap();
            let mut buf = [0u8; 256];
            // A close reads as the end (after a 408, if one is sent); a
            // connection still open times out instead.
            loop {
                match s.read(&mut buf) {
                    Ok(0) => return true,
                    Ok(_) => continue,
                    Err(e) => return e.kind() == std::io::ErrorKind::ConnectionReset,
                }
            }
        })
        .filter(|c| *c)
        .count();
    assert_eq!(
        closed,
        2000,
        "{} of 2000 half-sent connections still open",
        2000 - closed
    );
}

#[test]
fn binding_every_address_needs_the_names_other_machines_use() {
    let desk = Desk::new();
    common::arlux_refused(
        &["serve", &desk.scene(), "--port", "0", "--bind", "0.0.0.0"],
        &["--bind 0.0.0.0", "--allow-host"],
    );
    common::arlux_refused(
        &[
            "serve",
            &desk.scene(),
            "--port",
            "0",
            "--bind",
            "0.0.0.0",
            "--allow-host",
            "a b",
        ],
        &["--allow-host 'a b'"],
    );
    let server = Server::start(
        &desk.scene(),
        &["--bind", "0.0.0.0", "--allow-host", "studio.local"],
    );
    server.wait_ready();
    let ask = |host: &str| {
        raw(
            &server,
            format!(
                "GET /api/state HTTP/1.1\r\nHost: {host}:{}\r\nx-arlux-token: {}\r\nConnection: close\r\n\r\n",
                server.port, server.token
            )
            .as_bytes(),
        )
        .unwrap_or_default()
    };
    assert!(
        ask("studio.local").contains(" 200 "),
        "{}",
        ask("studio.local")
    );
    assert!(ask("127.0.0.1").contains(" 200 "));
    assert!(ask("elsewhere.example").contains(" 403 "));
}

/// One truth across tabs: an edit or a save made on a version another page
/// has changed since is refused (409) with the state as it is; the page's
/// own edits in flight are not; an edit without a version is not checked.
#[test]
fn an_edit_made_on_a_state_another_page_changed_is_refused_with_the_new_state() {
    let desk = Desk::new();
    let server = Server::start(&desk.scene(), &[]);
    let v0 = server.wait_ready()["version"].as_u64().unwrap();
    let light = |scale: f64, version: u64, client: &str| {
        server.post(
            "/api/light",
            &json!({ "light": "spot", "scale": scale, "version": version, "client": client }),
        )
    };
    // Tab a edits; tab b, still on v0, is refused and given a's state.
    assert_eq!(light(1.5, v0, "tab-a").status, 200);
    let refused = light(0.5, v0, "tab-b");
    assert_eq!(refused.status, 409);
    let body = refused.json();
    assert_eq!(body["error"]["field"], "version");
    assert_eq!(body["state"]["version"].as_u64(), Some(v0 + 1));
    let spot = |state: &Value| light_in(state, "spot")["scale"].as_f64().unwrap();
    assert_eq!(spot(&body["state"]), 1.5, "the refusal carries a's state");
    assert_eq!(
        spot(&server.get("/api/state").json()),
        1.5,
        "b's edit changed nothing"
    );
    // Tab a's next edit sent before its first reply (still stamped v0) is its own.
    assert_eq!(light(1.25, v0, "tab-a").status, 200);
    // b's save on the state it has not seen is refused too; on the new one, b may edit.
    let save = server.post("/api/save", &json!({ "version": v0, "client": "tab-b" }));
    assert_eq!(save.status, 409, "{}", String::from_utf8_lossy(&save.body));
    let now = server.get("/api/state").json()["version"].as_u64().unwrap();
    assert_eq!(light(0.5, now, "tab-b").status, 200);
    // Unstamped (curl, scripts): applied as before.
    let plain = server.post("/api/light", &json!({ "light": "spot", "scale": 1.0 }));
    assert_eq!(plain.status, 200);
}

/// Undo and redo over every edit: a drag's moves are one step; undoing
/// every step gives back the first image bit for bit, redoing them the
/// last; a new edit clears what redo had; nothing to undo is a 422.
#[test]
fn undo_and_redo_step_through_the_edits_and_give_back_their_images() {
    let desk = Desk::new();
    let server = Server::start(&desk.scene(), &[]);
    let first = server.wait_ready();
    assert_eq!(first["history"], json!({ "undo": 0, "redo": 0 }));
    let (image0, _) = server.linear();
    let scene = arlux::scene::Scene::load(desk.scene()).unwrap();
    let at = |x: f64, z: f64| {
        let (px, py, _) = scene.camera.project(glam::DVec3::new(x, 0.0, z)).unwrap();
        (px, py)
    };
    let ok = |path: &str, body: Value| {
        let r = server.post(path, &body);
        assert_eq!(
            r.status,
            200,
            "{path}: {}",
            String::from_utf8_lossy(&r.body)
        );
        r.json()
    };
    // A click, a turn, then a click-and-drag (its moves one step with
    // the click), a light: four steps.
    let (x, y) = at(-0.6, 0.6);
    ok("/api/place", json!({ "object": "box", "x": x, "y": y }));
    ok("/api/object", json!({ "object": "box", "yaw_deg": 45.0 }));
    for k in 0..=3 {
        let (x, y) = at(0.2 + 0.1 * k as f64, 0.3);
        ok(
            "/api/place",
            json!({ "object": "box", "x": x, "y": y, "drag": k > 0 }),
        );
    }
    let last = ok("/api/light", json!({ "light": "spot", "scale": 0.5 }));
    assert_eq!(last["state"]["history"], json!({ "undo": 4, "redo": 0 }));
    let (image_last, _) = server.linear();
    // Undo the light, then the click-and-drag: the box back at the first
    // click, still turned.
    ok("/api/undo", json!({}));
    let after_drag = ok("/api/undo", json!({}));
    let box_state = &after_drag["state"]["objects"][0];
    assert_eq!(box_state["yaw_deg"], 45.0);
    let t: Vec<f64> = (0..3)
        .map(|i| box_state["translate"][i].as_f64().unwrap())
        .collect();
    let (px, py, _) = scene
        .camera
        .project(glam::DVec3::new(t[0], t[1], t[2]))
        .unwrap();
    assert!(
        (px - x).abs() < 3.0 && (py - y).abs() < 3.0,
        "after undoing the drag the box is at the first click: {px},{py} against {x},{y}"
    );
    ok("/api/undo", json!({}));
    let back = ok("/api/undo", json!({}));
    assert_eq!(back["state"]["history"], json!({ "undo": 0, "redo": 4 }));
    assert_eq!(
        server.linear().0,
        image0,
        "undoing every step gives the first image"
    );
    let none = server.post("/api/undo", &json!({}));
    assert_eq!(none.status, 422);
    assert_eq!(none.json()["error"]["field"], "undo");
    for _ in 0..4 {
        ok("/api/redo", json!({}));
    }
    // The same state; the light step may come by another exact path the
    // second time (a relight of the session made ahead for the lights, or
    // a full render), equal to 1e-5 as a relight is to a full render.
    let worst = common::relative_difference_of(&server.linear().0, &image_last);
    assert!(
        worst <= 1e-5,
        "redoing every step gives the last image: {worst:.2e} relative"
    );
    // A new edit after an undo clears the redo list.
    ok("/api/undo", json!({}));
    let fresh = ok("/api/light", json!({ "light": "spot", "scale": 2.0 }));
    assert_eq!(fresh["state"]["history"], json!({ "undo": 4, "redo": 0 }));
}

/// The session takes `arlux render`'s flags: its image after an edit is the
/// render of the variant it saves with the same flags, bit for bit, and
/// differs from the default settings' render.
#[test]
fn the_session_renders_with_the_render_flags_it_was_given() {
    let desk = Desk::new();
    let flags = [
        "--patch-size",
        "0.4",
        "--min-level",
        "3",
        "--supersample",
        "1",
    ];
    let server = Server::start(&desk.scene(), &flags);
    server.wait_ready();
    let r = server.post("/api/object", &json!({ "object": "box", "yaw_deg": 20.0 }));
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let (served, _) = server.linear();
    let saved = server.post("/api/save", &json!({}));
    assert_eq!(
        saved.status,
        200,
        "{}",
        String::from_utf8_lossy(&saved.body)
    );
    let saved = saved.json();
    let file = desk.path(saved["file"].as_str().unwrap());
    let variant = saved["variant"].as_str().unwrap();
    let out = tempfile::tempdir().unwrap();
    let render = |extra: &[&str]| {
        let exr = out.path().join("render.exr");
        let mut args = vec!["render", file.to_str().unwrap(), "--variant", variant];
        args.extend(["-o", exr.to_str().unwrap()]);
        args.extend(extra);
        common::arlux_ok(&args);
        let image = arlux::image_io::read_image(&exr).unwrap();
        image
            .pixels
            .iter()
            .flat_map(|p| p.to_array())
            .collect::<Vec<f32>>()
    };
    let differing = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .filter(|(x, y)| x.to_bits() != y.to_bits())
            .count()
    };
    let same = render(&flags);
    assert_eq!(same.len(), served.len());
    let differ = differing(&same, &served);
    assert_eq!(
        differ, 0,
        "{differ} values differ from render with the same flags"
    );
    let default = render(&[]);
    assert!(
        differing(&default, &served) > 1000,
        "the flags changed nothing"
    );
}

/// `/api/light` places a virtual light by an image point and a height: the
/// state gives its position and where it projects; a real light, a mixed
/// body and a missing field are refused.
#[test]
fn a_virtual_light_is_placed_through_the_api() {
    let validator = validator();
    let desk = Desk::new();
    let server = Server::start(&desk.scene(), &[]);
    server.wait_ready();
    let scene = arlux::scene::Scene::load(desk.scene()).unwrap();
    let (x, y, _) = scene
        .camera
        .project(glam::DVec3::new(0.3, 0.0, 0.2))
        .unwrap();
    let r = server.post(
        "/api/light",
        &json!({ "light": "bulb", "x": x, "y": y, "height_m": 1.2 }),
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let state = r.json()["state"].clone();
    assert!(validator.is_valid(&r.json()), "{}", r.json());
    let bulb = light_in(&state, "bulb");
    assert_eq!(bulb["scale"], 1.0, "{bulb}");
    let p: Vec<f64> = (bulb["position"].as_array().unwrap().iter())
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        (p[1] - 1.2).abs() < 2e-3 && (p[0] - 0.3).abs() < 2e-3,
        "{bulb}"
    );
    let screen = bulb["screen"].as_array().unwrap();
    let (sx, sy, _) = scene.camera.project(glam::DVec3::from_slice(&p)).unwrap();
    assert!(
        (screen[0].as_f64().unwrap() - sx).abs() < 1e-6
            && (screen[1].as_f64().unwrap() - sy).abs() < 1e-6
    );
    for (body, status) in [
        (
            json!({ "light": "panel", "x": x, "y": y, "height_m": 1.0 }),
            422,
        ),
        (
            json!({ "light": "bulb", "scale": 1.0, "x": x, "y": y, "height_m": 1.0 }),
            400,
        ),
        (json!({ "light": "bulb", "x": x, "y": y }), 400),
        (
            json!({ "light": "bulb", "x": x, "y": y, "height_m": 0.0 }),
            422,
        ),
    ] {
        let r = server.post("/api/light", &body);
        assert_eq!(
            r.status,
            status,
            "{body}: {}",
            String::from_utf8_lossy(&r.body)
        );
    }
}

/// `--assets DIR`: the state lists the folder's meshes by name; `/api/add`
/// stands one where a point sees the floor and the object's name joins the
/// others (it can then be turned by name); names not listed, paths and a
/// server without assets are refused.
#[test]
fn objects_are_added_from_the_asset_folder_by_name() {
    let validator = validator();
    let desk = Desk::new();
    let (assets, folder) = crate_folder(&desk.path("geometry/box.obj"));
    std::fs::write(assets.path().join("readme.md"), "not a mesh").unwrap();
    let server = Server::start(&desk.scene(), &["--assets", &folder]);
    let state = server.wait_ready();
    assert_eq!(state["assets"], json!(["crate.obj"]), "{state}");
    let scene = arlux::scene::Scene::load(desk.scene()).unwrap();
    let (x, y, _) = scene
        .camera
        .project(glam::DVec3::new(0.4, 0.0, 0.3))
        .unwrap();
    let r = server.post("/api/add", &json!({ "asset": "crate.obj", "x": x, "y": y }));
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert!(validator.is_valid(&r.json()), "{}", r.json());
    let objects = r.json()["state"]["objects"].clone();
    let added = objects.as_array().unwrap().last().unwrap().clone();
    assert_eq!(
        (added["name"].as_str(), added["enabled"].as_bool()),
        (Some("crate"), Some(true)),
        "{objects}"
    );
    let r = server.post(
        "/api/object",
        &json!({ "object": "crate", "yaw_deg": 30.0 }),
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    for asset in [
        "readme.md",
        "../scene.toml",
        "/etc/passwd",
        "geometry/box.obj",
    ] {
        let r = server.post("/api/add", &json!({ "asset": asset, "x": x, "y": y }));
        assert_eq!(
            r.status,
            422,
            "{asset}: {}",
            String::from_utf8_lossy(&r.body)
        );
    }
    drop(server);
    let plain = Server::start(&desk.scene(), &[]);
    assert_eq!(plain.wait_ready()["assets"], json!([]));
    let r = plain.post("/api/add", &json!({ "asset": "crate.obj", "x": x, "y": y }));
    assert_eq!(r.status, 422);
    assert!(String::from_utf8_lossy(&r.body).contains("--assets"));
}
