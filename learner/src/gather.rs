//! The learner's gather rule as a pure state machine (clock injected, no I/O), so that each rule of
//! ARCHITECTURE.md "Protocol decisions" has a unit test. The daemon feeds it actor liveliness and
//! chunks and asks [`Gather::ready`] after every event.
//!
//! Main type: [`Gather`]. Rules:
//! - an update starts when every live actor that is not *silent* has a chunk for the current
//!   version (or one at most `max_policy_lag` versions older), or when `gather_timeout_s` has passed
//!   with at least one chunk;
//! - `min_actors` gates only a fresh run's first update;
//! - chunks from the future or older than the lag allows are dropped (counted), as is an older
//!   chunk of an actor that sends a newer one; any chunk, stale or not, ends an actor's silence;
//! - a live actor without a chunk at a timeout becomes silent: it is not waited for again until it
//!   sends a chunk (a stuck actor costs one timeout, not one per iteration);
//! - a *newcomer* (a live actor that has not delivered a chunk since it came up) is waited for
//!   only a short while: once every other awaited actor has reported, at most as long again as the
//!   gather's first chunk took (at least [`NEWCOMER_MIN_WAIT_S`], at most the timeout). One that
//!   misses it becomes silent, so a forged liveliness token costs one short wait, once. A real
//!   actor that is slow to start loses nothing: its late chunk is used under `max_policy_lag` (or
//!   dropped as stale) and from then on it is waited for like every actor that has delivered.

use std::collections::{BTreeMap, BTreeSet};

use l3p_proto::RolloutChunk;

/// What became of an arriving chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkFate {
    Accepted,
    /// It replaced an older chunk of the same actor (that one is dropped).
    ReplacedOlder,
    /// Newer than the learner, or older than `max_policy_lag` allows.
    Stale,
}

/// The shortest wait for a newcomer's first chunk, in seconds (see the module docs).
pub const NEWCOMER_MIN_WAIT_S: f64 = 2.0;

/// Why an update may start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ready {
    /// Every live, non-silent actor has reported.
    Everyone,
    /// Every awaited actor that has delivered before has reported; the newcomers that have not
    /// yet sent a first chunk had their short wait.
    WithoutNewcomers,
    /// `gather_timeout_s` passed; the chunks that arrived are used.
    TimedOut,
}

/// The gather state of one learner (see the module docs for the rules).
#[derive(Debug, Clone)]
pub struct Gather {
    max_policy_lag: u64,
    min_actors: usize,
    timeout_s: f64,
    live: BTreeSet<String>,
    silent: BTreeSet<String>,
    /// Live actors that have delivered a chunk since they came up.
    delivered: BTreeSet<String>,
    pending: BTreeMap<String, RolloutChunk>,
    started_s: f64,
    /// When the current gather's first chunk arrived.
    first_chunk_s: Option<f64>,
    dropped: u64,
}

/// The id a chunk's actor has in liveliness: `<robot>/<actor>`.
pub fn actor_key(chunk: &RolloutChunk) -> String {
    format!("{}/{}", chunk.robot, chunk.actor_id)
}

impl Gather {
    /// A gather starting at `now_s` (seconds on any monotonic clock).
    pub fn new(max_policy_lag: u64, min_actors: usize, timeout_s: f64, now_s: f64) -> Self {
        Self {
            max_policy_lag,
            min_actors,
            timeout_s,
            live: BTreeSet::new(),
            silent: BTreeSet::new(),
            delivered: BTreeSet::new(),
            pending: BTreeMap::new(),
            started_s: now_s,
            first_chunk_s: None,
            dropped: 0,
        }
    }

    pub fn actor_up(&mut self, id: String) {
        self.live.insert(id);
    }

    pub fn actor_down(&mut self, id: &str) {
        self.silent.remove(id);
        self.delivered.remove(id);
        self.live.remove(id);
    }

    /// A chunk arrived at `now_s` while the learner is at `version`.
    pub fn chunk(&mut self, chunk: RolloutChunk, version: u64, now_s: f64) -> ChunkFate {
        // Even a stale chunk shows a real actor: it is waited for again (else a slow actor, once
        // silent, would stay silent and stale under a lag of 0).
        let id = actor_key(&chunk);
        self.silent.remove(&id);
        self.delivered.insert(id.clone());
        let lag = version.saturating_sub(chunk.policy_version);
        if chunk.policy_version > version || lag > self.max_policy_lag {
            self.dropped += 1;
            return ChunkFate::Stale;
        }
        self.first_chunk_s.get_or_insert(now_s);
        match self.pending.insert(id, chunk) {
            Some(_) => {
                self.dropped += 1;
                ChunkFate::ReplacedOlder
            }
            None => ChunkFate::Accepted,
        }
    }

    /// Whether an update may start at `now_s`; `first_update` is true before a fresh run's first.
    pub fn ready(&self, now_s: f64, first_update: bool) -> Option<Ready> {
        if self.pending.is_empty() {
            return None;
        }
        let enough_actors = !first_update || self.live.len() >= self.min_actors;
        let mut awaited = self.live.iter().filter(|id| !self.silent.contains(*id));
        let everyone = enough_actors
            && !self.live.is_empty()
            && awaited.clone().all(|id| self.pending.contains_key(id));
        // Only newcomers are missing: on a first update, once `min_actors` have reported.
        let newcomers_late = (!first_update || self.pending.len() >= self.min_actors)
            && awaited.all(|id| self.pending.contains_key(id) || !self.delivered.contains(id))
            && self
                .first_chunk_s
                .is_some_and(|first| now_s - first > self.newcomer_wait_s(first));
        if everyone {
            Some(Ready::Everyone)
        } else if newcomers_late {
            Some(Ready::WithoutNewcomers)
        } else if now_s - self.started_s > self.timeout_s {
            Some(Ready::TimedOut)
        } else {
            None
        }
    }

    /// How long newcomers are waited for after the gather's first chunk arrived at `first_s`.
    fn newcomer_wait_s(&self, first_s: f64) -> f64 {
        (first_s - self.started_s)
            .max(NEWCOMER_MIN_WAIT_S)
            .min(self.timeout_s)
    }

    /// Takes the chunks for the update and starts the next gather at `now_s`. After a timeout or a
    /// newcomer's short wait the live actors that sent nothing become silent; their ids are
    /// returned (for the log).
    pub fn take(&mut self, ready: Ready, now_s: f64) -> (Vec<RolloutChunk>, Vec<String>) {
        let mut newly_silent = Vec::new();
        if ready != Ready::Everyone {
            for id in self
                .live
                .iter()
                .filter(|id| !self.pending.contains_key(*id))
            {
                if self.silent.insert(id.clone()) {
                    newly_silent.push(id.clone());
                }
            }
        }
        self.started_s = now_s;
        self.first_chunk_s = None;
        let chunks = std::mem::take(&mut self.pending).into_values().collect();
        (chunks, newly_silent)
    }

    /// Starts the current gather's clock (its wait and its timeout) at `now_s`: the daemon calls it
    /// when the update that followed [`Gather::take`] has published its policy.
    pub fn restart(&mut self, now_s: f64) {
        self.started_s = now_s;
        if let Some(first) = &mut self.first_chunk_s {
            *first = first.max(now_s);
        }
    }

    /// Seconds since the current gather started.
    pub fn waited_s(&self, now_s: f64) -> f64 {
        now_s - self.started_s
    }

    pub fn live(&self) -> usize {
        self.live.len()
    }

    pub fn silent(&self) -> usize {
        self.silent.len()
    }

    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Chunks dropped so far (stale or replaced).
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk(robot: &str, actor: &str, version: u64) -> RolloutChunk {
        RolloutChunk::zeros("run", robot, actor, version, 1, 1, 1, 1)
    }

    fn two_actors(now: f64) -> Gather {
        let mut g = Gather::new(0, 2, 30.0, now);
        g.actor_up("a1/a".into());
        g.actor_up("go1/b".into());
        g
    }

    /// Two actors that have each delivered a chunk (version 0, taken at `now`); at version 1.
    fn two_delivered(now: f64) -> Gather {
        let mut g = two_actors(now);
        g.chunk(chunk("a1", "a", 0), 0, now);
        g.chunk(chunk("go1", "b", 0), 0, now);
        assert_eq!(g.ready(now, true), Some(Ready::Everyone));
        g.take(Ready::Everyone, now);
        g
    }

    #[test]
    fn an_update_waits_for_every_live_actor() {
        let mut g = two_actors(0.0);
        assert_eq!(g.ready(0.0, true), None);
        assert_eq!(g.chunk(chunk("a1", "a", 0), 0, 0.5), ChunkFate::Accepted);
        assert_eq!(g.ready(1.0, true), None);
        g.chunk(chunk("go1", "b", 0), 0, 1.0);
        assert_eq!(g.ready(1.0, true), Some(Ready::Everyone));
        let (chunks, silent) = g.take(Ready::Everyone, 1.0);
        assert_eq!((chunks.len(), silent.len(), g.pending()), (2, 0, 0));
    }

    #[test]
    fn min_actors_gates_only_the_first_update() {
        let mut g = Gather::new(0, 2, 30.0, 0.0);
        g.actor_up("a1/a".into());
        g.chunk(chunk("a1", "a", 0), 0, 0.5);
        assert_eq!(g.ready(1.0, true), None, "one of two required actors");
        assert_eq!(g.ready(1.0, false), Some(Ready::Everyone));
    }

    #[test]
    fn stale_future_and_replaced_chunks_are_dropped_and_counted() {
        let mut g = Gather::new(1, 1, 30.0, 0.0);
        g.actor_up("a1/a".into());
        assert_eq!(
            g.chunk(chunk("a1", "a", 3), 5, 0.0),
            ChunkFate::Stale,
            "lag 2 > 1"
        );
        assert_eq!(
            g.chunk(chunk("a1", "a", 6), 5, 0.0),
            ChunkFate::Stale,
            "from the future"
        );
        assert_eq!(
            g.chunk(chunk("a1", "a", 4), 5, 0.0),
            ChunkFate::Accepted,
            "lag 1"
        );
        assert_eq!(
            g.chunk(chunk("a1", "a", 5), 5, 0.0),
            ChunkFate::ReplacedOlder
        );
        assert_eq!(g.dropped(), 3);
        let (chunks, _) = g.take(Ready::Everyone, 0.0);
        assert_eq!(chunks[0].policy_version, 5, "the newer chunk is kept");
    }

    #[test]
    fn a_timeout_updates_with_what_arrived_and_needs_a_chunk() {
        let mut g = two_delivered(10.0);
        assert_eq!(g.ready(50.0, false), None, "nothing arrived: keep waiting");
        g.chunk(chunk("a1", "a", 1), 1, 11.0);
        assert_eq!(
            g.ready(39.0, false),
            None,
            "b has delivered before: waited for"
        );
        assert_eq!(g.ready(41.0, false), Some(Ready::TimedOut));
        let (chunks, silent) = g.take(Ready::TimedOut, 41.0);
        assert_eq!(chunks.len(), 1);
        assert_eq!(silent, ["go1/b"]);
        assert_eq!(g.waited_s(42.0), 1.0, "the next gather starts at the take");
    }

    #[test]
    fn the_timeout_counts_from_the_restart_after_the_update() {
        let mut g = two_delivered(1.0);
        // The update takes 30 s; the daemon restarts the clock once the policy is out.
        g.restart(31.0);
        assert_eq!(g.waited_s(32.0), 1.0);
        g.chunk(chunk("a1", "a", 1), 1, 32.0);
        assert_eq!(
            g.ready(60.0, false),
            None,
            "the 30 s timeout counts 29 s since the restart (59 s since the take)"
        );
        assert_eq!(g.ready(61.5, false), Some(Ready::TimedOut));
    }

    #[test]
    fn a_silent_actor_costs_one_timeout_until_it_sends_again() {
        let mut g = two_delivered(0.0);
        g.chunk(chunk("a1", "a", 1), 1, 1.0);
        let ready = g.ready(31.0, false).unwrap();
        assert_eq!(ready, Ready::TimedOut);
        g.take(ready, 31.0);
        assert_eq!(g.silent(), 1);
        // Next iteration: the silent actor is not waited for.
        g.chunk(chunk("a1", "a", 2), 2, 31.5);
        assert_eq!(g.ready(31.5, false), Some(Ready::Everyone));
        g.take(Ready::Everyone, 31.5);
        // It sends again, even a stale chunk: waited for again.
        g.chunk(chunk("go1", "b", 1), 3, 32.0);
        assert_eq!(g.silent(), 0);
        g.chunk(chunk("a1", "a", 3), 3, 32.5);
        assert_eq!(g.ready(40.0, false), None, "b is expected again");
    }

    #[test]
    fn an_actor_that_leaves_is_not_waited_for() {
        let mut g = two_actors(0.0);
        g.chunk(chunk("a1", "a", 0), 0, 0.5);
        assert_eq!(g.ready(1.0, false), None);
        g.actor_down("go1/b");
        assert_eq!(g.ready(1.0, false), Some(Ready::Everyone));
        assert_eq!((g.live(), g.silent()), (1, 0));
    }

    #[test]
    fn a_ghost_token_costs_one_short_wait_once() {
        // Two real actors deliver in 0.6 s per gather; a liveliness token that never sends joins.
        let mut g = two_delivered(0.0);
        g.actor_up("a1/ghost".into());
        g.chunk(chunk("a1", "a", 1), 1, 0.5);
        g.chunk(chunk("go1", "b", 1), 1, 0.6);
        assert_eq!(g.ready(2.4, false), None, "a newcomer gets a short wait");
        assert_eq!(
            g.ready(2.6, false),
            Some(Ready::WithoutNewcomers),
            "at most {NEWCOMER_MIN_WAIT_S} s after the first chunk, far below the 30 s timeout"
        );
        let (chunks, silent) = g.take(Ready::WithoutNewcomers, 2.6);
        assert_eq!((chunks.len(), silent), (2, vec!["a1/ghost".to_string()]));
        // From then on it costs nothing.
        g.chunk(chunk("a1", "a", 2), 2, 3.0);
        g.chunk(chunk("go1", "b", 2), 2, 3.1);
        assert_eq!(g.ready(3.1, false), Some(Ready::Everyone));
    }

    #[test]
    fn a_newcomer_waits_as_long_again_as_the_first_chunk_took() {
        // Real actors take 8 s to collect: a newcomer is waited for until 16 s.
        let mut g = two_delivered(0.0);
        g.actor_up("a1/new".into());
        g.chunk(chunk("a1", "a", 1), 1, 8.0);
        g.chunk(chunk("go1", "b", 1), 1, 8.5);
        assert_eq!(g.ready(15.9, false), None);
        g.chunk(chunk("a1", "new", 1), 1, 15.0);
        assert_eq!(g.ready(15.0, false), Some(Ready::Everyone));
    }

    #[test]
    fn a_slow_actor_that_has_delivered_is_never_cut_short() {
        // The same wait that drops a newcomer does not apply to a known, slow actor.
        let mut g = two_delivered(0.0);
        g.chunk(chunk("a1", "a", 1), 1, 0.5);
        assert_eq!(g.ready(20.0, false), None, "b is slow, not new");
        g.chunk(chunk("go1", "b", 1), 1, 25.0);
        assert_eq!(g.ready(25.0, false), Some(Ready::Everyone));
    }

    #[test]
    fn a_fresh_run_waits_for_newcomers_only_after_min_actors_reported() {
        let mut g = Gather::new(0, 2, 30.0, 0.0);
        for id in ["a1/a", "a1/b", "a1/ghost"] {
            g.actor_up(id.into());
        }
        g.chunk(chunk("a1", "a", 0), 0, 1.0);
        assert_eq!(g.ready(3.1, true), None, "one of the two required actors");
        g.chunk(chunk("a1", "b", 0), 0, 2.0);
        assert_eq!(
            g.ready(2.5, true),
            None,
            "the ghost's short wait runs from 1 s to 3 s"
        );
        assert_eq!(g.ready(3.1, true), Some(Ready::WithoutNewcomers));
    }

    #[test]
    fn a_restarted_actor_is_a_newcomer_again() {
        let mut g = two_delivered(0.0);
        g.actor_down("go1/b");
        g.actor_up("go1/b".into());
        g.chunk(chunk("a1", "a", 1), 1, 0.5);
        assert_eq!(g.ready(2.6, false), Some(Ready::WithoutNewcomers));
    }
}
