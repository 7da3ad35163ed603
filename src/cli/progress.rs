//! A progress bar on stderr while a run goes, when stderr is a terminal;
//! otherwise, with `SQUALL_LOG=squall::cli::progress=info` (or any filter
//! that lets its info lines through), one log line a second: a log file,
//! a supervisor or a test can follow a run. Without either, nothing.

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use squall_topology::Progress;

/// How often progress is logged when stderr is not a terminal.
const LOG_PERIOD: Duration = Duration::from_secs(1);

/// Redraws the bar from the runtime's live counters until finished.
pub(super) struct ProgressDisplay {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl ProgressDisplay {
    /// Starts drawing, if stderr is a terminal, or logging, if info lines
    /// of this module are logged.
    pub(super) fn start(progress: Arc<Progress>) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        if !std::io::stderr().is_terminal() {
            let thread = tracing::enabled!(tracing::Level::INFO).then(|| {
                let flag = stop.clone();
                std::thread::spawn(move || log_progress(&progress, &flag))
            });
            return ProgressDisplay { stop, thread };
        }
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr_with_hz(10));
            let with_total = ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:40} {human_pos}/{human_len} tuples from spouts ({msg}, eta {eta})",
            )
            .expect("valid template");
            let open_ended = ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {pos} tuples from spouts ({per_sec})",
            )
            .expect("valid template");
            bar.set_style(open_ended.clone());
            while !flag.load(Ordering::Relaxed) {
                let expected = progress.expected.load(Ordering::Relaxed);
                if expected > 0 && bar.length() != Some(expected) {
                    bar.set_length(expected);
                    bar.set_style(with_total.clone());
                }
                let emitted = progress.emitted.load(Ordering::Relaxed);
                bar.set_position(emitted);
                bar.set_message(rate(emitted, bar.elapsed()));
                std::thread::sleep(Duration::from_millis(100));
            }
            bar.finish_and_clear();
        });
        ProgressDisplay { stop, thread: Some(thread) }
    }

    /// Stops drawing and clears the bar.
    pub(super) fn finish(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Logs the counters every [`LOG_PERIOD`] until `stop`, as
/// `N tuples from spouts` (with ` of TOTAL` once the spouts said).
fn log_progress(progress: &Progress, stop: &AtomicBool) {
    let mut last = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        if last.elapsed() < LOG_PERIOD {
            continue;
        }
        last = Instant::now();
        let emitted = progress.emitted.load(Ordering::Relaxed);
        match progress.expected.load(Ordering::Relaxed) {
            0 => tracing::info!("{emitted} tuples from spouts"),
            expected => tracing::info!("{emitted} tuples from spouts of {expected}"),
        }
    }
}

/// "2.56 M/s"-style rate.
fn rate(count: u64, elapsed: Duration) -> String {
    let per_sec = count as f64 / elapsed.as_secs_f64().max(1e-9);
    if per_sec >= 1e6 {
        format!("{:.2} M/s", per_sec / 1e6)
    } else if per_sec >= 1e3 {
        format!("{:.1} k/s", per_sec / 1e3)
    } else {
        format!("{per_sec:.0}/s")
    }
}
