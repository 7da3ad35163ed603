//! Bounded input queue of one subscription at one consumer task.
//!
//! Invariant: with `block`, messages queued plus messages handed to the task
//! and not yet executed never exceed the bound; with the drop policies the
//! bound covers waiting messages only (one already handed over can no longer
//! be dropped). Every message accepted is eventually *resolved*: executed,
//! dropped, or discarded at shutdown. Shutdown detection compares the
//! accepted and resolved totals.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use tokio::sync::Notify;

use crate::runtime::control::TaskSignal;

use crate::grouping::OverflowPolicy;
use crate::tuple::Tuple;

/// The result of a push.
#[derive(Debug)]
pub(crate) enum Push {
    /// Queued (possibly after waiting for room).
    Queued,
    /// Queued, but this older tuple was evicted (drop_oldest) or the pushed
    /// tuple itself was refused (drop_newest). It is counted as dropped.
    Dropped(Tuple),
    /// The consumer has exited or the run is aborting; the tuple is returned.
    Closed(Tuple),
}

#[derive(Debug, Default)]
struct State {
    buf: VecDeque<Tuple>,
    /// Handed to the consumer, not yet released.
    taken: usize,
    closed: bool,
    max_depth: usize,
    blocked_producers: usize,
    /// Tuples that entered the queue.
    accepted: u64,
    /// Tuples executed, evicted or discarded.
    resolved: u64,
}

/// Loss counters of one queue.
#[derive(Debug, Default)]
pub(crate) struct QueueCounters {
    /// Tuples lost to a drop policy.
    pub(crate) dropped: AtomicU64,
    /// Tuples that arrived after the consumer exited, or were left queued
    /// when the run aborted.
    pub(crate) undelivered: AtomicU64,
}

/// A bounded multi-producer, single-consumer queue.
#[derive(Debug)]
pub(crate) struct EdgeQueue {
    state: Mutex<State>,
    capacity: usize,
    policy: OverflowPolicy,
    room: Notify,
    consumer: Arc<TaskSignal>,
    pub(crate) counters: QueueCounters,
}

impl EdgeQueue {
    /// A queue that wakes `consumer` when it stops being empty.
    pub(crate) fn new(capacity: usize, policy: OverflowPolicy, consumer: Arc<TaskSignal>) -> Self {
        assert!(capacity > 0, "queue capacity must be positive");
        EdgeQueue {
            state: Mutex::new(State::default()),
            capacity,
            policy,
            room: Notify::new(),
            consumer,
            counters: QueueCounters::default(),
        }
    }

    fn occupied(&self, s: &State) -> usize {
        match self.policy {
            OverflowPolicy::Block => s.buf.len() + s.taken,
            _ => s.buf.len(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // A poisoned lock only means another thread panicked while holding it;
        // the queue's state is always consistent between statements.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Offers a tuple, waiting for room under `block`; time spent waiting is
    /// added to `blocked`.
    pub(crate) async fn push(&self, tuple: Tuple, blocked: &mut std::time::Duration) -> Push {
        let mut tuple = Some(tuple);
        loop {
            let notified = {
                let mut s = self.lock();
                if s.closed {
                    self.counters.undelivered.fetch_add(1, Ordering::Relaxed);
                    return Push::Closed(tuple.take().expect("present"));
                }
                if self.occupied(&s) < self.capacity {
                    return self.enqueue(s, tuple.take().expect("present"), None);
                }
                match self.policy {
                    OverflowPolicy::DropNewest => {
                        self.counters.dropped.fetch_add(1, Ordering::Relaxed);
                        return Push::Dropped(tuple.take().expect("present"));
                    }
                    OverflowPolicy::DropOldest => {
                        let victim = s.buf.pop_front().expect("full drop_oldest queue is non-empty");
                        self.counters.dropped.fetch_add(1, Ordering::Relaxed);
                        s.resolved += 1;
                        return self.enqueue(s, tuple.take().expect("present"), Some(victim));
                    }
                    OverflowPolicy::Block => {
                        s.blocked_producers += 1;
                        // Register for a wake-up before the lock is released,
                        // so a release in between cannot be missed.
                        let mut notified = Box::pin(self.room.notified());
                        notified.as_mut().enable();
                        notified
                    }
                }
            };
            let waited = std::time::Instant::now();
            notified.await;
            *blocked += waited.elapsed();
            self.lock().blocked_producers -= 1;
        }
    }

    /// Offers a producer's batch, front first, under one lock per pass:
    /// as many as there is room for are queued; under `block` the rest
    /// waits for room if `wait`, else stays in `tuples` (the caller
    /// delivers elsewhere first and comes back); the drop policies drop
    /// per tuple, exactly as that many single pushes would. Evicted or
    /// refused tuples with an acking anchor are appended to `failed` (the
    /// caller fails their trees); others are dropped here. Returns whether
    /// the queue is closed (everything left was refused and counted as
    /// undelivered).
    pub(crate) async fn push_batch(
        &self,
        tuples: &mut Vec<Tuple>,
        wait: bool,
        blocked: &mut std::time::Duration,
        failed: &mut Vec<Tuple>,
    ) -> bool {
        let keep_failed = |t: Tuple, failed: &mut Vec<Tuple>| {
            if t.anchor.is_some() {
                failed.push(t);
            }
        };
        while !tuples.is_empty() {
            let notified = {
                let mut s = self.lock();
                if s.closed {
                    self.counters.undelivered.fetch_add(tuples.len() as u64, Ordering::Relaxed);
                    tuples.drain(..).for_each(|t| keep_failed(t, failed));
                    return true;
                }
                let was_empty = s.buf.is_empty();
                let room = self.capacity.saturating_sub(self.occupied(&s));
                let fits = room.min(tuples.len());
                s.buf.extend(tuples.drain(..fits));
                s.accepted += fits as u64;
                if !tuples.is_empty() {
                    match self.policy {
                        OverflowPolicy::DropNewest => {
                            self.counters.dropped.fetch_add(tuples.len() as u64, Ordering::Relaxed);
                            tuples.drain(..).for_each(|t| keep_failed(t, failed));
                        }
                        OverflowPolicy::DropOldest => {
                            // Each arrival evicts the oldest waiting tuple
                            // (an earlier arrival of this batch, once the
                            // older ones are gone).
                            let n = tuples.len() as u64;
                            for t in tuples.drain(..) {
                                match s.buf.pop_front() {
                                    Some(victim) => {
                                        s.buf.push_back(t);
                                        keep_failed(victim, failed);
                                    }
                                    // Everything is taken (a queue of
                                    // handed-over tuples): the arrival
                                    // itself is the oldest left to drop.
                                    None => keep_failed(t, failed),
                                }
                            }
                            self.counters.dropped.fetch_add(n, Ordering::Relaxed);
                            s.accepted += n;
                            s.resolved += n;
                        }
                        OverflowPolicy::Block => {}
                    }
                }
                let depth = s.buf.len() + s.taken;
                s.max_depth = s.max_depth.max(depth);
                let wake = was_empty && !s.buf.is_empty() && self.consumer.is_parking();
                let notified = if tuples.is_empty() || !wait {
                    None
                } else {
                    s.blocked_producers += 1;
                    let mut notified = Box::pin(self.room.notified());
                    notified.as_mut().enable();
                    Some(notified)
                };
                drop(s);
                if wake {
                    self.consumer.wake();
                }
                match notified {
                    Some(n) => n,
                    None => return false,
                }
            };
            let waited = std::time::Instant::now();
            notified.await;
            *blocked += waited.elapsed();
            self.lock().blocked_producers -= 1;
        }
        false
    }

    fn enqueue(&self, mut s: std::sync::MutexGuard<'_, State>, tuple: Tuple, victim: Option<Tuple>) -> Push {
        let was_empty = s.buf.is_empty();
        s.buf.push_back(tuple);
        s.accepted += 1;
        let depth = s.buf.len() + s.taken;
        s.max_depth = s.max_depth.max(depth);
        let wake = was_empty && self.consumer.is_parking();
        drop(s);
        if wake {
            self.consumer.wake();
        }
        match victim {
            Some(v) => Push::Dropped(v),
            None => Push::Queued,
        }
    }

    /// Moves up to `max` waiting tuples into `out`; returns how many. They
    /// must be given back with [`release`](Self::release) once executed.
    pub(crate) fn take(&self, out: &mut VecDeque<Tuple>, max: usize) -> usize {
        let mut s = self.lock();
        let n = s.buf.len().min(max);
        out.extend(s.buf.drain(..n));
        s.taken += n;
        n
    }

    /// Marks `n` taken tuples as executed, making room for producers.
    pub(crate) fn release(&self, n: usize) {
        if n == 0 {
            return;
        }
        let wake = {
            let mut s = self.lock();
            s.taken -= n;
            s.resolved += n as u64;
            s.blocked_producers > 0
        };
        if wake {
            self.room.notify_waiters();
        }
    }

    /// Refuses further tuples and discards what is waiting (counted as
    /// undelivered); wakes blocked producers. Returns the discarded tuples
    /// so their acking trees can be failed.
    pub(crate) fn close(&self) -> Vec<Tuple> {
        let discarded: Vec<Tuple> = {
            let mut s = self.lock();
            s.closed = true;
            s.resolved += s.buf.len() as u64;
            s.buf.drain(..).collect()
        };
        self.counters.undelivered.fetch_add(discarded.len() as u64, Ordering::Relaxed);
        self.room.notify_waiters();
        discarded
    }

    /// (accepted, resolved) totals, read together.
    pub(crate) fn totals(&self) -> (u64, u64) {
        let s = self.lock();
        (s.accepted, s.resolved)
    }

    /// The deepest the queue has been (waiting + handed over).
    pub(crate) fn max_depth(&self) -> usize {
        self.lock().max_depth
    }

    /// The queue's bound.
    pub(crate) fn capacity(&self) -> usize {
        self.capacity
    }

    /// Waiting + handed-over tuples now.
    pub(crate) fn depth(&self) -> usize {
        let s = self.lock();
        s.buf.len() + s.taken
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tuple::Source;

    fn tuple(i: u64) -> Tuple {
        Tuple { source: Source::Peer { task: 0 }.interned(), payload: Arc::new(i), anchor: None }
    }

    fn value(t: &Tuple) -> u64 {
        *t.get::<u64>().unwrap()
    }

    fn run<F: std::future::Future>(f: F) -> F::Output {
        tokio::runtime::Builder::new_current_thread().enable_time().build().unwrap().block_on(f)
    }

    #[test]
    fn drop_oldest_keeps_the_newest_and_counts() {
        let q = EdgeQueue::new(3, OverflowPolicy::DropOldest, Arc::new(TaskSignal::default()));
        let mut evicted = Vec::new();
        run(async {
            for i in 0..10 {
                if let Push::Dropped(t) = q.push(tuple(i), &mut Default::default()).await {
                    evicted.push(value(&t));
                }
            }
        });
        let mut out = VecDeque::new();
        assert_eq!(q.take(&mut out, 100), 3);
        assert_eq!(out.iter().map(value).collect::<Vec<_>>(), vec![7, 8, 9]);
        assert_eq!(evicted, (0..7).collect::<Vec<_>>());
        assert_eq!(q.counters.dropped.load(Ordering::Relaxed), 7);
    }

    #[test]
    fn drop_newest_refuses_arrivals() {
        let q = EdgeQueue::new(2, OverflowPolicy::DropNewest, Arc::new(TaskSignal::default()));
        run(async {
            for i in 0..5 {
                q.push(tuple(i), &mut Default::default()).await;
            }
        });
        let mut out = VecDeque::new();
        q.take(&mut out, 100);
        assert_eq!(out.iter().map(value).collect::<Vec<_>>(), vec![0, 1]);
        assert_eq!(q.counters.dropped.load(Ordering::Relaxed), 3);
    }

    #[test]
    fn block_counts_taken_tuples_against_the_bound() {
        let q = Arc::new(EdgeQueue::new(2, OverflowPolicy::Block, Arc::new(TaskSignal::default())));
        let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_time().build().unwrap();
        rt.block_on(async {
            q.push(tuple(0), &mut Default::default()).await;
            q.push(tuple(1), &mut Default::default()).await;
            let mut out = VecDeque::new();
            assert_eq!(q.take(&mut out, 1), 1);
            let q2 = q.clone();
            let producer = tokio::spawn(async move { q2.push(tuple(2), &mut Default::default()).await });
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
            assert!(!producer.is_finished(), "a full block queue must hold the producer");
            assert_eq!(q.depth(), 2);
            q.release(1);
            assert!(matches!(producer.await.unwrap(), Push::Queued));
            assert_eq!(q.depth(), 2);
        });
    }

    fn batch(range: std::ops::Range<u64>) -> Vec<Tuple> {
        range.map(tuple).collect()
    }

    #[test]
    fn a_batch_is_dropped_per_tuple_as_single_pushes_would_be() {
        // drop_oldest: each arrival past the bound evicts the oldest.
        let q = EdgeQueue::new(3, OverflowPolicy::DropOldest, Arc::new(TaskSignal::default()));
        let (mut tuples, mut failed) = (batch(0..4), Vec::new());
        run(q.push_batch(&mut tuples, true, &mut Default::default(), &mut failed));
        let (mut more, mut failed) = (batch(4..10), failed);
        run(q.push_batch(&mut more, true, &mut Default::default(), &mut failed));
        assert!(tuples.is_empty() && more.is_empty() && failed.is_empty(), "no anchors to fail");
        let mut out = VecDeque::new();
        assert_eq!(q.take(&mut out, 100), 3);
        assert_eq!(out.iter().map(value).collect::<Vec<_>>(), vec![7, 8, 9]);
        assert_eq!(q.counters.dropped.load(Ordering::Relaxed), 7);
        q.release(3);
        assert_eq!(q.totals(), (10, 10), "every arrival accepted, every one resolved");

        // drop_newest: the arrivals past the bound are refused.
        let q = EdgeQueue::new(2, OverflowPolicy::DropNewest, Arc::new(TaskSignal::default()));
        let mut tuples = batch(0..5);
        run(q.push_batch(&mut tuples, true, &mut Default::default(), &mut Vec::new()));
        let mut out = VecDeque::new();
        q.take(&mut out, 100);
        assert_eq!(out.iter().map(value).collect::<Vec<_>>(), vec![0, 1]);
        assert_eq!(q.counters.dropped.load(Ordering::Relaxed), 3);
    }

    #[test]
    fn a_batch_to_a_full_block_queue_leaves_the_rest_unless_told_to_wait() {
        let q = Arc::new(EdgeQueue::new(3, OverflowPolicy::Block, Arc::new(TaskSignal::default())));
        let mut tuples = batch(0..5);
        let closed = run(q.push_batch(&mut tuples, false, &mut Default::default(), &mut Vec::new()));
        assert!(!closed);
        assert_eq!(tuples.iter().map(value).collect::<Vec<_>>(), vec![3, 4], "what did not fit stays");
        assert_eq!(q.depth(), 3);
        let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_time().build().unwrap();
        rt.block_on(async {
            let q2 = q.clone();
            let producer = tokio::spawn(async move {
                let mut blocked = std::time::Duration::ZERO;
                q2.push_batch(&mut tuples, true, &mut blocked, &mut Vec::new()).await;
                (tuples.len(), blocked)
            });
            let mut out = VecDeque::new();
            q.take(&mut out, 2);
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
            assert!(!producer.is_finished(), "taken tuples still count against a block queue's bound");
            q.release(2);
            let (left, blocked) = producer.await.unwrap();
            assert_eq!(left, 0);
            assert!(blocked > std::time::Duration::ZERO, "the wait counts as backpressure");
            q.take(&mut out, 100);
            assert_eq!(out.iter().map(value).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4], "order is kept");
        });
    }

    #[test]
    fn a_batch_to_a_closed_queue_is_counted_undelivered() {
        let q = EdgeQueue::new(4, OverflowPolicy::Block, Arc::new(TaskSignal::default()));
        q.close();
        let mut tuples = batch(0..3);
        assert!(run(q.push_batch(&mut tuples, true, &mut Default::default(), &mut Vec::new())));
        assert!(tuples.is_empty());
        assert_eq!(q.counters.undelivered.load(Ordering::Relaxed), 3);
    }

    #[test]
    fn close_discards_and_refuses() {
        let q = EdgeQueue::new(4, OverflowPolicy::Block, Arc::new(TaskSignal::default()));
        run(async {
            q.push(tuple(0), &mut Default::default()).await;
            assert_eq!(q.close().len(), 1);
            assert!(matches!(q.push(tuple(1), &mut Default::default()).await, Push::Closed(_)));
        });
        assert_eq!(q.counters.undelivered.load(Ordering::Relaxed), 2);
        let (accepted, resolved) = q.totals();
        assert_eq!((accepted, resolved), (1, 1));
    }
}
