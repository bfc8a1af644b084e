//! `arlux serve` in a real browser: headless Chromium driven through
//! chromedriver (WebDriver). The box is clicked onto the desk's floor,
//! dragged 30 steps, the panel switched off and the state saved; the saved
//! variant's `arlux render` equals the server's last image bit for bit, and
//! the box stands where the last pointer position sees the floor.

mod common;
use common::Desk;
use common::serve::{Server, crate_folder, light_in};

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::actions::{InputSource, MOUSE_BUTTON_LEFT, MouseActions, PointerAction};
use fantoccini::{Client, ClientBuilder, Locator};
use glam::DVec3;
use serde_json::json;

/// One browser at a time: two chromedrivers starting at once on two cores
/// now and then fail to give a session.
static ONE_BROWSER: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// chromedriver on a free port; killed when dropped.
struct Driver(Child, u16);

impl Driver {
    fn start() -> Option<Driver> {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let child = Command::new("chromedriver")
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .ok()?;
        let start = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "chromedriver does not listen"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        Some(Driver(child, port))
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// chromedriver started, or a failure that says how to install it.
fn driver() -> Driver {
    Driver::start().unwrap_or_else(|| {
        panic!("chromedriver is not installed: `bash .ci/setup` installs Chromium and chromedriver")
    })
}

/// A copy of the desk served, and its page open and ready in a browser.
struct DeskPage {
    client: Client,
    desk: Desk,
    server: Server,
    _profile: tempfile::TempDir,
    _driver: Driver,
}

impl DeskPage {
    async fn open() -> DeskPage {
        DeskPage::open_with(&[]).await
    }

    /// The desk served with `args` given to `arlux serve`.
    async fn open_with(args: &[&str]) -> DeskPage {
        let driver = driver();
        let profile = tempfile::tempdir().unwrap();
        let client = browser(&driver, profile.path()).await;
        let desk = Desk::new();
        let server = Server::start(&desk.scene(), args);
        open_page(&client, &server.url).await;
        DeskPage {
            client,
            desk,
            server,
            _profile: profile,
            _driver: driver,
        }
    }
}

/// The page at `url` opened and ready (its first image shown).
async fn open_page(client: &Client, url: &str) {
    client.goto(url).await.unwrap();
    wait_until(
        client,
        "document.getElementById('status').dataset.ready === 'true'",
    )
    .await;
}

async fn browser(driver: &Driver, profile: &std::path::Path) -> Client {
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": "/usr/bin/chromium",
            "args": [
                "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync",
                "--window-size=1100,700",
                format!("--user-data-dir={}", profile.display()),
            ],
        }),
    );
    let connector = hyper_util::client::legacy::connect::HttpConnector::new();
    ClientBuilder::new(connector)
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{}", driver.1))
        .await
        .expect("a Chromium session")
}

/// Waits until the page's script says `condition` (a JS expression) holds.
async fn wait_until(client: &Client, condition: &str) {
    let start = Instant::now();
    loop {
        let v = client
            .execute(&format!("return !!({condition});"), vec![])
            .await
            .unwrap();
        if v == json!(true) {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "timed out waiting for {condition}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// The image canvas's left, top and width in the viewport.
async fn canvas_rect(client: &Client) -> (f64, f64, f64) {
    let rect = client
        .execute(
            "const r = document.getElementById('view').getBoundingClientRect(); return [r.left, r.top, r.width];",
            vec![],
        )
        .await
        .unwrap();
    let at = |i: usize| rect[i].as_f64().unwrap();
    (at(0), at(1), at(2))
}

/// A mouse press at `from`, 30 moves of 20 ms to `to` and the release (viewport pixels).
async fn drag(client: &Client, from: (f64, f64), to: (f64, f64)) {
    let mut mouse = pressed_at(from);
    let steps = 30;
    for k in 1..=steps {
        let f = k as f64 / steps as f64;
        mouse = mouse.then(PointerAction::MoveTo {
            duration: Some(Duration::from_millis(20)),
            x: (from.0 + f * (to.0 - from.0)).round(),
            y: (from.1 + f * (to.1 - from.1)).round(),
        });
    }
    mouse = mouse.then(PointerAction::Up {
        button: MOUSE_BUTTON_LEFT,
    });
    client.perform_actions(mouse).await.unwrap();
}

/// Clicks the element `what` finds.
async fn click(client: &Client, what: Locator<'_>) {
    client.find(what).await.unwrap().click().await.unwrap();
}

/// Clicks Save and waits for it: the scene file and variant the page names.
async fn save_in_page(client: &Client) -> (serde_json::Value, serde_json::Value) {
    click(client, Locator::Id("save")).await;
    wait_until(client, "document.getElementById('saved').dataset.file").await;
    let mut named = Vec::new();
    for key in ["file", "variant"] {
        let js = format!("return document.getElementById('saved').dataset.{key};");
        named.push(client.execute(&js, vec![]).await.unwrap());
    }
    let variant = named.pop().unwrap();
    (named.pop().unwrap(), variant)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_box_clicked_dragged_and_saved_in_the_browser_renders_as_the_server_showed_it() {
    let _one = ONE_BROWSER.lock().await;
    let driver = driver();
    let desk = Desk::new();
    let out = tempfile::tempdir().unwrap();
    let server = Server::start(&desk.scene(), &["--out", &out.path().display().to_string()]);
    let profile = tempfile::tempdir().unwrap();
    let client = browser(&driver, profile.path()).await;
    open_page(&client, &server.url).await;

    // Where the canvas is in the viewport, and the image points to click.
    let (left, top, width) = canvas_rect(&client).await;
    assert_eq!(width, 512.0, "the canvas shows the image one to one");
    let scene = arlux::scene::Scene::load(desk.scene()).unwrap();
    let at = |p: DVec3| {
        let (x, y, _) = scene.camera.project(p).unwrap();
        (x.round(), y.round())
    };
    let start = at(DVec3::new(-0.9, 0.0, 0.7));
    let end = at(DVec3::new(0.3, 0.0, 0.2));
    drag(
        &client,
        (left + start.0, top + start.1),
        (left + end.0, top + end.1),
    )
    .await;
    // The drag is over when the page has no edit in flight and shows the
    // server's latest version.
    wait_until(&client, "!busy && !pendingMove").await;
    let state = server.get("/api/state").json();
    let dragged = state["version"].as_u64().unwrap();
    assert!(
        dragged >= 2,
        "the click and the drag changed the image: {state}"
    );

    // The page after the drag (the README's picture).
    let shot = client.screenshot().await.unwrap();
    std::fs::write(
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("serve-page.png"),
        &shot,
    )
    .unwrap();
    // Switch the panel off with its checkbox, as a user does.
    let panel = client
        .find(Locator::Css("[data-light='panel'] input[type=checkbox]"))
        .await
        .unwrap();
    panel.click().await.unwrap();
    wait_until(
        &client,
        &format!("+document.getElementById('view').dataset.version > {dragged} && !busy"),
    )
    .await;
    let (file, variant) = save_in_page(&client).await;
    client.close().await.unwrap();

    let (served, version) = server.linear();
    let state = server.get("/api/state").json();
    assert_eq!(
        state["lights"][0]["scale"], 0.0,
        "the panel is off: {state}"
    );
    assert_eq!(version, state["version"].as_u64().unwrap());
    let saved = desk.path(file.as_str().unwrap());
    let exr = out.path().join("render.exr");
    common::arlux_ok(&[
        "render",
        saved.to_str().unwrap(),
        "--variant",
        variant.as_str().unwrap(),
        "-o",
        exr.to_str().unwrap(),
    ]);
    let rendered = arlux::image_io::read_image(&exr).unwrap();
    let rendered: Vec<f32> = rendered.pixels.iter().flat_map(|p| p.to_array()).collect();
    assert_eq!(rendered.len(), served.len());
    // The panel's switch is a relight where the session made ahead for a
    // change of the lights was ready (a sum of the lights' solutions, to
    // 1e-5 of the full render), a full render where it was not.
    let worst = common::relative_difference_of(&served, &rendered);
    assert!(
        worst <= 1e-5,
        "the server's image differs from arlux render's by {worst:.2e} relative"
    );

    // The box's footprint centre projects onto the drag's last point.
    let placed = arlux::scene::Scene::load(&saved)
        .unwrap()
        .with_variant(variant.as_str().unwrap())
        .unwrap();
    let o = &placed.objects[0];
    let (lo, hi) = arlux::geometry::bounds(
        o.surfaces
            .iter()
            .flat_map(|s| s.triangles.iter().flatten())
            .map(|&p| o.pose.apply(p).as_dvec3()),
    );
    let footprint = DVec3::new(0.5 * (lo.x + hi.x), lo.y, 0.5 * (lo.z + hi.z));
    let (x, y, _) = placed.camera.project(footprint).unwrap();
    let off = ((x - end.0).powi(2) + (y - end.1).powi(2)).sqrt();
    assert!(
        off <= 1.0,
        "the box stands {off:.2} px from where the drag ended"
    );
}

/// Whether the element `id` is laid out (its computed display is not `none`).
async fn displayed(client: &Client, id: &str) -> bool {
    let v = client
        .execute(
            &format!(
                "return getComputedStyle(document.getElementById('{id}')).display !== 'none';"
            ),
            vec![],
        )
        .await
        .unwrap();
    v == json!(true)
}

/// Keeps the errors the page's script throws, for the test to read.
const CATCH_ERRORS: &str = "window.__errors = []; window.addEventListener('error', (e) => window.__errors.push(String(e.message)));";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_refines_and_hides_the_wipe() {
    let _one = ONE_BROWSER.lock().await;
    let driver = driver();
    let profile = tempfile::tempdir().unwrap();
    let client = browser(&driver, profile.path()).await;

    // The desk, refining to 2 rounds once it settles.
    let desk = Desk::new();
    let server = Server::start(&desk.scene(), &["--samples", "2"]);
    client.goto(&server.url).await.unwrap();
    client.execute(CATCH_ERRORS, vec![]).await.unwrap();
    wait_until(
        &client,
        "document.getElementById('status').dataset.ready === 'true'",
    )
    .await;
    wait_until(
        &client,
        "document.getElementById('refining').textContent === 'refined: 2 rounds'",
    )
    .await;
    // The wipe on, then off: its canvas and slider go away.
    for (view, shown) in [("wipe", true), ("final", false)] {
        client
            .find(Locator::Css(&format!("input[name=view][value={view}]")))
            .await
            .unwrap()
            .click()
            .await
            .unwrap();
        wait_until(
            &client,
            &format!("document.getElementById('before').hidden === {}", !shown),
        )
        .await;
        assert_eq!(displayed(&client, "before").await, shown, "{view}");
        assert_eq!(displayed(&client, "wipe").await, shown, "{view}");
    }
    // A virtual light switched on with its box (a full render: its terms
    // were never traced) shows that it is working, and five moves of its
    // slider meanwhile coalesce: the latest wins.
    let before = server.get("/api/state").json()["version"].as_u64().unwrap();
    client
        .execute(
            "const status = document.getElementById('status');
             window.__worked = false;
             new MutationObserver(() => {
               if (status.dataset.working === 'true') window.__worked = true;
             }).observe(status, { attributes: true });
             const row = document.querySelector(\"[data-light='bulb']\");
             const box = row.querySelector('input[type=checkbox]');
             box.checked = true; box.dispatchEvent(new Event('change'));
             const range = row.querySelector('input[type=range]');
             for (const v of [0.5, 1.5, 2.0, 2.5, 3.0]) {
               range.value = v; range.dispatchEvent(new Event('change'));
             }",
            vec![],
        )
        .await
        .unwrap();
    // Watched as it changes, not polled: the render takes a few tenths
    // of a second, the flag is up for the part beyond 100 ms.
    wait_until(&client, "window.__worked").await;
    wait_until(
        &client,
        "!busy && waiting.size === 0 && document.getElementById('status').dataset.working === 'false'",
    )
    .await;
    let state = server.get("/api/state").json();
    let bulb = light_in(&state, "bulb");
    assert_eq!(bulb["scale"], 3.0, "{state}");
    let edits = state["version"].as_u64().unwrap() - before;
    assert!(edits <= 2, "{edits} edits for five moves of one slider");
    let errors = client
        .execute("return window.__errors;", vec![])
        .await
        .unwrap();
    assert_eq!(errors, json!([]), "the page threw");
    client.close().await.unwrap();
}

/// A scene without virtual objects: the page is ready, its object controls
/// are off and say why, and nothing throws.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scene_without_objects_is_served_with_its_object_controls_off() {
    let _one = ONE_BROWSER.lock().await;
    let driver = driver();
    let profile = tempfile::tempdir().unwrap();
    let client = browser(&driver, profile.path()).await;
    let empty = Desk::new();
    let text = std::fs::read_to_string(empty.scene()).unwrap();
    let cut = text.find("[[virtual]]").expect("the desk has an object");
    std::fs::write(empty.scene(), &text[..cut]).unwrap();
    let server = Server::start(&empty.scene(), &[]);
    client.goto(&server.url).await.unwrap();
    client.execute(CATCH_ERRORS, vec![]).await.unwrap();
    wait_until(
        &client,
        "document.getElementById('status').dataset.ready === 'true'",
    )
    .await;
    let off = client
        .execute(
            "return ['object', 'enabled', 'yaw', 'scale'].every((id) => document.getElementById(id).disabled);",
            vec![],
        )
        .await
        .unwrap();
    assert_eq!(off, json!(true));
    // A click on the photo and a turn of the (disabled) slider do nothing.
    click(&client, Locator::Id("view")).await;
    client
        .execute(
            "document.getElementById('yaw').dispatchEvent(new Event('change'));",
            vec![],
        )
        .await
        .unwrap();
    let message = client
        .execute(
            "return document.getElementById('message').textContent;",
            vec![],
        )
        .await
        .unwrap();
    assert!(
        message.as_str().unwrap().contains("no [[virtual]] objects"),
        "{message}"
    );
    let errors = client
        .execute("return window.__errors;", vec![])
        .await
        .unwrap();
    assert_eq!(errors, json!([]), "the page threw");
    client.close().await.unwrap();
}

/// Two tabs on one session: a change in one shows in the other (it looks
/// once a second while idle), and an edit a tab makes on a state it has
/// not seen is refused by the server; the tab then shows the session's
/// state instead of its own stale one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_tabs_stay_in_step_and_a_stale_edit_is_refused() {
    let _one = ONE_BROWSER.lock().await;
    let page = DeskPage::open().await;
    let (client, server) = (&page.client, &page.server);
    let a = client.window().await.unwrap();
    let b = client.new_window(true).await.unwrap().handle;
    client.switch_to_window(b.clone()).await.unwrap();
    open_page(client, &server.url).await;
    let v0 = server.get("/api/state").json()["version"].as_u64().unwrap();

    // Tab a switches the box off.
    client.switch_to_window(a.clone()).await.unwrap();
    client
        .execute(
            "const e = document.getElementById('enabled'); e.checked = false; e.dispatchEvent(new Event('change'));",
            vec![],
        )
        .await
        .unwrap();
    wait_until(client, &format!("state.version > {v0} && !busy")).await;
    // Tab b follows: its control and its image are the new state's.
    client.switch_to_window(b.clone()).await.unwrap();
    wait_until(
        client,
        &format!("state.version > {v0} && !document.getElementById('enabled').checked && +document.getElementById('view').dataset.version === state.version"),
    )
    .await;
    // Tab b edits on the old state (as if it had not looked yet): the
    // server refuses, nothing changes, and b shows the session's state.
    let v1 = server.get("/api/state").json()["version"].as_u64().unwrap();
    client
        .execute(
            &format!("state.version = {v0}; const e = document.getElementById('enabled'); e.checked = true; e.dispatchEvent(new Event('change'));"),
            vec![],
        )
        .await
        .unwrap();
    wait_until(
        client,
        &format!("!busy && state.version === {v1} && document.getElementById('message').textContent.startsWith('version:')"),
    )
    .await;
    assert!(
        !client
            .execute("return document.getElementById('enabled').checked;", vec![])
            .await
            .unwrap()
            .as_bool()
            .unwrap(),
        "the stale tab shows its own edit"
    );
    let state = server.get("/api/state").json();
    assert_eq!(
        state["version"].as_u64(),
        Some(v1),
        "the stale edit was applied"
    );
    assert_eq!(state["objects"][0]["enabled"], false);
    client.clone().close().await.unwrap();
}

/// Undo and redo from the page: Ctrl+Z takes an edit back, the Redo
/// button makes it again, an arrow key slides the selected object, Delete
/// hides it; the buttons are off when there is nothing to take.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn undo_redo_and_delete_from_the_keyboard_and_buttons() {
    use fantoccini::key::Key;
    let _one = ONE_BROWSER.lock().await;
    let page = DeskPage::open().await;
    let (client, desk, server) = (&page.client, &page.desk, &page.server);
    wait_until(
        client,
        "document.getElementById('undo').disabled && document.getElementById('redo').disabled",
    )
    .await;
    let shown = || async {
        server.get("/api/state").json()["objects"][0]["enabled"]
            .as_bool()
            .unwrap()
    };
    // Switch the spot to half: one step.
    client
        .execute(
            "const r = document.querySelector(\"[data-light='spot'] input[type=range]\"); r.value = 0.5; r.dispatchEvent(new Event('change'));",
            vec![],
        )
        .await
        .unwrap();
    wait_until(client, "!busy && !document.getElementById('undo').disabled").await;
    let body = client.find(Locator::Css("body")).await.unwrap();
    let ctrl_z = format!("{}z{}", char::from(Key::Control), char::from(Key::Control));
    body.send_keys(&ctrl_z).await.unwrap();
    wait_until(client, "!busy && document.getElementById('undo').disabled && !document.getElementById('redo').disabled").await;
    let spot = |s: &serde_json::Value| s["lights"][1]["scale"].as_f64().unwrap();
    assert_eq!(
        spot(&server.get("/api/state").json()),
        1.0,
        "Ctrl+Z took the change back"
    );
    click(client, Locator::Id("redo")).await;
    wait_until(client, "!busy && document.getElementById('redo').disabled").await;
    assert_eq!(
        spot(&server.get("/api/state").json()),
        0.5,
        "Redo made it again"
    );
    // The selected box is outlined where its box covers the image.
    wait_until(
        client,
        "document.getElementById('outline').dataset.box !== ''",
    )
    .await;
    let outlined = client
        .execute(
            "return document.getElementById('outline').dataset.box;",
            vec![],
        )
        .await
        .unwrap();
    let b: Vec<f64> = (outlined.as_str().unwrap().split(','))
        .map(|v| v.parse().unwrap())
        .collect();
    let state = server.get("/api/state").json();
    let t = &state["objects"][0]["translate"];
    let scene = arlux::scene::Scene::load(desk.scene()).unwrap();
    let centre = DVec3::new(
        t[0].as_f64().unwrap(),
        t[1].as_f64().unwrap() + 0.15,
        t[2].as_f64().unwrap(),
    );
    let (x, y, _) = scene.camera.project(centre).unwrap();
    assert!(
        b[0] < x && x < b[2] && b[1] < y && y < b[3],
        "outline {b:?} misses the box's centre {x},{y}"
    );
    // An arrow key slides the box 5 cm along the floor.
    let x0 = server.get("/api/state").json()["objects"][0]["translate"][0]
        .as_f64()
        .unwrap();
    body.send_keys(&char::from(Key::Right).to_string())
        .await
        .unwrap();
    wait_until(
        client,
        &format!("!busy && state.objects[0].translate[0] !== {x0}"),
    )
    .await;
    let t = server.get("/api/state").json()["objects"][0]["translate"].clone();
    let moved = (t[0].as_f64().unwrap() - x0).hypot(0.0);
    assert!(
        moved > 0.01 && moved <= 0.05 + 1e-9,
        "moved {moved} m in x: {t}"
    );
    // Delete hides the selected object (the box).
    assert!(shown().await);
    body.send_keys(&char::from(Key::Delete).to_string())
        .await
        .unwrap();
    wait_until(client, "!busy && !state.objects[0].enabled").await;
    assert!(!shown().await, "Delete hid the box");
    wait_until(
        client,
        "document.getElementById('outline').dataset.box === ''",
    )
    .await;
    client.clone().close().await.unwrap();
}

/// The mouse moved to `at` and pressed there (viewport pixels).
fn pressed_at(at: (f64, f64)) -> MouseActions {
    MouseActions::new("mouse".into())
        .then(PointerAction::MoveTo {
            duration: None,
            x: at.0.round(),
            y: at.1.round(),
        })
        .then(PointerAction::Down {
            button: MOUSE_BUTTON_LEFT,
        })
}

/// A press and release at `at` (viewport pixels).
async fn click_at(client: &Client, at: (f64, f64)) {
    let mouse = pressed_at(at).then(PointerAction::Up {
        button: MOUSE_BUTTON_LEFT,
    });
    client.perform_actions(mouse).await.unwrap();
}

/// `--assets`: the page offers the folder's mesh, *add* and a click stand
/// it on the floor there and select it; a virtual light's *place* and a
/// click put it the height asked above the floor, switched on and ringed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_object_is_added_from_the_assets_and_a_light_placed_by_clicks() {
    let _one = ONE_BROWSER.lock().await;
    let (_assets, folder) = crate_folder(&common::scene_dir("desk").join("geometry/box.obj"));
    let page = DeskPage::open_with(&["--assets", &folder]).await;
    let (client, server, desk) = (&page.client, &page.server, &page.desk);
    client.execute(CATCH_ERRORS, vec![]).await.unwrap();
    let (left, top, _) = canvas_rect(client).await;
    let scene = arlux::scene::Scene::load(desk.scene()).unwrap();
    let at = |p: DVec3| {
        let (x, y, _) = scene.camera.project(p).unwrap();
        (left + x, top + y)
    };

    // Add the crate where the floor is seen.
    click(client, Locator::Id("add")).await;
    click_at(client, at(DVec3::new(0.4, 0.0, 0.3))).await;
    wait_until(client, "!busy && state.objects.length === 2").await;
    let state = server.get("/api/state").json();
    assert_eq!(state["objects"][1]["name"], "crate", "{state}");
    assert_eq!(state["objects"][1]["enabled"], true, "{state}");
    let chosen = client
        .execute("return document.getElementById('object').value;", vec![])
        .await
        .unwrap();
    assert_eq!(chosen, json!("crate"), "the added object is selected");

    // Place the bulb 1.2 m above the floor at another point.
    let height = client
        .find(Locator::Css("[data-light='bulb'] input.height"))
        .await
        .unwrap();
    height.clear().await.unwrap();
    height.send_keys("1.2").await.unwrap();
    click(
        client,
        Locator::Css("[data-light='bulb'] button.place-light"),
    )
    .await;
    click_at(client, at(DVec3::new(-0.3, 0.0, 0.5))).await;
    wait_until(
        client,
        "!busy && state.lights.some((l) => l.name === 'bulb' && l.scale > 0)",
    )
    .await;
    let state = server.get("/api/state").json();
    let bulb = light_in(&state, "bulb");
    let y = bulb["position"][1].as_f64().unwrap();
    assert!((y - 1.2).abs() < 0.01, "the bulb is {y} m up: {bulb}");
    wait_until(
        client,
        "document.getElementById('outline').dataset.lights.split(',').includes('bulb')",
    )
    .await;
    let errors = client
        .execute("return window.__errors;", vec![])
        .await
        .unwrap();
    assert_eq!(errors, json!([]), "the page threw");
    client.clone().close().await.unwrap();
}
