//! Rays traced and the time spent in Embree tracing them, per kind of
//! query, when arlux is built with the `ray-timing` feature: what an
//! update's rays cost, against the rest of its work, in the benches'
//! reports (`update_stages`). Without the feature nothing is counted and
//! [`take`] gives None: a clock read per query would cost single rays
//! about a fifth more.

use std::time::Duration;

/// A kind of query: closest hit or occlusion, one ray or a packet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Intersect1,
    Occluded1,
    IntersectPacket,
    OccludedPacket,
}

impl Kind {
    pub const ALL: [Kind; 4] = [
        Kind::Intersect1,
        Kind::Occluded1,
        Kind::IntersectPacket,
        Kind::OccludedPacket,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Kind::Intersect1 => "closest hit, single rays",
            Kind::Occluded1 => "occlusion, single rays",
            Kind::IntersectPacket => "closest hit, packets",
            Kind::OccludedPacket => "occlusion, packets",
        }
    }
}

/// Per kind, the rays traced and the CPU time spent in its queries.
pub type Totals = [(u64, Duration); 4];

#[cfg(feature = "ray-timing")]
mod counted {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::time::Instant;

    static RAYS: [AtomicU64; 4] = [const { AtomicU64::new(0) }; 4];
    static NANOS: [AtomicU64; 4] = [const { AtomicU64::new(0) }; 4];

    /// A query being timed: counted when dropped.
    pub struct Timed(Kind, Instant, u64);

    impl Drop for Timed {
        fn drop(&mut self) {
            let k = self.0 as usize;
            let nanos = u64::try_from(self.1.elapsed().as_nanos()).unwrap_or(u64::MAX);
            NANOS[k].fetch_add(nanos, Ordering::Relaxed);
            RAYS[k].fetch_add(self.2, Ordering::Relaxed);
        }
    }

    #[inline]
    pub fn start(kind: Kind, rays: usize) -> Timed {
        Timed(kind, Instant::now(), rays as u64)
    }

    pub fn take() -> Option<Totals> {
        Some(std::array::from_fn(|k| {
            (
                RAYS[k].swap(0, Ordering::Relaxed),
                Duration::from_nanos(NANOS[k].swap(0, Ordering::Relaxed)),
            )
        }))
    }
}

#[cfg(not(feature = "ray-timing"))]
mod counted {
    use super::*;

    /// Nothing is timed without the feature.
    pub struct Timed;

    #[inline(always)]
    pub fn start(_: Kind, _: usize) -> Timed {
        Timed
    }

    pub fn take() -> Option<Totals> {
        None
    }
}

pub(super) use counted::start;
/// The totals since the last call, reset (None: built without `ray-timing`).
pub use counted::take;
