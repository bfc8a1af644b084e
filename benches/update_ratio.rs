//! An update's time against a full render's, interleaved in one process
//! (this machine's speed drifts between runs: timing the two apart puts
//! that drift into their ratio). Each round times `UPDATES` updates on
//! one session (the desk's box moving between poses 3 and 4 of
//! `box_slide`) and one full render of pose 4; prints the medians.
//!
//! `cargo bench --bench update_ratio -- [ROUNDS] [UPDATES]` (a report, not
//! criterion; `cargo test --benches` runs nothing).

use std::time::Instant;

use arlux::model::StageTimes;
use arlux::render::{RenderSettings, Session, render};
use arlux::scene::Scene;

fn main() -> anyhow::Result<()> {
    // `cargo bench` passes its own flags; `cargo test --benches` asks for a quick pass.
    if std::env::args().any(|a| a == "--test" || a == "--list") {
        return Ok(());
    }
    let base = Scene::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/desk/scene.toml"
    ))?;
    let (p3, p4) = (
        base.with_motion_pose("box_slide", 3)?,
        base.with_motion_pose("box_slide", 4)?,
    );
    let photo = p3.load_photo()?;
    let settings = RenderSettings::default();
    let mut args = (std::env::args().skip(1))
        .filter(|a| !a.starts_with("--"))
        .map(|a| a.parse::<usize>());
    let rounds = args.next().transpose()?.unwrap_or(15);
    let updates = args.next().transpose()?.unwrap_or(20);
    let mut session = Session::start(&p3, &photo, &settings, &mut StageTimes::default())?;
    session.prepare_updates(&mut StageTimes::default());
    session.image_only();
    let (mut update_ms, mut full_ms) = (Vec::new(), Vec::new());
    for round in 0..rounds {
        for i in 0..updates {
            let t0 = Instant::now();
            session.update(
                if (round * updates + i) % 2 == 0 {
                    &p4
                } else {
                    &p3
                },
                &mut StageTimes::default(),
            )?;
            update_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        let t0 = Instant::now();
        let full = render(&p4, &photo, &settings, &mut StageTimes::default())?;
        full_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        drop(full);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (u, f) = (median(&mut update_ms), median(&mut full_ms));
    println!(
        "{rounds} rounds of {updates} updates and a full render: update {u:.2} ms, full render {f:.1} ms, {:.1}x",
        f / u
    );
    Ok(())
}
