//! Commands from the coordinator to a task, and what tasks report back.

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use tokio::sync::Notify;

/// The stage a task is told to be in; stages only move forward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub(crate) enum Stage {
    /// Normal operation.
    Run = 0,
    /// All spouts are done: no more ticks.
    Drain = 1,
    /// Call `finish`/`close`, then keep processing input.
    Finish = 2,
    /// Stop.
    Exit = 3,
    /// The run failed: stop now.
    Abort = 4,
}

impl Stage {
    /// The stage of this number (as stored, and as sent to workers).
    pub(crate) fn from_u8(n: u8) -> Option<Stage> {
        Some(match n {
            0 => Stage::Run,
            1 => Stage::Drain,
            2 => Stage::Finish,
            3 => Stage::Exit,
            4 => Stage::Abort,
            _ => return None,
        })
    }
}

/// Wakes one task's thread.
///
/// Producers wake a consumer only when it has announced that it is parking,
/// so the steady state costs a plain load per tuple instead of a shared
/// atomic write. The flag is read under the queue lock and set before the
/// consumer re-checks its queues under the same locks, so a wake-up cannot
/// be missed.
#[derive(Debug, Default)]
pub(crate) struct TaskSignal {
    notify: Notify,
    parked: AtomicBool,
}

impl TaskSignal {
    /// Wakes the task unconditionally (commands, acks); a wake-up sent while
    /// it runs is kept for its next wait.
    pub(crate) fn wake(&self) {
        self.notify.notify_one();
    }

    /// Whether the task has announced that it is parking. Read it under the
    /// lock of the queue just pushed to.
    pub(crate) fn is_parking(&self) -> bool {
        self.parked.load(Ordering::Relaxed)
    }

    /// Announces that the task is about to park; it must re-check its queues
    /// after this and before [`wait`](Self::wait).
    pub(crate) fn announce_park(&self) {
        self.parked.store(true, Ordering::SeqCst);
    }

    /// Withdraws the announcement (the task found work or woke up).
    pub(crate) fn unpark(&self) {
        self.parked.store(false, Ordering::Relaxed);
    }

    /// Resolves on the next wake-up (or at once if one is pending).
    pub(crate) fn wait(&self) -> tokio::sync::futures::Notified<'_> {
        self.notify.notified()
    }
}

/// The coordinator's side of one task.
#[derive(Debug)]
pub(crate) struct Control {
    stage: AtomicU8,
    /// The task is inside `tick` (shutdown waits for it).
    pub(crate) ticking: AtomicBool,
    /// Wakes the task.
    pub(crate) signal: Arc<TaskSignal>,
    /// When the bolt's current `execute` or `tick` began, or last stopped
    /// waiting for queue space, in ns after [`epoch`] plus one; 0 outside
    /// a call. What the stall watchdog reads.
    busy_since: AtomicU64,
}

/// The instant `busy_since` counts from (the first use in the process).
fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

impl Control {
    pub(crate) fn new(signal: Arc<TaskSignal>) -> Self {
        Control {
            stage: AtomicU8::new(Stage::Run as u8),
            ticking: AtomicBool::new(false),
            signal,
            busy_since: AtomicU64::new(0),
        }
    }

    /// The bolt entered a call (or stopped waiting inside one) at `at`.
    pub(crate) fn call_progressed(&self, at: Instant) {
        let since = at.saturating_duration_since(epoch()).as_nanos() as u64 + 1;
        self.busy_since.store(since, Ordering::Relaxed);
    }

    /// An emit stopped waiting for queue space at `at`: if the bolt is in
    /// a call, the call progressed. Outside one (an emit from `finish`,
    /// which is not watched) nothing changes: the watchdog must not start
    /// counting a call that will never be said to end.
    pub(crate) fn wait_ended(&self, at: Instant) {
        if self.busy_since.load(Ordering::Relaxed) != 0 {
            self.call_progressed(at);
        }
    }

    /// The bolt left its call.
    pub(crate) fn call_ended(&self) {
        self.busy_since.store(0, Ordering::Relaxed);
    }

    /// How long the bolt has been in its current call without progress
    /// (time waiting for queue space excluded), if it is in one.
    pub(crate) fn stuck_for(&self, now: Instant) -> Option<Duration> {
        let since = self.busy_since.load(Ordering::Relaxed).checked_sub(1)?;
        Some(now.saturating_duration_since(epoch() + Duration::from_nanos(since)))
    }

    pub(crate) fn stage(&self) -> Stage {
        Stage::from_u8(self.stage.load(Ordering::SeqCst)).unwrap_or(Stage::Abort)
    }

    /// Moves the task forward to `stage` (never back) and wakes it.
    pub(crate) fn advance(&self, stage: Stage) {
        self.stage.fetch_max(stage as u8, Ordering::SeqCst);
        self.signal.wake();
    }
}

/// What a task reports to the coordinator.
#[derive(Debug)]
pub(crate) enum EventKind {
    /// A spout task is exhausted and all its tuple trees are settled.
    SpoutDone,
    /// `finish`/`close` returned.
    Finished,
    /// The task failed for good.
    Failed(String),
    /// The thread is about to end.
    Exited,
    /// A process of a cluster run was lost, with the tasks it hosted
    /// (reported against one of them).
    #[cfg_attr(not(feature = "cluster"), allow(dead_code))]
    HostLost(u16),
}

/// Why a run was abandoned.
#[derive(Debug)]
pub(crate) enum Failure {
    /// A task failed (or stalled, or its host was lost).
    Task(TaskFailure),
    /// The process's resident memory (bytes) passed the limit (bytes).
    Memory { rss: u64, limit: u64 },
    /// The run was stopped and had not drained after this long.
    DrainTimedOut(std::time::Duration),
}

/// The task that failed a run, and why; the run's error names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct TaskFailure {
    pub(crate) component: usize,
    pub(crate) task: usize,
    pub(crate) message: String,
}

/// A task's report.
#[derive(Debug)]
pub(crate) struct Event {
    pub(crate) component: usize,
    pub(crate) task: usize,
    pub(crate) kind: EventKind,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_call_is_watched_and_a_wait_restarts_its_clock() {
        let control = Control::new(Arc::new(TaskSignal::default()));
        // Every instant from one reading of the clock: nothing here depends
        // on how long the lines between take.
        let start = Instant::now();
        let later = start + Duration::from_secs(5);
        // An emit from `finish` that waited: still outside any call.
        control.wait_ended(start);
        assert_eq!(control.stuck_for(later), None);
        control.call_progressed(start);
        let stuck = control.stuck_for(later).unwrap();
        assert!(stuck >= Duration::from_secs(5) - Duration::from_millis(1), "{stuck:?}");
        assert!(stuck <= Duration::from_secs(5) + Duration::from_millis(1), "{stuck:?}");
        // A wait for queue space that ends 4 s into the call restarts the clock.
        control.wait_ended(start + Duration::from_secs(4));
        let stuck = control.stuck_for(later).unwrap();
        assert!(stuck <= Duration::from_secs(1) + Duration::from_millis(1), "{stuck:?}");
        control.call_ended();
        assert_eq!(control.stuck_for(later), None);
    }
}
