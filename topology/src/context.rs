//! What a task knows about itself and its run.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;

use crate::runtime::{Progress, StopRequest};

/// The identity and environment of one task, given to `open`/`prepare`.
#[derive(Debug, Clone)]
pub struct TaskContext {
    pub(crate) topology: Arc<str>,
    pub(crate) component: Arc<str>,
    pub(crate) task_index: usize,
    pub(crate) task_count: usize,
    pub(crate) seed: u64,
    pub(crate) out_dir: Option<Arc<PathBuf>>,
    pub(crate) progress: Option<Arc<Progress>>,
    pub(crate) replacement: bool,
    pub(crate) stop: Arc<StopRequest>,
}

impl TaskContext {
    /// The topology's name.
    pub fn topology(&self) -> &str {
        &self.topology
    }

    /// This component's name.
    pub fn component(&self) -> &str {
        &self.component
    }

    /// This task's index in `0..task_count()`.
    pub fn task_index(&self) -> usize {
        self.task_index
    }

    /// The component's parallelism.
    pub fn task_count(&self) -> usize {
        self.task_count
    }

    /// The run's seed (`[topology] seed`). Derive random streams from it and
    /// from what they are for, never from the task index, so that results
    /// do not depend on parallelism.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Whether this task replaces one that was lost with its process
    /// (cluster mode): it starts without the state its predecessor had.
    pub fn is_replacement(&self) -> bool {
        self.replacement
    }

    /// The run's output directory, when one was given.
    pub fn out_dir(&self) -> Option<&Path> {
        self.out_dir.as_deref().map(|p| p.as_path())
    }

    /// The run's stop request: a spout that waits inside `next` (pacing a
    /// replay) keeps it from `open` and waits on it beside its timer, then
    /// returns without emitting; the runtime stops polling it.
    pub fn stop(&self) -> Arc<StopRequest> {
        self.stop.clone()
    }

    /// Tells the progress display how many tuples this task will emit in
    /// all (spouts that know, e.g. a log reader after counting its records).
    pub fn expect_emits(&self, total: u64) {
        if let Some(p) = &self.progress {
            p.expected.fetch_add(total, Ordering::Relaxed);
        }
    }

    /// Tells the progress display that this spout's task emits sensor
    /// readings, each one a `unit` ("scans", "frames"), `total()` of them
    /// in all when known; count each with the counter returned. The display
    /// then shows readings, a percentage and an ETA rather than tuples
    /// (which count odometry and side streams too). The first unit given
    /// in a run names them all. `total` is called only when a display
    /// watches the run, so a spout may count its input for it.
    pub fn readings(&self, unit: &str, total: impl FnOnce() -> Option<u64>) -> ReadingCounter {
        if let Some(p) = &self.progress {
            let _ = p.reading_unit.set(unit.to_string());
            p.expected_readings.fetch_add(total().unwrap_or(0), Ordering::Relaxed);
        }
        ReadingCounter { progress: self.progress.clone() }
    }
}

/// Counts a spout's readings for the progress display (from
/// [`TaskContext::readings`]); does nothing when no display watches.
#[derive(Debug, Clone, Default)]
pub struct ReadingCounter {
    progress: Option<Arc<Progress>>,
}

impl ReadingCounter {
    /// Counts `n` more readings emitted.
    pub fn add(&self, n: u64) {
        if let Some(p) = &self.progress {
            p.readings.fetch_add(n, Ordering::Relaxed);
        }
    }
}
