//! `squall run`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use squall_topology::fsio::write_atomic;
use squall_topology::{Progress, RunError, RunOptions, RunReport, Topology};

use super::{EXIT_FAILED, progress::ProgressDisplay};

/// Runs the topology, prints the summary, writes metrics.json.
pub(super) fn run(topology: &Topology, out: Option<PathBuf>, quiet: bool) -> ExitCode {
    let progress = Arc::new(Progress::default());
    let display = ProgressDisplay::start(progress.clone());
    let options = RunOptions { out_dir: out.clone(), progress: Some(progress), ..RunOptions::default() };
    stop_on_ctrl_c(options.stop.clone());
    let result = squall_topology::run(topology, &options);
    display.finish();
    if options.stop.load(Ordering::Relaxed) {
        eprintln!("note: stopped early by Ctrl-C; everything already emitted was processed");
    }
    let (report, failure) = match result {
        Ok(report) => (report, None),
        Err(RunError::TaskFailed { report, role, component, task, message }) => {
            (*report, Some(format!("{role} \"{component}\" task {task} {message}")))
        }
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_FAILED);
        }
    };
    if !quiet {
        print!("{report}");
    }
    let mut code = ExitCode::SUCCESS;
    if let Some(dir) = &out {
        if let Err(e) = write_metrics(dir, &report) {
            eprintln!("error: cannot write {}: {e}", dir.join("metrics.json").display());
            code = ExitCode::from(EXIT_FAILED);
        }
    }
    if let Some(failure) = failure {
        eprintln!("error: the run failed: {failure}");
        code = ExitCode::from(EXIT_FAILED);
    }
    code
}

fn write_metrics(dir: &std::path::Path, report: &RunReport) -> std::io::Result<()> {
    write_atomic(&dir.join("metrics.json"), report.to_json().as_bytes())
}

/// First Ctrl-C: stop the spouts and let the run drain and finish. Second:
/// exit at once.
fn stop_on_ctrl_c(stop: Arc<AtomicBool>) {
    let spawned = std::thread::Builder::new().name("ctrl-c".into()).spawn(move || {
        let Ok(rt) = tokio::runtime::Builder::new_current_thread().enable_all().build() else { return };
        rt.block_on(async {
            if tokio::signal::ctrl_c().await.is_err() {
                return;
            }
            eprintln!("\nstopping: draining tuples in flight (Ctrl-C again to abort)");
            stop.store(true, Ordering::Relaxed);
            if tokio::signal::ctrl_c().await.is_ok() {
                eprintln!("aborted");
                std::process::exit(130);
            }
        });
    });
    if let Err(e) = spawned {
        tracing::warn!("cannot watch for Ctrl-C: {e}");
    }
}
