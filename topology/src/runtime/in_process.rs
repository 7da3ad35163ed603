//! The in-process host: every task of the topology on a thread of this
//! process, joined by the shared runtime's bounded queues. The embedded
//! default; the cluster host runs the same tasks spread over processes.

use std::sync::mpsc;
use std::time::Instant;

use crate::metrics::RunReport;
use crate::plan::Topology;
use crate::runtime::coordinator::Coordinator;
use crate::runtime::outcome::{build_report, finish_run};
use crate::runtime::threads::{io_runtime, join_tasks, lost_outcome, spawn_tasks};
use crate::runtime::wiring::Wiring;
use crate::runtime::{RunError, RunOptions};

/// Runs `topology` in this process until its spouts are exhausted and every
/// tuple is processed.
pub fn run(topology: &Topology, options: &RunOptions) -> Result<RunReport, RunError> {
    for warning in topology.declared_warnings() {
        tracing::warn!("{warning}");
    }
    let runtime = io_runtime()?;
    let mut wiring = Wiring::build(topology, options, &|_| None);
    let started = Instant::now();
    let (events_tx, events) = mpsc::channel();
    let threads = spawn_tasks(topology, &mut wiring, options, runtime.handle(), &events_tx, &|_, _| true)?;
    drop(events_tx);
    let failure = Coordinator::new(topology, &wiring).drive(&events, options);
    let mut outcomes = join_tasks(threads, failure.is_none())
        .into_iter()
        .map(|c| c.into_iter().map(|o| o.unwrap_or_else(lost_outcome)).collect())
        .collect::<Vec<Vec<_>>>();
    // A consumer counts its queues' losses when its thread ends; a producer
    // ending after it (a failed run) may still add its abandoned batch
    // there. Every thread has ended (or been left behind): count them as
    // they stand.
    for (c, tasks) in outcomes.iter_mut().enumerate() {
        for (t, outcome) in tasks.iter_mut().enumerate() {
            (outcome.dropped, outcome.undelivered) = wiring.queue_losses(c, t);
        }
    }
    runtime.shutdown_background();
    let report = build_report(topology, &outcomes, started.elapsed());
    if let Some(live) = &options.live {
        live.finish(&report);
    }
    finish_run(topology, report, failure)
}
