//! At-least-once tracking of spout tuples (opt-in per spout).
//!
//! Each tuple a tracked spout emits is a *root*. Every delivery of a tuple
//! descended from it adds one to the root's outstanding count; every tuple
//! executed subtracts one, after its own emits have been counted, so the count
//! reaches zero exactly when the whole tree is processed. A failure (explicit,
//! a drop, a panic or a timeout) fails the root at once. Roots carry an
//! attempt number so that late news from a replaced attempt is ignored.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::runtime::control::TaskSignal;

use crate::message::Payload;

/// How a root ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Outcome {
    Acked,
    Failed,
}

#[derive(Debug)]
struct Root {
    attempt: u32,
    outstanding: u64,
    stream: usize,
    payload: Payload,
    deadline: Instant,
}

#[derive(Debug, Default)]
struct State {
    roots: HashMap<u64, Root>,
    finished: Vec<(u64, Outcome)>,
}

/// The roots of one spout task.
#[derive(Debug)]
pub(crate) struct AckTracker {
    state: Mutex<State>,
    spout: Arc<TaskSignal>,
}

/// A tuple's link to its root; dropped without `complete`/`fail` it does
/// nothing (the root then times out).
#[derive(Debug)]
pub(crate) struct Anchor {
    tracker: Arc<AckTracker>,
    seq: u64,
    attempt: u32,
}

/// A root ready to be replayed.
#[derive(Debug)]
pub(crate) struct Replay {
    pub(crate) seq: u64,
    pub(crate) attempt: u32,
    pub(crate) stream: usize,
    pub(crate) payload: Payload,
}

impl AckTracker {
    pub(crate) fn new(spout: Arc<TaskSignal>) -> Arc<Self> {
        Arc::new(AckTracker { state: Mutex::new(State::default()), spout })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Starts tracking a root; the returned anchor holds it open until
    /// completed (after the emit has delivered its tuples).
    pub(crate) fn begin(
        self: &Arc<Self>,
        seq: u64,
        attempt: u32,
        stream: usize,
        payload: Payload,
        deadline: Instant,
    ) -> Anchor {
        self.lock().roots.insert(seq, Root { attempt, outstanding: 1, stream, payload, deadline });
        Anchor { tracker: self.clone(), seq, attempt }
    }

    /// Roots still open.
    pub(crate) fn pending(&self) -> usize {
        self.lock().roots.len()
    }

    /// Takes the roots that finished since the last call; failed roots come
    /// with what is needed to replay them.
    pub(crate) fn take_finished(&self, out: &mut Vec<(u64, Outcome, Option<Replay>)>) {
        let mut s = self.lock();
        let finished = std::mem::take(&mut s.finished);
        for (seq, outcome) in finished {
            let root = s.roots.remove(&seq);
            let replay = match (outcome, root) {
                (Outcome::Failed, Some(r)) => {
                    Some(Replay { seq, attempt: r.attempt, stream: r.stream, payload: r.payload })
                }
                _ => None,
            };
            out.push((seq, outcome, replay));
        }
    }

    /// Fails every root whose deadline has passed.
    pub(crate) fn expire(&self, now: Instant) -> usize {
        let mut s = self.lock();
        let expired: Vec<u64> =
            s.roots.iter().filter(|(_, r)| r.deadline <= now && r.outstanding > 0).map(|(k, _)| *k).collect();
        for seq in &expired {
            if let Some(r) = s.roots.get_mut(seq) {
                r.outstanding = 0;
            }
            s.finished.push((*seq, Outcome::Failed));
        }
        expired.len()
    }

    fn settle(&self, seq: u64, attempt: u32, outcome: Outcome) {
        let mut s = self.lock();
        let Some(root) = s.roots.get_mut(&seq) else {
            return;
        };
        if root.attempt != attempt || root.outstanding == 0 {
            return;
        }
        match outcome {
            Outcome::Acked => {
                root.outstanding -= 1;
                if root.outstanding > 0 {
                    return;
                }
            }
            Outcome::Failed => root.outstanding = 0,
        }
        s.finished.push((seq, outcome));
        drop(s);
        self.spout.wake();
    }
}

impl Anchor {
    /// A new anchor for a delivered child tuple.
    pub(crate) fn child(&self) -> Anchor {
        let mut s = self.tracker.lock();
        if let Some(root) = s.roots.get_mut(&self.seq)
            && root.attempt == self.attempt
            && root.outstanding > 0
        {
            root.outstanding += 1;
        }
        Anchor { tracker: self.tracker.clone(), seq: self.seq, attempt: self.attempt }
    }

    /// This tuple was processed.
    pub(crate) fn complete(self) {
        self.tracker.settle(self.seq, self.attempt, Outcome::Acked);
    }

    /// This tuple failed: the whole root fails.
    pub(crate) fn fail(self) {
        self.tracker.settle(self.seq, self.attempt, Outcome::Failed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn tracker() -> Arc<AckTracker> {
        AckTracker::new(Arc::new(TaskSignal::default()))
    }

    fn finished(t: &AckTracker) -> Vec<(u64, Outcome)> {
        let mut out = Vec::new();
        t.take_finished(&mut out);
        out.into_iter().map(|(s, o, _)| (s, o)).collect()
    }

    #[test]
    fn acks_when_the_whole_tree_is_done() {
        let t = tracker();
        let far = Instant::now() + Duration::from_secs(60);
        let root = t.begin(0, 0, 0, Arc::new(1u8), far);
        let a = root.child();
        let b = root.child();
        root.complete();
        let a1 = a.child();
        a.complete();
        b.complete();
        assert!(finished(&t).is_empty());
        a1.complete();
        assert_eq!(finished(&t), vec![(0, Outcome::Acked)]);
        assert_eq!(t.pending(), 0);
    }

    #[test]
    fn a_failed_branch_fails_the_root_once_and_offers_replay() {
        let t = tracker();
        let far = Instant::now() + Duration::from_secs(60);
        let root = t.begin(5, 0, 2, Arc::new(1u8), far);
        let a = root.child();
        let b = root.child();
        root.complete();
        a.fail();
        b.complete();
        let mut out = Vec::new();
        t.take_finished(&mut out);
        assert_eq!(out.len(), 1);
        let (seq, outcome, replay) = &out[0];
        assert_eq!((*seq, *outcome), (5, Outcome::Failed));
        assert_eq!(replay.as_ref().unwrap().stream, 2);
    }

    #[test]
    fn timeouts_fail_and_stale_attempts_are_ignored() {
        let t = tracker();
        let now = Instant::now();
        let root = t.begin(1, 0, 0, Arc::new(1u8), now);
        let stale = root.child();
        root.complete();
        assert_eq!(t.expire(now + Duration::from_millis(1)), 1);
        assert_eq!(finished(&t), vec![(1, Outcome::Failed)]);
        let retry = t.begin(1, 1, 0, Arc::new(1u8), now + Duration::from_secs(60));
        stale.complete();
        assert!(finished(&t).is_empty());
        retry.complete();
        assert_eq!(finished(&t), vec![(1, Outcome::Acked)]);
    }
}
