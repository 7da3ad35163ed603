//! What a run is given: where outputs go, live progress counters, how long
//! an abort waits, and the flag that ends a run early.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use tokio::sync::Notify;

/// Live counters for a progress display.
#[derive(Debug, Default)]
pub struct Progress {
    /// Tuples emitted by spouts so far.
    pub emitted: AtomicU64,
    /// Tuples the spouts expect to emit in all (0 if unknown).
    pub expected: AtomicU64,
    /// Sensor readings (scans, depth frames) the spouts have emitted: what
    /// a user measures a run's progress in, odometry and other side
    /// streams left out (see [`TaskContext::readings`](crate::TaskContext::readings)).
    pub readings: AtomicU64,
    /// Readings the spouts expect in all (0 if unknown).
    pub expected_readings: AtomicU64,
    /// What one reading is ("scans", "frames"), once a spout has said.
    pub reading_unit: OnceLock<String>,
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
    pub stop: Arc<StopRequest>,
    /// How long the run may drain once `stop` is made; past it the tasks
    /// are aborted, what they held counted as undelivered, and the run
    /// ends with [`RunError::DrainTimedOut`](crate::RunError::DrainTimedOut).
    /// The default is [`STOP_DRAIN`].
    pub stop_drain: Duration,
    /// Publish the tasks' counters while the run goes, for a live page,
    /// a Prometheus scrape or a periodic metrics.json (none when absent).
    pub live: Option<Arc<crate::live::LiveRun>>,
}

/// A request to end a run early (Ctrl-C, SIGTERM). Spouts are no longer
/// polled once it is made; a spout waiting inside `next` (a paced log
/// replay sleeping until a record is due) can wait on
/// [`requested`](Self::requested) beside its timer, through
/// [`TaskContext::stop`](crate::TaskContext::stop), so that the stop does
/// not wait for the timer.
#[derive(Debug, Default)]
pub struct StopRequest {
    made: AtomicBool,
    woken: Notify,
}

impl StopRequest {
    /// Makes the request and wakes everything waiting on it.
    pub fn request(&self) {
        self.made.store(true, Ordering::SeqCst);
        self.woken.notify_waiters();
    }

    /// Whether the request has been made.
    pub fn is_made(&self) -> bool {
        self.made.load(Ordering::SeqCst)
    }

    /// Resolves once the request is made (at once if it was).
    pub async fn requested(&self) {
        let woken = self.woken.notified();
        tokio::pin!(woken);
        // Registered before the flag is read: a request made in between
        // still wakes it.
        woken.as_mut().enable();
        if self.is_made() {
            return;
        }
        woken.await;
    }
}

/// The process's own stop request: what a signal handler makes on the
/// first Ctrl-C or SIGTERM. A run given it (`RunOptions::stop`) stops as
/// the request is made, and setup work that takes seconds before a run
/// (building observable scenes, replaying a simulated route) polls
/// [`StopRequest::is_made`] on it and gives up, so that a signal is
/// honoured at every stage, not only once the run has started.
pub fn process_stop() -> Arc<StopRequest> {
    static STOP: OnceLock<Arc<StopRequest>> = OnceLock::new();
    STOP.get_or_init(Default::default).clone()
}

/// How long a stopped run may take to drain (finish what its sources had
/// sent) before what is left is abandoned: 10 s, several times the
/// slowest scan match at the default settings. The default of
/// [`RunOptions::stop_drain`].
pub const STOP_DRAIN: Duration = Duration::from_secs(10);

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            out_dir: None,
            progress: None,
            abort_grace: Duration::from_secs(5),
            stop: Arc::new(StopRequest::default()),
            stop_drain: STOP_DRAIN,
            live: None,
        }
    }
}
