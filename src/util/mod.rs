//! Helpers every stage may use, depending on none of them: deterministic
//! randomness and content-hashed caches.

pub mod cache;
pub mod rng;
