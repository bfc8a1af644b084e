//! Helpers every stage may use, depending on none of them: deterministic
//! randomness, content-hashed caches, the temporary files a signal must
//! remove, who is told which stage runs, the figures' font, and
//! containing a third-party parser's panic, pause points for work made
//! ahead, a fast map and a grid of items by place.

pub mod cache;
pub mod cleanup;
pub mod figure;
pub mod guard;
pub mod near_lists;
pub mod pause;
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

/// This process's resident memory now (Linux: `VmRSS` in `/proc/self/status`), bytes.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
