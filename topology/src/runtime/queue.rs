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
