//! `arlux serve` and the session it makes ahead for a change of lights
//! (the standby: the room meshed finer, its lights solved, at the least
//! priority): what a change of lights gets before and after it is made.

mod common;
use common::Desk;
use common::serve::Server;

use serde_json::json;

/// A light changed as soon as the first image is up, before the session
/// made ahead for the lights is ready, waits for it and is relit on it,
/// not rendered in full (which would refine the same finer links from the
/// start); its image is the one the change gives once the standby was made.
#[test]
fn a_light_changed_before_the_standby_is_made_waits_for_it_and_is_relit() {
    let desk = Desk::new();
    let server = Server::start(&desk.scene(), &[]);
    server.wait_ready();
    let change = json!({ "light": "spot", "scale": 0.5 });
    let r = server.post("/api/light", &change);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["path"]["kind"], "relight", "{}", r.json()["path"]);
    let (early, _) = server.linear();
    // A second server, the change made once its standby was made.
    let later = Server::start(&desk.scene(), &[]);
    later.wait_ready();
    std::thread::sleep(std::time::Duration::from_secs(3));
    assert_eq!(
        later.post("/api/light", &change).json()["path"]["kind"],
        "relight"
    );
    let worst = common::relative_difference_of(&later.linear().0, &early);
    assert!(worst <= 1e-5, "{worst:.2e} relative");
}
