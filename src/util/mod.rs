//! Helpers every stage may use, depending on none of them: deterministic
//! randomness, content-hashed caches, the temporary files a signal must
//! remove, who is told which stage runs, the figures' font, and
//! containing a third-party parser's panic, and a fast map.

pub mod cache;
pub mod cleanup;
pub mod figure;
pub mod guard;
pub mod rng;
pub mod stages;

/// A hash map with foldhash's fixed-seed hasher: for the maps an update
/// fills per vertex and patch (std's SipHash, built against flooding,
/// took a twentieth of a 24,768-triangle object's update), and the same
/// on every run.
pub type FastMap<K, V> = std::collections::HashMap<K, V, foldhash::fast::FixedState>;

/// An empty [`FastMap`].
pub fn fast_map<K, V>() -> FastMap<K, V> {
    FastMap::with_hasher(foldhash::fast::FixedState::default())
}
