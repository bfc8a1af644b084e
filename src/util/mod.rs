//! Helpers every stage may use, depending on none of them: deterministic
//! randomness, content-hashed caches, the temporary files a signal must
//! remove, and who is told which stage runs.

pub mod cache;
pub mod cleanup;
pub mod rng;
pub mod stages;
