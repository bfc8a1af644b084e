//! `arlux serve`: a local web page over an editing session
//! ([`arlux::interactive`]): click to stand an object on the floor, drag to
//! slide it, turn, scale, hide; scale the lights; save the state as a
//! variant; write a full EXR. This module is the HTTP layer only: one worker
//! thread owns the session and takes jobs in order; the handlers talk to it
//! through a channel and read the latest frame without waiting for it.

use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, RwLock};

use anyhow::{Context, Result};
use serde_json::{Value, json};

use arlux::interactive::{Frame, Interactive, Outcome, Refusal};

mod api;
mod versions;
mod worker;

/// Arguments of `arlux serve`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    /// The port to listen on (0: any free port, printed at start).
    #[arg(long, default_value_t = 8765)]
    pub port: u16,
    /// The address to listen on. Anything but loopback lets other machines
    /// in (with the token): say so on purpose.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// Open the page in the desktop's browser (xdg-open).
    #[arg(long)]
    pub open: bool,
    /// The folder the page's "Render" writes full EXRs to (without it, the
    /// page offers no Render).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The render flags, as `arlux render` takes them. In the session,
    /// `--samples N` refines the image in the background once an edit
    /// settles (1, 2, 4 … up to N rounds; the next edit cancels): the page
    /// then shows what `render --samples N` gives of the state, while each
    /// edit's first image takes none.
    #[command(flatten)]
    pub flags: crate::flags::RenderFlags,
    /// A folder of meshes (.glb, .gltf, .obj, .ply; not its sub-folders)
    /// the page offers to add to the scene: picked by file name, placed
    /// by a click; a saved variant's file carries them.
    #[arg(long, value_name = "DIR")]
    pub assets: Option<PathBuf>,
    /// A name or address other machines reach this one by (repeatable):
    /// requests naming it in their Host header are served. Needed with
    /// `--bind 0.0.0.0` (or `::`), which names no address of its own.
    #[arg(long, value_name = "NAME")]
    pub allow_host: Vec<String>,
    /// Print the address as one JSON object on stdout once listening.
    #[arg(long)]
    pub json: bool,
}

/// What every handler shares.
pub(crate) struct Shared {
    pub token: String,
    /// The `Host` values a request may carry (a DNS-rebinding page cannot).
    pub hosts: Vec<String>,
    pub jobs: std::sync::mpsc::SyncSender<worker::Job>,
    /// The latest state, published by the worker after every change.
    pub latest: RwLock<Option<Arc<Published>>>,
    /// The stage the preprocess is in, or its failure.
    pub status: Mutex<Status>,
    pub limiter: governor::DefaultDirectRateLimiter,
    /// Fixed at start: the photo as shot and the room's surface per pixel.
    pub fixed: std::sync::OnceLock<(arlux::image_io::Image, arlux::surface_ids::SurfaceIds)>,
    pub can_render: bool,
    /// The meshes `--assets` offers, by file name.
    pub assets: Vec<(String, PathBuf)>,
    /// The scene's virtual objects' names by index (objects added from
    /// `--assets` join them) and its lights'.
    pub objects: RwLock<Vec<String>>,
    pub lights: Vec<String>,
}

/// The preprocess's progress, for the page before the first image.
#[derive(Debug, Clone, Default)]
pub(crate) struct Status {
    pub stage: String,
    pub failed: Option<String>,
}

/// One state as the page sees it.
pub(crate) struct Published {
    pub frame: Frame,
    pub state: Value,
}

pub fn run(args: &Args) -> Result<()> {
    let scene = crate::common::load(&args.scene, None)?;
    let photo = crate::common::read_photo(&scene)?;
    // Checked as render checks it; the session's own images take no
    // rounds of samples (each edit's first image is as fast as without).
    let mut options = arlux::settings::RenderOptions::default();
    args.flags.apply(&mut options);
    options.resolve()?;
    options.samples = 0;
    let method = options.resolve()?;
    let assets = match &args.assets {
        Some(dir) => arlux::interactive::list_assets(dir)
            .with_context(|| format!("--assets {}: cannot list the folder", dir.display()))?,
        None => Vec::new(),
    };
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out)
            .with_context(|| format!("--out {}: cannot create the folder", out.display()))?;
    }
    if args.bind.is_unspecified() && args.allow_host.is_empty() {
        anyhow::bail!(
            "--bind {}: a request from another machine names this one in its Host header, which the server must know: give --allow-host NAME for each name or address they use (or --bind one address of this machine)",
            args.bind
        );
    }
    if let Some(bad) = (args.allow_host.iter()).find(|h| {
        h.is_empty()
            || !h
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-.:[]".contains(c))
    }) {
        anyhow::bail!("--allow-host '{bad}': give a host name or an IP address");
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind(SocketAddr::new(
            args.bind, args.port,
        )))
        .with_context(|| format!("cannot listen on {}:{}", args.bind, args.port))?;
    let port = listener.local_addr()?.port();
    if !args.bind.is_loopback() {
        eprintln!(
            "warning: listening on {}: other machines can reach the page (the token still guards it; the connection is not encrypted)",
            args.bind
        );
    }
    let token = token();
    let (jobs, queue) = std::sync::mpsc::sync_channel(worker::QUEUE);
    let shared = Arc::new(Shared {
        token: token.clone(),
        hosts: hosts(args, port),
        jobs,
        latest: RwLock::new(None),
        status: Mutex::new(Status {
            stage: "loading".into(),
            failed: None,
        }),
        limiter: governor::RateLimiter::direct(api::quota()),
        fixed: std::sync::OnceLock::new(),
        can_render: args.out.is_some(),
        objects: RwLock::new(scene.objects.iter().map(|o| o.name.clone()).collect()),
        assets,
        lights: scene.lights.iter().map(|l| l.name.clone()).collect(),
    });
    let host = match args.bind {
        IpAddr::V6(a) => format!("[{a}]"),
        a => a.to_string(),
    };
    let url = format!("http://{host}:{port}/?token={token}");
    announce(args, &url, port, &token)?;
    // The preprocess's stages, on the terminal and for the page.
    let bar = crate::progress::stage_spinner("serve: preparing");
    let (observer, shown) = (Arc::clone(&shared), bar.clone());
    arlux::util::stages::observe(move |stage| {
        shown.set_message(stage.to_string());
        observer
            .status
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .stage = stage.to_string();
    });
    let context = worker::Context {
        shared: Arc::clone(&shared),
        out: args.out.clone(),
        meta: crate::common::frame_meta(&scene, json!({ "serve": true })),
        bar,
        refine_to: args.flags.samples,
    };
    std::thread::Builder::new()
        .name("session".into())
        .spawn(move || worker::run(scene, photo, method, context, queue))?;
    if args.open {
        let _ = std::process::Command::new("xdg-open").arg(&url).spawn();
    }
    runtime.block_on(serve_connections(listener, api::router(shared)));
    Ok(())
}

/// A client must send a request's headers within this time, and its body
/// within as long again ([`api`]), or its connection is closed.
pub(crate) const HEADER_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);
/// Connections held at once; beyond, a new one is closed at once (the page
/// needs a few; half-sent requests must not exhaust the process's files).
const MAX_CONNECTIONS: usize = 4096;

/// Accepts connections for ever, each served on its own task with the
/// header timeout, at most [`MAX_CONNECTIONS`] at a time.
async fn serve_connections(listener: tokio::net::TcpListener, app: axum::Router) {
    let slots = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(_) => {
                // Out of files or the like: the timeouts free some soon.
                tokio::time::sleep(std::time::Duration::from_millis(20)).await;
                continue;
            }
        };
        let Ok(slot) = Arc::clone(&slots).try_acquire_owned() else {
            drop(stream);
            continue;
        };
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        tokio::spawn(async move {
            let _ = hyper::server::conn::http1::Builder::new()
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(HEADER_TIMEOUT)
                // A client that closes its side once the request is sent
                // still gets the reply.
                .half_close(true)
                .serve_connection(hyper_util::rt::TokioIo::new(stream), service)
                .await;
            drop(slot);
        });
    }
}

/// The `Host` values a request may carry: this machine by loopback, the
/// bound address, and each `--allow-host`, all with the port.
fn hosts(args: &Args, port: u16) -> Vec<String> {
    let mut names = vec!["127.0.0.1".to_string(), "localhost".to_string()];
    if !args.bind.is_unspecified() {
        names.push(match args.bind {
            IpAddr::V6(a) => format!("[{a}]"),
            IpAddr::V4(a) => a.to_string(),
        });
    }
    for h in &args.allow_host {
        // An IPv6 address goes in brackets in a Host header.
        let bare = h.trim_start_matches('[').trim_end_matches(']');
        names.push(match bare.parse::<std::net::Ipv6Addr>() {
            Ok(a) => format!("[{a}]"),
            Err(_) => h.to_ascii_lowercase(),
        });
    }
    names.into_iter().map(|h| format!("{h}:{port}")).collect()
}

/// Where the page is, on stdout: a line for a person, or one JSON object.
fn announce(args: &Args, url: &str, port: u16, token: &str) -> Result<()> {
    if args.json {
        crate::common::emit(
            "serve",
            json!({ "url": url, "port": port, "token": token, "scene": args.scene.display().to_string() }),
        )?;
    } else {
        say!("arlux serve: open {url}");
        say!("(the token in the address is needed on every request; stop with Ctrl-C)");
    }
    use std::io::Write as _;
    std::io::stdout().flush()?;
    Ok(())
}

/// 128 random bits, hex: the secret every request must carry.
fn token() -> String {
    use rand::RngExt as _;
    let bits: u128 = rand::rng().random();
    format!("{bits:032x}")
}

/// An edit's reply: what it did and the state after it.
pub(crate) fn outcome_json(outcome: &Outcome, server_ms: f64, state: &Value) -> Value {
    json!({
        "version": outcome.version,
        "path": outcome.path,
        "update_ms": outcome.millis,
        "server_ms": server_ms,
        "state": state,
    })
}

/// A refused request's reply body.
pub(crate) fn refusal_json(r: &Refusal) -> Value {
    json!({ "error": { "field": r.field, "message": r.message } })
}

/// The state as the page shows it.
pub(crate) fn state_json(it: &Interactive, last: Option<&Value>, assets: &[String]) -> Value {
    let scene = it.scene();
    let objects: Vec<Value> = (0..scene.objects.len())
        .map(|k| {
            let (enabled, t, yaw, scale) = it.object_state(k);
            json!({
                "name": scene.objects[k].name,
                "enabled": enabled,
                "translate": t.to_array(),
                "yaw_deg": yaw,
                "scale": scale,
                "screen_box": it.screen_box(k),
            })
        })
        .collect();
    let lights: Vec<Value> = scene
        .lights
        .iter()
        .map(|l| {
            let at = l.known_position();
            json!({
                "name": l.name,
                "real": l.real,
                "scale": l.scale,
                "position": at.map(|p| p.to_array()),
                "screen": at.and_then(|p| scene.camera.project(p)).map(|(x, y, _)| [x, y]),
            })
        })
        .collect();
    json!({
        "ready": true,
        "scene": scene.name,
        "width": scene.camera.width,
        "height": scene.camera.height,
        "exposure": it.auto_exposure(),
        "version": it.version(),
        "objects": objects,
        "lights": lights,
        "last": last,
        "refined": refined_json(it),
        "history": { "undo": it.history().0, "redo": it.history().1 },
        "assets": assets,
    })
}

/// How far the background refinement has come: rounds done and asked
/// for, and the estimated remaining noise (null before any round).
fn refined_json(it: &Interactive) -> Value {
    let (rounds, stats) = it.refined();
    json!({
        "rounds": rounds,
        "noise_rms": stats.map(|s| s.noise_rms),
    })
}
