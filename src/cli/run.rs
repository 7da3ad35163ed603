//! `squall run`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use squall_topology::fsio::write_atomic;
use squall_topology::{Progress, RunError, RunOptions, RunReport, Topology};

use super::watch::{Watch, WatchArgs};
use super::{EXIT_FAILED, EXIT_INVALID, progress::ProgressDisplay, writable_out};

/// Scores a finished run from the files it wrote in the output folder:
/// (key, value) for metrics.json, or what went wrong.
pub(super) type Scorer<'a> = &'a dyn Fn(&Path) -> Result<(&'static str, serde_json::Value), String>;

/// Runs the topology (in this process, or on the workers of a cluster
/// file), prints the summary, writes metrics.json.
pub(super) fn run(
    topology: &Topology,
    out: Option<PathBuf>,
    quiet: bool,
    cluster: Option<&Path>,
    watch: &WatchArgs,
) -> ExitCode {
    run_scored(topology, out, quiet, cluster, watch, None)
}

/// [`run`], and when the run succeeded, `scorer`'s score of its outputs
/// in metrics.json too.
pub(super) fn run_scored(
    topology: &Topology,
    out: Option<PathBuf>,
    quiet: bool,
    cluster: Option<&Path>,
    watch: &WatchArgs,
    scorer: Option<Scorer>,
) -> ExitCode {
    // Everything a run in this process needs, checked before it starts and
    // reported together: the inputs the components read, and --out.
    let mut invalid = false;
    if cluster.is_none() {
        for error in topology.unreadable_inputs() {
            eprintln!("{error}");
            invalid = true;
        }
    }
    if let Some(dir) = &out {
        invalid |= writable_out(dir).is_err();
    }
    if invalid {
        return ExitCode::from(EXIT_INVALID);
    }
    if super::signals::stopping() {
        return stopped_before_start(out.as_deref());
    }
    let mut watching = match Watch::start(watch, out.as_deref()) {
        Ok(w) => w,
        Err(message) => {
            eprintln!("error: {message}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    let progress = Arc::new(Progress::default());
    // Counters only when something shows them: what spouts do for the
    // display (a log's scans counted ahead) is then left undone.
    let watched = ProgressDisplay::wanted().then(|| progress.clone());
    let options = RunOptions {
        out_dir: out.clone(),
        progress: watched,
        live: watching.live(),
        stop: squall_topology::runtime::process_stop(),
        ..RunOptions::default()
    };
    let result = match cluster {
        None => {
            let display = ProgressDisplay::start(progress);
            let result = squall_topology::run(topology, &options);
            display.finish();
            result
        }
        Some(file) => match on_cluster(topology, file, &options, progress) {
            Ok(result) => result,
            Err((code, message)) => {
                eprintln!("error: {message}");
                return ExitCode::from(code);
            }
        },
    };
    // A stop whose drain passed its bound is still a stop: the run
    // ends "stopped", its warning saying what was abandoned.
    let mut drain_note = None;
    let result = match result {
        Err(e @ RunError::DrainTimedOut { .. }) => {
            drain_note = Some(e.to_string());
            match e {
                RunError::DrainTimedOut { report, .. } => Ok(*report),
                other => Err(other),
            }
        }
        other => other,
    };
    if options.stop.is_made() && drain_note.is_none() {
        eprintln!("note: stopped early (Ctrl-C or SIGTERM); everything already emitted was processed");
    }
    let (mut report, failure) = match result.map_err(RunError::into_parts) {
        Ok(report) => (report, None),
        Err((message, Some(report))) => (report, Some(message)),
        Err((message, None)) => {
            eprintln!("error: {message}");
            watching.finish(&options.stop);
            return ExitCode::from(EXIT_FAILED);
        }
    };
    report.warnings.extend(watching.warnings().iter().cloned());
    if let Some(note) = &drain_note {
        eprintln!("warning: {note}");
        report.warnings.push(note.clone());
    }
    if let Some(live) = watching.live() {
        live.finish(&report);
    }
    let mut code = ExitCode::SUCCESS;
    if let Err(message) = watching.run_ended() {
        eprintln!("error: {message}");
        code = ExitCode::from(EXIT_FAILED);
    }
    if !quiet {
        out!("{report}");
    }
    // A run aborted at the end of its drain wrote no outputs to score.
    let scorer = scorer.filter(|_| drain_note.is_none());
    let score = match (&out, scorer, &failure) {
        (Some(dir), Some(scorer), None) => match scorer(dir) {
            Ok(score) => Some(score),
            Err(message) => {
                eprintln!("error: cannot score the run: {message}");
                code = ExitCode::from(EXIT_FAILED);
                None
            }
        },
        _ => None,
    };
    let status = match (&failure, options.stop.is_made()) {
        (Some(message), _) => Status::Failed(message.clone()),
        (None, true) => Status::Stopped,
        (None, false) => Status::Completed,
    };
    if let Some(dir) = &out
        && let Err(e) = write_metrics(dir, &report, score, &status)
    {
        eprintln!("error: cannot write {}: {e}", dir.join("metrics.json").display());
        code = ExitCode::from(EXIT_FAILED);
    }
    if let Some(failure) = failure {
        eprintln!("error: the run failed: {failure}");
        code = ExitCode::from(EXIT_FAILED);
    }
    watching.finish(&options.stop);
    code
}

/// Runs on the cluster of `file`; a cluster that cannot run is an exit
/// code with its message.
#[cfg(feature = "cluster")]
fn on_cluster(
    topology: &Topology,
    file: &Path,
    options: &RunOptions,
    progress: Arc<Progress>,
) -> Result<Result<RunReport, RunError>, (u8, String)> {
    use squall_topology::cluster::config::ClusterSpec;
    use squall_topology::cluster::run::{ClusterRunError, run_on_cluster};
    let cluster = ClusterSpec::load(file).map_err(|e| (EXIT_INVALID, e.to_string()))?;
    let display = ProgressDisplay::start(progress);
    let result = run_on_cluster(topology, &cluster, options);
    display.finish();
    match result {
        Ok(report) => Ok(Ok(report)),
        Err(ClusterRunError::Run(e)) => Ok(Err(e)),
        Err(ClusterRunError::Setup(message)) => Err((EXIT_FAILED, message)),
    }
}

#[cfg(not(feature = "cluster"))]
fn on_cluster(
    _: &Topology,
    _: &Path,
    _: &RunOptions,
    _: Arc<Progress>,
) -> Result<Result<RunReport, RunError>, (u8, String)> {
    Err((
        EXIT_INVALID,
        "--cluster needs cluster mode: this squall was built without the `cluster` feature".into(),
    ))
}

/// How a run stands, as metrics.json's `status` says: `running` (written
/// while it goes, with `--metrics-every`), `completed` (the sources ended
/// and everything was processed), `stopped` (Ctrl-C or SIGTERM: the
/// sources were stopped early, everything they had sent was processed) or
/// `failed` (with `error`: the counters are as they stood when the run was
/// abandoned).
pub(super) enum Status {
    Running,
    Completed,
    Stopped,
    Failed(String),
}

/// Writes metrics.json: the run's report, its status, and `score` under
/// its key.
pub(super) fn write_metrics(
    dir: &std::path::Path,
    report: &RunReport,
    score: Option<(&'static str, serde_json::Value)>,
    status: &Status,
) -> std::io::Result<()> {
    let mut all = serde_json::to_value(report).map_err(std::io::Error::other)?;
    if let Some(fields) = all.as_object_mut() {
        let (name, error) = match status {
            Status::Running => ("running", None),
            Status::Completed => ("completed", None),
            Status::Stopped => ("stopped", None),
            Status::Failed(message) => ("failed", Some(message)),
        };
        fields.insert("status".into(), name.into());
        if let Some(error) = error {
            fields.insert("error".into(), error.as_str().into());
        }
        if let Some((key, value)) = score {
            fields.insert(key.to_string(), value);
        }
    }
    let json = serde_json::to_string_pretty(&all).map_err(std::io::Error::other)?;
    write_atomic(&dir.join("metrics.json"), json.as_bytes())
}

/// A run stopped by a signal before it started (while its inputs were
/// read or its structures built): metrics.json says "stopped" at
/// "setup", with nothing run.
pub(super) fn stopped_before_start(out: Option<&Path>) -> ExitCode {
    eprintln!("note: stopped (Ctrl-C or SIGTERM) before the run started; nothing ran");
    if let Some(dir) = out {
        let json = serde_json::json!({ "status": "stopped", "stage": "setup" });
        let written = squall_topology::fsio::check_writable_dir(dir)
            .and_then(|()| write_atomic(&dir.join("metrics.json"), json.to_string().as_bytes()));
        if let Err(e) = written {
            eprintln!("error: cannot write {}: {e}", dir.join("metrics.json").display());
            return ExitCode::from(EXIT_FAILED);
        }
    }
    ExitCode::SUCCESS
}
