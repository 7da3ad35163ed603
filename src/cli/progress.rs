//! A progress bar on stderr while a run goes, when stderr is a terminal.

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use squall_topology::Progress;

/// Redraws the bar from the runtime's live counters until finished.
pub(super) struct ProgressDisplay {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl ProgressDisplay {
    /// Starts drawing, if stderr is a terminal.
    pub(super) fn start(progress: Arc<Progress>) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        if !std::io::stderr().is_terminal() {
            return ProgressDisplay { stop, thread: None };
        }
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr_with_hz(10));
            let with_total = ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} tuples from spouts ({per_sec}, eta {eta})",
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
                bar.set_position(progress.emitted.load(Ordering::Relaxed));
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
