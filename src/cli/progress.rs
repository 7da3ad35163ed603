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
    /// Whether [`start`](Self::start) will show anything: stderr is a
    /// terminal, or info lines of this module are logged.
    pub(super) fn wanted() -> bool {
        std::io::stderr().is_terminal() || tracing::enabled!(tracing::Level::INFO)
    }

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
                "{spinner} [{elapsed_precise}] {bar:40} {human_pos}/{human_len} {msg} {percent}%, eta {eta}",
            )
            .expect("valid template");
            let open_ended = ProgressStyle::with_template("{spinner} [{elapsed_precise}] {human_pos} {msg}")
                .expect("valid template");
            bar.set_style(open_ended.clone());
            while !flag.load(Ordering::Relaxed) {
                let count = Count::of(&progress);
                if count.total > 0 && bar.length() != Some(count.total) {
                    bar.set_length(count.total);
                    bar.set_style(with_total.clone());
                }
                bar.set_position(count.done);
                let separator = if count.total > 0 { "," } else { "" };
                bar.set_message(format!("{} ({}){separator}", count.unit, rate(count.done, bar.elapsed())));
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

/// What the display counts: the spouts' readings once one has said it
/// emits them (scans, frames), else every tuple from spouts.
struct Count {
    done: u64,
    total: u64,
    unit: String,
}

impl Count {
    fn of(progress: &Progress) -> Count {
        match progress.reading_unit.get() {
            Some(unit) => Count {
                done: progress.readings.load(Ordering::Relaxed),
                total: progress.expected_readings.load(Ordering::Relaxed),
                unit: unit.clone(),
            },
            None => Count {
                done: progress.emitted.load(Ordering::Relaxed),
                total: progress.expected.load(Ordering::Relaxed),
                unit: "tuples from spouts".to_string(),
            },
        }
    }
}

/// Logs the counts every [`LOG_PERIOD`] until `stop` (see [`log_line`]).
fn log_progress(progress: &Progress, stop: &AtomicBool) {
    let mut last = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
        if last.elapsed() < LOG_PERIOD {
            continue;
        }
        last = Instant::now();
        tracing::info!("{}", log_line(progress));
    }
}

/// `120 scans of 1200 (10%); 361 tuples from spouts`: the readings, when a
/// spout counts them, then every tuple from spouts (with ` of TOTAL` once
/// the spouts said), which a supervisor can follow in any run.
fn log_line(progress: &Progress) -> String {
    let emitted = progress.emitted.load(Ordering::Relaxed);
    let tuples = match progress.expected.load(Ordering::Relaxed) {
        0 => format!("{emitted} tuples from spouts"),
        expected => format!("{emitted} tuples from spouts of {expected}"),
    };
    let Some(unit) = progress.reading_unit.get() else { return tuples };
    let done = progress.readings.load(Ordering::Relaxed);
    match progress.expected_readings.load(Ordering::Relaxed) {
        0 => format!("{done} {unit}; {tuples}"),
        total => format!("{done} {unit} of {total} ({:.0}%); {tuples}", 100.0 * done as f64 / total as f64),
    }
}

/// "2.56 M/s"-style rate.
fn rate(count: u64, elapsed: Duration) -> String {
    let per_sec = count as f64 / elapsed.as_secs_f64().max(1e-9);
    if per_sec >= 1e6 {
        format!("{:.2} M/s", per_sec / 1e6)
    } else if per_sec >= 1e3 {
        format!("{:.1} k/s", per_sec / 1e3)
    } else if per_sec >= 10.0 {
        format!("{per_sec:.0}/s")
    } else {
        format!("{per_sec:.1}/s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_keep_three_significant_figures_at_most() {
        let second = Duration::from_secs(1);
        assert_eq!(rate(2_560_000, second), "2.56 M/s");
        assert_eq!(rate(41_234, second), "41.2 k/s");
        assert_eq!(rate(412, second), "412/s");
        assert_eq!(rate(41, second), "41/s");
        assert_eq!(rate(25, Duration::from_secs(10)), "2.5/s");
    }

    #[test]
    fn readings_are_counted_once_a_spout_names_them() {
        let progress = Progress::default();
        progress.emitted.store(30, Ordering::Relaxed);
        progress.expected.store(300, Ordering::Relaxed);
        let tuples = Count::of(&progress);
        assert_eq!((tuples.done, tuples.total, tuples.unit.as_str()), (30, 300, "tuples from spouts"));
        assert_eq!(log_line(&progress), "30 tuples from spouts of 300");
        progress.reading_unit.set("scans".to_string()).unwrap();
        progress.readings.store(10, Ordering::Relaxed);
        progress.expected_readings.store(100, Ordering::Relaxed);
        let scans = Count::of(&progress);
        assert_eq!((scans.done, scans.total, scans.unit.as_str()), (10, 100, "scans"));
        assert_eq!(log_line(&progress), "10 scans of 100 (10%); 30 tuples from spouts of 300");
    }
}
