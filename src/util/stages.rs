//! Who is told when a stage starts: a front end (the command line's
//! progress line) registers one observer; the library only names its
//! stages, and costs nothing when none listens.

use std::sync::OnceLock;

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
