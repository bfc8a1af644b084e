//! Helpers every stage may use, depending on none of them: deterministic
//! randomness, content-hashed caches, the temporary files a signal must
//! remove, who is told which stage runs, the figures' font, and
//! containing a third-party parser's panic.

pub mod cache;
pub mod cleanup;
pub mod figure;
pub mod guard;
pub mod rng;
pub mod stages;
