//! Which policy an actor collects with next, as a pure state machine (no I/O), so that the rules
//! of ARCHITECTURE.md "Protocol decisions" have unit tests. The daemon loop feeds it the newest
//! announce it has seen and does what [`AnnounceTracker::next`] says.
//!
//! Main type: [`AnnounceTracker`]. Rules:
//! - collect once per (learner incarnation, version): a learner restarted from a checkpoint is
//!   followed even to a version collected before;
//! - a newer announce always wins;
//! - with `max_policy_lag` ≥ 1 and no new announce, keep collecting with the policy held, up to
//!   that many extra chunks per version (collection overlaps the learner's update).

use l3p_proto::PolicyAnnounce;

/// (learner incarnation, policy version): what a chunk is collected for.
pub type PolicyKey = (u64, u64);

fn key(a: &PolicyAnnounce) -> PolicyKey {
    (a.incarnation, a.version)
}

/// What to do now.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Next {
    /// Collect one chunk with this announce's policy (fetch it first if not held).
    Collect(PolicyAnnounce),
    /// Nothing to collect: wait for an announce.
    Wait,
}

/// The actor's view of the learner's announces (see the module docs for the rules).
#[derive(Debug, Clone, Default)]
pub struct AnnounceTracker {
    held: Option<PolicyAnnounce>,
    last_collected: Option<PolicyKey>,
    extra: u64,
}

impl AnnounceTracker {
    /// The decision given the newest announce seen since the last call, if any.
    pub fn next(&mut self, newest: Option<PolicyAnnounce>) -> Next {
        let fresh = newest.filter(|a| self.last_collected != Some(key(a)));
        match (fresh, &self.held) {
            (Some(a), _) => {
                self.extra = 0;
                Next::Collect(a)
            }
            (None, Some(a))
                if self.last_collected == Some(key(a)) && self.extra < a.max_policy_lag =>
            {
                self.extra += 1;
                Next::Collect(a.clone())
            }
            _ => Next::Wait,
        }
    }

    /// An announce that arrived while waiting: collect with it only if not collected yet.
    pub fn arrived(&mut self, a: PolicyAnnounce) -> Next {
        if self.last_collected == Some(key(&a)) {
            Next::Wait
        } else {
            self.extra = 0;
            Next::Collect(a)
        }
    }

    /// The policy of `a` was fetched and is the one held now.
    pub fn fetched(&mut self, a: &PolicyAnnounce) {
        self.held = Some(a.clone());
    }

    /// A chunk for `key` was sent.
    pub fn collected(&mut self, key: PolicyKey) {
        self.last_collected = Some(key);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn announce(incarnation: u64, version: u64, max_policy_lag: u64) -> PolicyAnnounce {
        PolicyAnnounce {
            wire_version: l3p_proto::WIRE_VERSION,
            run: "run".into(),
            version,
            incarnation,
            mode: "l3p".into(),
            robots: Vec::new(),
            max_policy_lag,
        }
    }

    /// Runs one collection of whatever `next` decides.
    fn collect(t: &mut AnnounceTracker, newest: Option<PolicyAnnounce>) -> Option<PolicyKey> {
        match t.next(newest) {
            Next::Collect(a) => {
                t.fetched(&a);
                t.collected(key(&a));
                Some(key(&a))
            }
            Next::Wait => None,
        }
    }

    #[test]
    fn each_version_is_collected_once_without_lag() {
        let mut t = AnnounceTracker::default();
        assert_eq!(collect(&mut t, None), None, "nothing announced yet");
        assert_eq!(collect(&mut t, Some(announce(1, 0, 0))), Some((1, 0)));
        assert_eq!(
            collect(&mut t, Some(announce(1, 0, 0))),
            None,
            "repeat announce"
        );
        assert_eq!(collect(&mut t, None), None);
        assert_eq!(collect(&mut t, Some(announce(1, 1, 0))), Some((1, 1)));
    }

    #[test]
    fn with_lag_the_held_policy_collects_that_many_extra_chunks() {
        let mut t = AnnounceTracker::default();
        assert_eq!(collect(&mut t, Some(announce(1, 4, 2))), Some((1, 4)));
        assert_eq!(collect(&mut t, None), Some((1, 4)), "extra 1");
        assert_eq!(collect(&mut t, None), Some((1, 4)), "extra 2");
        assert_eq!(collect(&mut t, None), None, "lag exhausted");
        // A newer announce resets the allowance.
        assert_eq!(collect(&mut t, Some(announce(1, 5, 2))), Some((1, 5)));
        assert_eq!(collect(&mut t, None), Some((1, 5)));
    }

    #[test]
    fn a_restarted_learner_is_followed_to_a_version_collected_before() {
        let mut t = AnnounceTracker::default();
        collect(&mut t, Some(announce(1, 7, 0)));
        // The learner restarts from its checkpoint at version 7: new incarnation, same version.
        assert_eq!(collect(&mut t, Some(announce(2, 7, 0))), Some((2, 7)));
    }

    #[test]
    fn an_announce_arriving_while_waiting_counts_only_if_new() {
        let mut t = AnnounceTracker::default();
        collect(&mut t, Some(announce(1, 0, 0)));
        assert_eq!(t.arrived(announce(1, 0, 0)), Next::Wait);
        assert_eq!(
            t.arrived(announce(1, 1, 0)),
            Next::Collect(announce(1, 1, 0))
        );
    }
}
