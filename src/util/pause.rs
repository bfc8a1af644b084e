//! Pause points for work made ahead of need.
//!
//! A pool that makes work nobody waits for yet (`arlux serve`'s session
//! for a change of lights) gives each of its threads a check; every
//! stage's start ([`StageTimes::time`](super::stages::StageTimes::time))
//! and the longest loops (the links' refinement, a pair of roots at a
//! time; the room's solution per light, a light at a time) call [`point`],
//! where the check may wait, e.g. while the user's edit is
//! served, so that the work made ahead takes neither its cores nor its
//! caches; or it may [`cancel`] the work, when what it was for has gone,
//! and [`cancellable`] returns None. On any other thread a point is one
//! thread-local read.

use std::cell::RefCell;
use std::sync::Arc;

/// What a thread's pause points call.
pub type Check = Arc<dyn Fn() + Send + Sync>;

thread_local! {
    static CHECK: RefCell<Option<Check>> = const { RefCell::new(None) };
}

/// Gives the calling thread `check`, called at each pause point it meets
/// from now on (a pool's start handler gives it to each of its threads).
pub fn set_check(check: Check) {
    CHECK.with_borrow_mut(|c| *c = Some(check));
}

/// A point where work made ahead may pause: calls the thread's check, if
/// it has one.
pub fn point() {
    // Cloned out of the cell: a check may itself run code that meets a point.
    if let Some(check) = CHECK.with_borrow(|c| c.clone()) {
        check();
    }
}

/// What [`cancel`] unwinds with.
struct Cancelled;

/// Cancels the work the calling thread runs for [`cancellable`]: called
/// from a check, it unwinds (without the panic hook's message) to there,
/// through the rayon tasks between (each passes it on to its caller).
/// Unwinding, rather than an error returned from every pause point up
/// through the stages that have one: the work is given up whole, and its
/// stages hold nothing another thread sees (their files are written
/// atomically, between pause points).
pub fn cancel() -> ! {
    std::panic::resume_unwind(Box::new(Cancelled))
}

/// Runs `work`; None where a check called [`cancel`] in it. Other panics
/// go on unwinding.
pub fn cancellable<R>(work: impl FnOnce() -> R) -> Option<R> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)) {
        Ok(r) => Some(r),
        Err(payload) if payload.is::<Cancelled>() => None,
        Err(payload) => std::panic::resume_unwind(payload),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn only_the_threads_given_a_check_call_it_at_their_points() {
        let calls = Arc::new(AtomicUsize::new(0));
        let counted = Arc::clone(&calls);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .start_handler(move |_| {
                let counted = Arc::clone(&counted);
                set_check(Arc::new(move || {
                    counted.fetch_add(1, Ordering::Relaxed);
                }))
            })
            .build()
            .unwrap();
        use rayon::prelude::*;
        pool.install(|| (0..100).into_par_iter().for_each(|_| point()));
        assert_eq!(calls.load(Ordering::Relaxed), 100);
        // This thread has none: its points call nothing.
        point();
        std::thread::spawn(point).join().unwrap();
        assert_eq!(calls.load(Ordering::Relaxed), 100);
    }

    #[test]
    fn a_check_that_cancels_ends_the_work_on_a_pool_and_nothing_else() {
        use rayon::prelude::*;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .start_handler(|_| set_check(Arc::new(|| cancel())))
            .build()
            .unwrap();
        let done = AtomicUsize::new(0);
        let work = || {
            (0..1000).into_par_iter().for_each(|_| {
                point();
                done.fetch_add(1, Ordering::Relaxed);
            });
            7
        };
        assert_eq!(cancellable(|| pool.install(work)), None);
        assert_eq!(done.load(Ordering::Relaxed), 0);
        // Without a check the same work runs whole.
        assert_eq!(cancellable(work), Some(7));
        assert_eq!(done.load(Ordering::Relaxed), 1000);
        // Another panic is not taken for a cancel.
        let other = std::panic::catch_unwind(|| cancellable(|| panic!("a bug")));
        assert!(other.is_err());
    }
}
