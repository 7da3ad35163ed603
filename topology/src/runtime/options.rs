//! What a run is given: where outputs go, live progress counters, how long
//! an abort waits, and the flag that ends a run early.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64};
use std::time::Duration;

/// Live counters for a progress display.
#[derive(Debug, Default)]
pub struct Progress {
    /// Tuples emitted by spouts so far.
    pub emitted: AtomicU64,
    /// Tuples the spouts expect to emit in all (0 if unknown).
    pub expected: AtomicU64,
}

/// Options of a local run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Where components may write their outputs (`TaskContext::out_dir`).
    pub out_dir: Option<PathBuf>,
    /// Live counters, read by a progress bar.
    pub progress: Option<Arc<Progress>>,
    /// How long an abort waits for tasks to stop. The default is 5 s.
    pub abort_grace: Duration,
    /// Set it to end the run early and cleanly: spouts are no longer polled,
    /// then everything in flight is processed and every component finishes,
    /// as if the sources had ended (Ctrl-C in `squall run`).
    pub stop: Arc<AtomicBool>,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            out_dir: None,
            progress: None,
            abort_grace: Duration::from_secs(5),
            stop: Arc::new(AtomicBool::new(false)),
        }
    }
}
