//! Commands from the coordinator to a task, and what tasks report back.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};

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

/// The coordinator's side of one task.
#[derive(Debug)]
pub(crate) struct Control {
    stage: AtomicU8,
    /// The task is inside `tick` (shutdown waits for it).
    pub(crate) ticking: AtomicBool,
    /// Wakes the task.
    pub(crate) signal: Arc<Notify>,
}

impl Control {
    pub(crate) fn new(signal: Arc<Notify>) -> Self {
        Control { stage: AtomicU8::new(Stage::Run as u8), ticking: AtomicBool::new(false), signal }
    }

    pub(crate) fn stage(&self) -> Stage {
        match self.stage.load(Ordering::SeqCst) {
            0 => Stage::Run,
            1 => Stage::Drain,
            2 => Stage::Finish,
            3 => Stage::Exit,
            _ => Stage::Abort,
        }
    }

    /// Moves the task forward to `stage` (never back) and wakes it.
    pub(crate) fn advance(&self, stage: Stage) {
        self.stage.fetch_max(stage as u8, Ordering::SeqCst);
        self.signal.notify_one();
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
}

/// A task's report.
#[derive(Debug)]
pub(crate) struct Event {
    pub(crate) component: usize,
    pub(crate) task: usize,
    pub(crate) kind: EventKind,
}
