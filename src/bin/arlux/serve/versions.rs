//! One truth across tabs: every edit may name the state version it was
//! made on and the page (client) it comes from. An edit made on a version
//! that another page has since changed is stale: refused (409) with the
//! new state, so a tab never overwrites what it has not seen. A page's own
//! edits in flight (a drag's moves sent before the last reply came) are
//! not stale to it.

use std::collections::VecDeque;

/// Edits remembered, newest last; an edit made on a version older than
/// these is stale.
const REMEMBERED: usize = 4096;

/// What an edit says it was made on.
#[derive(Debug, Clone, Default, serde::Deserialize)]
pub(crate) struct Stamp {
    /// The state version the page showed (none: not checked).
    pub version: Option<u64>,
    /// The page's own id, random per tab.
    pub client: Option<String>,
}

/// Which page made each recent version.
#[derive(Debug, Default)]
pub(crate) struct History {
    /// (the version an edit produced, the page that made it).
    made: VecDeque<(u64, Option<String>)>,
}

impl History {
    /// Records that `client`'s edit produced `version`.
    pub fn record(&mut self, version: u64, client: Option<String>) {
        if self.made.len() == REMEMBERED {
            self.made.pop_front();
        }
        self.made.push_back((version, client));
    }

    /// Whether an edit stamped `stamp` is stale at `current`: made on an
    /// older version some other page (or an unnamed one) has changed
    /// since, or on one this session never had.
    pub fn stale(&self, stamp: &Stamp, current: u64) -> bool {
        let Some(seen) = stamp.version else {
            return false;
        };
        if seen >= current {
            return seen > current;
        }
        let since: Vec<&(u64, Option<String>)> =
            self.made.iter().filter(|(v, _)| *v > seen).collect();
        let remembered = (current - seen) as usize == since.len();
        let own = since
            .iter()
            .all(|(_, c)| c.is_some() && c.as_deref() == stamp.client.as_deref());
        !(remembered && own)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamp(version: u64, client: &str) -> Stamp {
        Stamp {
            version: Some(version),
            client: Some(client.into()),
        }
    }

    #[test]
    fn another_page_s_edit_makes_an_older_version_stale_and_one_s_own_does_not() {
        let mut h = History::default();
        assert!(!h.stale(&stamp(0, "a"), 0));
        h.record(1, Some("a".into()));
        // Page a's next move, sent before its first reply: not stale.
        assert!(!h.stale(&stamp(0, "a"), 1));
        // Page b still shows version 0: stale; once it has 1, not.
        assert!(h.stale(&stamp(0, "b"), 1));
        assert!(!h.stale(&stamp(1, "b"), 1));
        h.record(2, Some("b".into()));
        assert!(h.stale(&stamp(1, "a"), 2));
        // A version the session never had, and an unstamped edit.
        assert!(h.stale(&stamp(7, "a"), 2));
        assert!(!h.stale(&Stamp::default(), 2));
        // An edit of no named page makes every older stamp stale.
        h.record(3, None);
        assert!(h.stale(&stamp(2, "b"), 3));
    }
}
