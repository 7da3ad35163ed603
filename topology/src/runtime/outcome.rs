//! How a run ends: the report built from every task's outcome, and the
//! error that names the task that failed.

use std::time::Duration;

use crate::metrics::{RunReport, TaskOutcome, component_report};
use crate::plan::Topology;
use crate::runtime::control::{Failure, TaskFailure};
use crate::spec::Role;

/// A run that failed: which task and why, with the metrics up to then.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A task panicked or returned an error (after any restarts).
    #[error("{role} \"{component}\" task {task} {message}")]
    TaskFailed {
        /// Spout or bolt.
        role: Role,
        /// The component.
        component: String,
        /// The task index.
        task: usize,
        /// What happened.
        message: String,
        /// Metrics up to the failure.
        report: Box<RunReport>,
    },
    /// The process's resident memory passed the topology's limit
    /// (`[topology] memory_limit_mb`, by default 90% of the machine's).
    #[error(
        "the process's resident memory reached {rss_mb} MiB, past the limit of {limit_mb} MiB \
         ([topology] memory_limit_mb): a component keeps what it should let go, or the limit is too low"
    )]
    MemoryLimit {
        /// Resident memory when the watchdog looked, MiB.
        rss_mb: u64,
        /// The limit, MiB.
        limit_mb: u64,
        /// Metrics up to the failure.
        report: Box<RunReport>,
    },
    /// The run was stopped (Ctrl-C, SIGTERM, [`RunOptions::stop`](crate::RunOptions::stop))
    /// and had not drained within [`RunOptions::stop_drain`](crate::RunOptions::stop_drain):
    /// the tasks were aborted, what they still held is counted as
    /// undelivered.
    #[error(
        "stopped, and not drained within {secs} s: what was still in flight was abandoned \
         (counted as undelivered)"
    )]
    DrainTimedOut {
        /// The bound, seconds.
        secs: f64,
        /// Metrics up to the abort.
        report: Box<RunReport>,
    },
    /// The runtime itself could not start.
    #[error("cannot start the runtime: {0}")]
    Start(#[from] std::io::Error),
}

impl RunError {
    /// What went wrong, and the metrics up to then if the run started.
    pub fn into_parts(self) -> (String, Option<RunReport>) {
        let message = self.to_string();
        match self {
            RunError::TaskFailed { report, .. }
            | RunError::MemoryLimit { report, .. }
            | RunError::DrainTimedOut { report, .. } => (message, Some(*report)),
            RunError::Start(_) => (message, None),
        }
    }
}

/// The report as the run's result: an error naming the failed task, if any.
pub(crate) fn finish_run(
    topology: &Topology,
    report: RunReport,
    failure: Option<Failure>,
) -> Result<RunReport, RunError> {
    match failure {
        None => Ok(report),
        Some(Failure::Memory { rss, limit }) => {
            Err(RunError::MemoryLimit { rss_mb: rss >> 20, limit_mb: limit >> 20, report: Box::new(report) })
        }
        Some(Failure::DrainTimedOut(bound)) => {
            Err(RunError::DrainTimedOut { secs: bound.as_secs_f64(), report: Box::new(report) })
        }
        Some(Failure::Task(TaskFailure { component, task, message })) => {
            let spec = &topology.components[component].spec;
            Err(RunError::TaskFailed {
                role: spec.role,
                component: spec.name.clone(),
                task,
                message,
                report: Box::new(report),
            })
        }
    }
}

pub(crate) fn build_report(topology: &Topology, outcomes: &[Vec<TaskOutcome>], wall: Duration) -> RunReport {
    build_report_with_unsent(topology, outcomes, wall, &[])
}

/// The run's report, where `unsent` lists, per consumer component, tuples
/// held for its tasks in another process and never sent (their producer
/// ended first): they count in the consumer's `undelivered`.
pub(crate) fn build_report_with_unsent(
    topology: &Topology,
    outcomes: &[Vec<TaskOutcome>],
    wall: Duration,
    unsent: &[(usize, u64)],
) -> RunReport {
    let mut components: Vec<_> = topology
        .components
        .iter()
        .zip(outcomes)
        .map(|(p, o)| component_report(&p.spec.name, &p.spec.kind, p.spec.role, o))
        .collect();
    for &(consumer, n) in unsent {
        components[consumer].undelivered += n;
    }
    let mut warnings = topology.declared_warnings();
    for c in &components {
        if c.undelivered > 0 {
            warnings.push(format!(
                "{} \"{}\": {} tuples sent to it were not executed (they arrived after it had exited or \
                 at an abort, or their producer ended holding them)",
                c.role, c.name, c.undelivered
            ));
        }
        if c.abandoned > 0 {
            warnings.push(format!(
                "spout \"{}\": {} acked tuples were abandoned after their last replay failed",
                c.name, c.abandoned
            ));
        }
    }
    RunReport {
        topology: topology.spec.name.clone(),
        seed: topology.spec.seed,
        execute_sample: topology.spec.execute_sample,
        wall_secs: wall.as_secs_f64(),
        peak_rss_mb: crate::metrics::peak_rss_mb(),
        components,
        warnings,
        edges: Vec::new(),
    }
}
