//! Helpers every stage may use, depending on none of them: deterministic
//! randomness, content-hashed caches, and the temporary files a signal must remove.

pub mod cache;
pub mod cleanup;
pub mod rng;
