//! The one thread that owns the editing session: it takes jobs in the order
//! they came, except that a drag's moves of one object that queued up
//! during an update are coalesced (the latest wins; the others are told
//! they were superseded).

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tokio::sync::oneshot;

use arlux::image_io::{ExrMeta, Image};
use arlux::interactive::{Edit, Interactive, Refusal};
use arlux::model::StageTimes;
use arlux::scene::Scene;

use super::versions::{History, Stamp};
use super::{Published, Shared};

/// Jobs that may wait for the worker; beyond, a request is refused (503).
pub(crate) const QUEUE: usize = 256;

/// A reply: an HTTP status and a JSON body.
pub(crate) type Reply = (u16, Value);

pub(crate) enum Job {
    Edit {
        edit: Edit,
        /// A drag's move: may be superseded by a later move of the same object.
        drag: bool,
        stamp: Stamp,
        received: Instant,
        reply: oneshot::Sender<Reply>,
    },
    /// An object added from `--assets` (the file, as the server listed it)
    /// and stood where the image point sees a floor.
    Add {
        file: PathBuf,
        at: (f64, f64),
        stamp: Stamp,
        received: Instant,
        reply: oneshot::Sender<Reply>,
    },
    Save {
        name: Option<String>,
        stamp: Stamp,
        reply: oneshot::Sender<Reply>,
    },
    Render {
        reply: oneshot::Sender<Reply>,
    },
}

pub(crate) struct Context {
    pub shared: Arc<Shared>,
    pub out: Option<PathBuf>,
    pub meta: ExrMeta,
    /// The preprocess's progress on the terminal, cleared at the first image.
    pub bar: indicatif::ProgressBar,
    /// Rounds of per-pixel samples the image refines to while no edit
    /// waits (`--samples`; 0: none).
    pub refine_to: u32,
}

/// Builds the session (the preprocess), then serves jobs until the server goes.
pub(crate) fn run(
    scene: Scene,
    photo: Image,
    method: arlux::settings::Method,
    cx: Context,
    queue: Receiver<Job>,
) {
    let started = Instant::now();
    let made = Interactive::with_method(scene, photo, method.clone(), &mut StageTimes::default());
    cx.bar.finish_and_clear();
    let mut it = match made {
        Ok(it) => it,
        Err(e) => {
            eprintln!("error: {e}");
            cx.shared
                .status
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .failed = Some(e.to_string());
            return;
        }
    };
    let _ = cx
        .shared
        .fixed
        .set((it.photo().clone(), it.room().ids.clone()));
    let first = json!({ "path": { "kind": "full", "reason": "the first image" }, "update_ms": started.elapsed().as_secs_f64() * 1e3 });
    publish(&cx, &it, Some(&first));
    eprintln!(
        "arlux serve: ready ({:.1} s of preprocess)",
        started.elapsed().as_secs_f64()
    );
    let ahead = it
        .standby_scene()
        .map(|scene| standby_ahead(scene, it.photo().clone(), method));
    let mut held: VecDeque<Job> = VecDeque::new();
    let mut history = History::default();
    loop {
        let job = match held.pop_front() {
            Some(j) => j,
            None => match next_job(&cx, &mut it, &queue) {
                Some(j) => j,
                None => return,
            },
        };
        // Taken before the job: it may be the light change it is for.
        if let Some((made, quiet)) = &ahead {
            quiet.busy.store(true, Ordering::Relaxed);
            let standby = if changes_lights(&job) && it.standby_wanted() {
                awaited(made, quiet)
            } else {
                made.try_recv().ok()
            };
            // Made for a session that has since left the photo's lights
            // (and so the coarse mesh) itself, it could serve nothing: freed.
            if let Some(standby) = standby
                && it.standby_wanted()
            {
                it.offer_standby(standby);
            }
        }
        let job = coalesce(job, &queue, &mut held);
        // A bug in a stage must not end the session: the job fails, the
        // session goes on from its last state.
        let job_run = std::panic::AssertUnwindSafe(|| serve_job(&cx, &mut it, &mut history, job));
        if std::panic::catch_unwind(job_run).is_err() {
            eprintln!("arlux serve: a job failed (see above); the session goes on");
        }
        if let Some((_, quiet)) = &ahead {
            // Once the session has left the photo's lights it is on the
            // finer mesh itself: a standby under way is given up.
            if !it.standby_wanted() {
                quiet.wanted.store(false, Ordering::Relaxed);
            }
            quiet.mark_idle();
        }
    }
}

/// Whether `job` changes the lights (a light's scale, or a virtual light
/// placed).
fn changes_lights(job: &Job) -> bool {
    matches!(
        job,
        Job::Edit {
            edit: Edit::Light { .. } | Edit::PlaceLight { .. },
            ..
        }
    )
}

/// The standby under way, waited for at full speed: a change of lights
/// that came before it was made would render in full on the same finer
/// mesh, refining the same links from the start, where the standby has a
/// head start (`lounge`, cold, a light changed 2.5 s after the first
/// image: 7.4 s in full). Where the standby cannot serve the change, the
/// links it refined are in the cache for the full render. None when it
/// was taken before, given up or failed.
fn awaited(
    made: &Receiver<arlux::interactive::Standby>,
    quiet: &Quiet,
) -> Option<arlux::interactive::Standby> {
    quiet.urgent.store(true, Ordering::Relaxed);
    let standby = made.recv().ok();
    quiet.urgent.store(false, Ordering::Relaxed);
    standby
}

/// What the worker tells the thread that makes the standby: whether an
/// edit is being served, when the last one ended, whether a standby is
/// still wanted, and whether an edit waits for it.
struct Quiet {
    epoch: Instant,
    busy: AtomicBool,
    /// An edit waits for the standby: it goes on at once.
    urgent: AtomicBool,
    /// Milliseconds from `epoch` to the end of the last edit.
    idle_since_ms: AtomicU64,
    wanted: AtomicBool,
}

impl Quiet {
    fn mark_idle(&self) {
        let now = self.epoch.elapsed().as_millis() as u64;
        self.idle_since_ms.store(now, Ordering::Relaxed);
        self.busy.store(false, Ordering::Relaxed);
    }

    fn quiet_for(&self) -> Duration {
        if self.busy.load(Ordering::Relaxed) {
            return Duration::ZERO;
        }
        let since = Duration::from_millis(self.idle_since_ms.load(Ordering::Relaxed));
        self.epoch.elapsed().saturating_sub(since)
    }

    /// What the standby's threads do at a pause point: wait until the
    /// session has gone [`QUIET_FOR_STANDBY`] without an edit (or an edit
    /// waits for the standby), or give the standby up once it is no
    /// longer wanted.
    fn wait_for_quiet(&self) {
        loop {
            if !self.wanted.load(Ordering::Relaxed) {
                arlux::util::pause::cancel();
            }
            if self.urgent.load(Ordering::Relaxed) || self.quiet_for() >= QUIET_FOR_STANDBY {
                return;
            }
            std::thread::sleep(PAUSE_POLL);
        }
    }
}

/// How long the session must have gone without an edit for the standby to
/// go on: made beside a drag or a slider's steps, it took their caches
/// (the serve bench's slider steps 36 → 48 ms median, the stool's drag
/// steps 118 → 129 ms). A drag's steps come closer than this.
const QUIET_FOR_STANDBY: Duration = Duration::from_millis(300);

/// How often a paused standby looks whether the session is quiet.
const PAUSE_POLL: Duration = Duration::from_millis(2);

/// Makes, beside the session and at the least priority, the session a
/// first change of the lights renders (the room meshed finer, its links
/// refined, each light solved: [`arlux::interactive::Standby`]), from the
/// first image on, pausing at its pause points ([`arlux::util::pause`])
/// while edits come, and given up once the session no longer wants it
/// (its lights changed before it was made); the worker takes it from the
/// returned channel before its next job. On `lounge` from a cold cache that change took
/// 13 s in full, 1.1 s with its links refined ahead. Its threads take only
/// the CPU the session leaves idle (the stool's drag steps 107 ms alone,
/// 115 ms beside the links' refinement; 201 ms beside one thread at the
/// session's priority).
fn standby_ahead(
    scene: Scene,
    photo: Image,
    method: arlux::settings::Method,
) -> (Receiver<arlux::interactive::Standby>, Arc<Quiet>) {
    let (send, made) = std::sync::mpsc::channel();
    let quiet = Arc::new(Quiet {
        // Quiet from the first image on: the standby begins at once.
        epoch: (Instant::now().checked_sub(QUIET_FOR_STANDBY)).unwrap_or_else(Instant::now),
        busy: AtomicBool::new(false),
        urgent: AtomicBool::new(false),
        idle_since_ms: AtomicU64::new(0),
        wanted: AtomicBool::new(true),
    });
    let told = Arc::clone(&quiet);
    std::thread::spawn(move || {
        let started = Instant::now();
        let start = || {
            arlux::interactive::Standby::start(scene, &photo, &method, &mut StageTimes::default())
        };
        let paused = Arc::clone(&told);
        let pool = rayon::ThreadPoolBuilder::new()
            .thread_name(|i| format!("arlux-ahead-{i}"))
            .start_handler(move |_| {
                lowest_priority();
                let paused = Arc::clone(&paused);
                arlux::util::pause::set_check(Arc::new(move || paused.wait_for_quiet()));
            })
            .build();
        // Without a pool of its own, not at all: it would take the
        // session's threads.
        let made = pool.map(|p| arlux::util::pause::cancellable(|| p.install(start)));
        let why = match made {
            Ok(None) => return, // given up: the session changed its lights first
            Ok(Some(Ok(standby))) => {
                eprintln!(
                    "arlux serve: changes of the lights relight from here on (made in {:.1} s)",
                    started.elapsed().as_secs_f64()
                );
                let _ = send.send(standby);
                return;
            }
            Ok(Some(Err(e))) => e.to_string(),
            Err(e) => e.to_string(),
        };
        eprintln!("arlux serve: the session for a change of lights was not made ahead: {why}");
    });
    (made, quiet)
}

/// Lowers the calling thread to the least priority (nice 19), by
/// util-linux's `renice` on its thread id (no `unsafe` here: the crate's
/// only unsafe code binds Embree). Best effort: without /proc or renice it
/// keeps the session's priority.
fn lowest_priority() {
    let Ok(link) = std::fs::read_link("/proc/thread-self") else {
        return;
    };
    let Some(tid) = link.file_name().and_then(|t| t.to_str()) else {
        return;
    };
    let _ = std::process::Command::new("renice")
        .args(["-n", "19", "-p", tid])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status();
}

/// The next job. While none waits, the session first solves ahead what a
/// light's slider would solve on its first step (after a full render or
/// a relight: [`Interactive::prepare_relights`]), then the image refines a
/// level at a time (1, 2, 4 … rounds of per-pixel samples, up to
/// `--samples`), each level published when done; an edit that arrives is
/// served after the step under way, and starts again from the session's
/// own image.
fn next_job(cx: &Context, it: &mut Interactive, queue: &Receiver<Job>) -> Option<Job> {
    use std::sync::mpsc::TryRecvError;
    loop {
        match queue.try_recv() {
            Ok(j) => return Some(j),
            Err(TryRecvError::Disconnected) => return None,
            Err(TryRecvError::Empty) => {}
        }
        // First what a light's slider would solve on its first step.
        let ahead =
            std::panic::AssertUnwindSafe(|| it.prepare_relights(&mut StageTimes::default()));
        match std::panic::catch_unwind(ahead) {
            Ok(true) => continue,
            Ok(false) => {}
            Err(_) => {
                eprintln!("arlux serve: solving ahead failed (see above); the session goes on")
            }
        }
        let (done, _) = it.refined();
        if it.composite().is_none() || done >= cx.refine_to {
            return queue.recv().ok();
        }
        let next = (2 * done).clamp(1, cx.refine_to);
        let job_run = std::panic::AssertUnwindSafe(|| {
            it.refine(next, &mut StageTimes::default());
        });
        if std::panic::catch_unwind(job_run).is_err() {
            eprintln!("arlux serve: refining failed (see above); the session goes on");
            return queue.recv().ok();
        }
        let last = (cx.shared.latest.read().unwrap_or_else(|e| e.into_inner()))
            .as_ref()
            .map(|p| p.state["last"].clone());
        publish(cx, it, last.as_ref());
    }
}

/// The latest of the moves of one object queued behind `job`, when `job`
/// is a drag's move; the jobs of other kinds met on the way are kept in order.
fn coalesce(mut job: Job, queue: &Receiver<Job>, held: &mut VecDeque<Job>) -> Job {
    let object = |j: &Job| match j {
        Job::Edit {
            edit: Edit::Place { object, .. },
            drag: true,
            ..
        } => Some(*object),
        _ => None,
    };
    let Some(first) = object(&job) else {
        return job;
    };
    if !held.is_empty() {
        return job;
    }
    while let Ok(next) = queue.try_recv() {
        if object(&next) == Some(first) {
            if let Job::Edit { reply, .. } = std::mem::replace(&mut job, next) {
                let _ = reply.send((200, json!({ "superseded": true })));
            }
        } else {
            held.push_back(next);
            break;
        }
    }
    job
}

/// The refusal of an edit made on a state another page has changed since,
/// with the state as it is now (the page shows it).
fn stale(cx: &Context, it: &Interactive, stamp: &Stamp) -> Reply {
    let state = (cx.shared.latest.read().unwrap_or_else(|e| e.into_inner()))
        .as_ref()
        .map(|p| p.state.clone());
    let message = format!(
        "made on version {} but the session is at {}: another page changed it (its state is here)",
        stamp.version.unwrap_or_default(),
        it.version()
    );
    (
        409,
        json!({ "error": { "field": "version", "message": message }, "state": state }),
    )
}

fn serve_job(cx: &Context, it: &mut Interactive, history: &mut History, job: Job) {
    match job {
        Job::Edit {
            edit,
            drag,
            stamp,
            received,
            reply,
        } => {
            let times = &mut StageTimes::default();
            let made = edited(cx, it, history, (stamp, received), |it| match drag {
                true => it.apply_drag(edit, times),
                false => it.apply(edit, times),
            });
            let _ = reply.send(made);
        }
        Job::Add {
            file,
            at,
            stamp,
            received,
            reply,
        } => {
            let made = edited(cx, it, history, (stamp, received), |it| {
                let (outcome, name) = it.add_object(&file, at, &mut StageTimes::default())?;
                let mut names = cx.shared.objects.write().unwrap_or_else(|e| e.into_inner());
                names.push(name);
                Ok(outcome)
            });
            let _ = reply.send(made);
        }
        Job::Save { name, stamp, reply } => {
            if history.stale(&stamp, it.version()) {
                let _ = reply.send(stale(cx, it, &stamp));
                return;
            }
            let name = name.unwrap_or_else(|| it.next_variant_name());
            let body = match it.save_variant(&name) {
                Ok(path) => (
                    200,
                    json!({
                        "file": path.file_name().map(|n| n.to_string_lossy().into_owned()),
                        "variant": name,
                        "scene_file_changed": it.file_changed(),
                    }),
                ),
                Err(e) => (
                    409,
                    super::refusal_json(&Refusal {
                        field: "name",
                        message: e.to_string(),
                    }),
                ),
            };
            let _ = reply.send(body);
        }
        Job::Render { reply } => {
            let _ = reply.send(render(cx, it));
        }
    }
}

/// Writes the state's full EXR (every layer `arlux render` writes) into the
/// `--out` folder, under a name no file there has.
fn render(cx: &Context, it: &mut Interactive) -> Reply {
    let Some(out) = &cx.out else {
        return (
            409,
            json!({ "error": { "field": "render", "message": "the server was started without --out DIR: nowhere to write" } }),
        );
    };
    let path = (0..)
        .map(|k| {
            let suffix = if k == 0 {
                String::new()
            } else {
                format!("-{k}")
            };
            out.join(format!("{}-v{}{suffix}.exr", it.base().name, it.version()))
        })
        .find(|p| !p.exists())
        .expect("some name is free");
    let photo = it.photo().clone();
    let write =
        |c: &arlux::composite::Composite| crate::common::write_frame(&path, c, &photo, &cx.meta);
    let written = it
        .with_every_layer(&mut StageTimes::default(), write)
        .unwrap_or_else(|| write(&arlux::composite::Composite::unchanged(&photo)));
    match written {
        Ok(()) => (
            200,
            json!({ "file": path.file_name().map(|n| n.to_string_lossy().into_owned()) }),
        ),
        Err(e) => (
            500,
            json!({ "error": { "field": "render", "message": e.to_string() } }),
        ),
    }
}

/// Makes an edit (`make`) unless its stamp is stale; the reply: the
/// outcome and the state it published, or the refusal.
fn edited(
    cx: &Context,
    it: &mut Interactive,
    history: &mut History,
    (stamp, received): (Stamp, Instant),
    make: impl FnOnce(&mut Interactive) -> Result<arlux::interactive::Outcome, Refusal>,
) -> Reply {
    if history.stale(&stamp, it.version()) {
        return stale(cx, it, &stamp);
    }
    let version = it.version();
    match make(it) {
        Ok(outcome) => {
            // An edit that changes nothing keeps the version.
            if it.version() > version {
                history.record(it.version(), stamp.client.clone());
            }
            let server_ms = received.elapsed().as_secs_f64() * 1e3;
            let last = json!({ "path": outcome.path, "update_ms": outcome.millis });
            let state = publish(cx, it, Some(&last));
            (200, super::outcome_json(&outcome, server_ms, &state))
        }
        Err(r) => (422, super::refusal_json(&r)),
    }
}

/// Makes the current state the one the handlers read; returns its JSON.
fn publish(cx: &Context, it: &Interactive, last: Option<&Value>) -> Value {
    let assets: Vec<String> = cx.shared.assets.iter().map(|(n, _)| n.clone()).collect();
    let mut state = super::state_json(it, last, &assets);
    state["refined"]["target"] = json!(cx.refine_to);
    let published = Published {
        frame: it.frame(),
        state: state.clone(),
    };
    *cx.shared.latest.write().unwrap_or_else(|e| e.into_inner()) = Some(Arc::new(published));
    state
}
