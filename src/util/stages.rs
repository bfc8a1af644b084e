//! The pipeline's stages: their wall times ([`StageTimes`], which every
//! stage takes to time itself, so that none imports the model for it), and
//! who is told when one starts: a front end (the command line's progress
//! line) registers one observer; the library only names its stages, and
//! costs nothing when none listens.

use std::sync::OnceLock;
use std::time::{Duration, Instant};

type Observer = Box<dyn Fn(&str) + Send + Sync>;

static OBSERVER: OnceLock<Observer> = OnceLock::new();

/// Registers the process's one observer of stage starts (later calls are ignored).
pub fn observe(f: impl Fn(&str) + Send + Sync + 'static) {
    let _ = OBSERVER.set(Box::new(f));
}

/// Tells the observer, if any, that the stage `name` starts.
pub fn started(name: &str) {
    if let Some(f) = OBSERVER.get() {
        f(name);
    }
}

/// Wall time per named stage, in order; then the stages that ran side by
/// side within one of those (see [`StageTimes::concurrently`]), which the
/// total leaves out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StageTimes(
    pub Vec<(&'static str, Duration)>,
    pub Vec<(&'static str, Duration)>,
);

impl StageTimes {
    /// Runs `f` and records its time under `name`.
    pub fn time<T>(&mut self, name: &'static str, f: impl FnOnce() -> T) -> T {
        // Work made ahead may pause between its stages.
        super::pause::point();
        started(name);
        let t0 = Instant::now();
        let out = f();
        self.0.push((name, t0.elapsed()));
        out
    }

    /// Runs `a` and `b` side by side (rayon's join) as the stage `name`;
    /// the stages each records go to the side list.
    pub fn concurrently<A: Send, B: Send>(
        &mut self,
        name: &'static str,
        a: impl FnOnce(&mut StageTimes) -> A + Send,
        b: impl FnOnce(&mut StageTimes) -> B + Send,
    ) -> (A, B) {
        let (mut ta, mut tb) = (StageTimes::default(), StageTimes::default());
        let t0 = Instant::now();
        let out = rayon::join(|| a(&mut ta), || b(&mut tb));
        self.0.push((name, t0.elapsed()));
        for t in [ta, tb] {
            self.1.extend(t.0.into_iter().chain(t.1));
        }
        out
    }

    /// Adds `other`'s stages, each to this one's of the same name (pushed
    /// when there is none): a stage run once per band is one line.
    pub fn absorb(&mut self, other: StageTimes) {
        for (list, more) in [(&mut self.0, other.0), (&mut self.1, other.1)] {
            for (name, d) in more {
                match list.iter_mut().find(|(n, _)| *n == name) {
                    Some(entry) => entry.1 += d,
                    None => list.push((name, d)),
                }
            }
        }
    }

    /// The stages' wall time (those run side by side counted once, as the stage they ran in).
    pub fn total(&self) -> Duration {
        self.0.iter().map(|(_, d)| *d).sum()
    }
}
