//! Containing a third-party parser's panic: a bug there is a malformed
//! input to report, not a reason to stop the process. While a closure runs
//! under [`contain`], [`is_containing`] tells a front end's panic hook to
//! stay quiet.

use std::cell::Cell;

thread_local! {
    static CONTAINING: Cell<bool> = const { Cell::new(false) };
}

/// Runs `f`; `None` if it panicked.
pub fn contain<T>(f: impl FnOnce() -> T) -> Option<T> {
    let before = CONTAINING.replace(true);
    let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).ok();
    CONTAINING.set(before);
    out
}

/// Whether this thread runs inside [`contain`].
pub fn is_containing() -> bool {
    CONTAINING.get()
}
