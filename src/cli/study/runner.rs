//! One run as its own process: `squall slam` started from this binary,
//! its stdout and stderr to files in its folder, waited on with `wait4`
//! to read the child's own resource usage (CPU time and peak memory),
//! which `Child::wait` does not give. The child's peak memory is the one
//! its `metrics.json` reports when there is one: Linux's `ru_maxrss` of a
//! child also counts the parent's memory as it was when the child
//! started, which a study that generated worlds in its own process would
//! add to every run.

use std::ffi::OsString;
use std::fs::File;
use std::io;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::Instant;

/// One (log, seed) to run.
#[derive(Debug)]
pub(super) struct Job {
    /// Index of the log in the study's list.
    pub(super) log: usize,
    pub(super) seed: u64,
    /// The run's folder: `--out` of its `squall slam`, and its logs.
    pub(super) dir: PathBuf,
    /// The arguments after the executable.
    pub(super) args: Vec<OsString>,
}

/// What a finished child cost, and why it failed if it did.
#[derive(Debug, Clone)]
pub(super) struct Measured {
    pub(super) wall_secs: f64,
    /// User plus system time of the child.
    pub(super) cpu_secs: f64,
    /// Peak resident set size of the child, MiB: as its `metrics.json`
    /// reports it, else its `ru_maxrss`.
    pub(super) peak_rss_mb: f64,
    /// Why the run failed (its last stderr line), `None` when it exited 0.
    pub(super) failure: Option<String>,
    /// Whether it was stopped early (the study was signalled, or its
    /// metrics.json says "stopped"): its outputs cover part of the log.
    pub(super) stopped: bool,
}

/// The error of a job the study never started, having been stopped.
pub(super) const NOT_STARTED: &str = "not started: the study was stopped (Ctrl-C or SIGTERM)";

/// Runs `job` to its end. `Err` when it could not even start.
pub(super) fn run(job: &Job) -> Result<Measured, String> {
    if crate::cli::signals::stopping() {
        return Err(NOT_STARTED.into());
    }
    let cannot = |what: &str, e: io::Error| format!("cannot {what}: {e}");
    std::fs::create_dir_all(&job.dir).map_err(|e| cannot(&format!("create {}", job.dir.display()), e))?;
    let stderr_path = job.dir.join("stderr.log");
    let stdout = File::create(job.dir.join("stdout.log")).map_err(|e| cannot("create stdout.log", e))?;
    let stderr = File::create(&stderr_path).map_err(|e| cannot("create stderr.log", e))?;
    let exe = std::env::current_exe().map_err(|e| cannot("find this executable", e))?;
    let started = Instant::now();
    let mut command = Command::new(exe);
    command.args(&job.args).arg("--out").arg(&job.dir).stdin(Stdio::null()).stdout(stdout).stderr(stderr);
    // SAFETY: between fork and exec the child calls only `setpgid` and
    // `prctl`, which are async-signal-safe, and touches no memory.
    unsafe {
        command.pre_exec(|| {
            // A process group of its own: Ctrl-C at the terminal reaches
            // the study alone, which passes one SIGTERM on (a child that
            // got both would take the second for "abort").
            libc::setpgid(0, 0);
            // Should the study die without passing a signal on (SIGKILL),
            // the child is stopped rather than left running.
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
    let child = command.spawn().map_err(|e| cannot("start squall slam", e))?;
    let pid = libc::pid_t::try_from(child.id()).map_err(|_| "pid out of range".to_string())?;
    crate::cli::signals::adopt(pid);
    let waited = wait_with_usage(&child);
    crate::cli::signals::release(pid);
    let (status, usage) = waited.map_err(|e| cannot("wait for squall slam", e))?;
    let wall_secs = started.elapsed().as_secs_f64();
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    let failure = (!status.success()).then(|| {
        let text = std::fs::read_to_string(&stderr_path).unwrap_or_default();
        let last = text.lines().rev().map(str::trim).find(|l| !l.is_empty());
        match (last, status.code(), status.signal()) {
            (Some(line), _, _) => line.strip_prefix("error: ").unwrap_or(line).to_string(),
            (None, Some(code), _) => format!("exited with {code}"),
            (None, None, Some(signal)) => format!("killed by signal {signal}"),
            (None, None, None) => format!("ended with {status}"),
        }
    });
    Ok(Measured {
        wall_secs,
        cpu_secs: secs(usage.ru_utime) + secs(usage.ru_stime),
        // Linux reports ru_maxrss in KiB.
        peak_rss_mb: reported_peak_rss_mb(&job.dir).unwrap_or(usage.ru_maxrss as f64 / 1024.0),
        failure,
        stopped: crate::cli::signals::stopping() || reported_status(&job.dir).as_deref() == Some("stopped"),
    })
}

/// The status the run's `metrics.json` in `dir` reports.
fn reported_status(dir: &std::path::Path) -> Option<String> {
    let text = std::fs::read_to_string(dir.join("metrics.json")).ok()?;
    Some(serde_json::from_str::<serde_json::Value>(&text).ok()?.get("status")?.as_str()?.to_string())
}

/// The peak memory the run's `metrics.json` in `dir` reports, MiB.
fn reported_peak_rss_mb(dir: &std::path::Path) -> Option<f64> {
    let text = std::fs::read_to_string(dir.join("metrics.json")).ok()?;
    serde_json::from_str::<serde_json::Value>(&text).ok()?.get("peak_rss_mb")?.as_f64()
}

/// Reaps `child` with `wait4`, returning its exit status and its own
/// resource usage. `child` must not have been waited on.
fn wait_with_usage(child: &Child) -> io::Result<(ExitStatus, libc::rusage)> {
    let pid = libc::pid_t::try_from(child.id()).map_err(|_| io::Error::other("pid out of range"))?;
    let mut status: libc::c_int = 0;
    // SAFETY: `rusage` is a plain C struct of integers, for which all zero
    // bytes is a valid value.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: both pointers are to live locals of the right types, and
        // `pid` is our own child, not yet reaped (nothing calls
        // `Child::wait`), so the id cannot name another process.
        let reaped = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if reaped == pid {
            return Ok((ExitStatus::from_raw(status), usage));
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}
