//! The in-process runtime: one thread per task, bounded queues between them,
//! a coordinator that detects the end of the run and shuts down in order.
//!
//! Shutdown: when every spout task is exhausted (and its acked tuples
//! settled), idle tasks stop ticking and the coordinator waits for
//! quiescence: every tuple accepted by any queue resolved, read twice with
//! equal totals. Then it
//! finishes components one at a time in dependency order (feedback edges
//! ignored): `finish`/`close`, quiescence again, exit. Nothing in flight is
//! lost; a tuple sent over a feedback edge to a component that has already
//! exited is counted as undelivered and reported.

pub(crate) mod acker;
pub(crate) mod control;
pub(crate) mod coordinator;
pub mod emitter;
pub(crate) mod erased;
pub(crate) mod queue;
pub(crate) mod target;
pub(crate) mod task;
pub(crate) mod wiring;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::metrics::{RunReport, TaskOutcome, component_report};
use crate::plan::{Factory, Topology};
use crate::spec::Role;
use coordinator::Coordinator;
use task::{BoltTask, SpoutTask, TaskCommon};
use wiring::Wiring;

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
    /// The runtime itself could not start.
    #[error("cannot start the runtime: {0}")]
    Start(#[from] std::io::Error),
}

/// Runs `topology` in this process until its spouts are exhausted and every
/// tuple is processed.
pub fn run(topology: &Topology, options: &RunOptions) -> Result<RunReport, RunError> {
    let runtime = io_runtime()?;
    let mut wiring = Wiring::build(topology, options, &|_| None);
    let started = Instant::now();
    let (events_tx, events) = mpsc::channel();
    let threads = spawn_tasks(topology, &mut wiring, options, runtime.handle(), &events_tx, &|_, _| true)?;
    drop(events_tx);
    let failure = Coordinator::new(topology, &wiring).drive(&events, options.abort_grace);
    let outcomes = join_tasks(threads, failure.is_none())
        .into_iter()
        .map(|c| c.into_iter().map(|o| o.unwrap_or_else(lost_outcome)).collect())
        .collect::<Vec<Vec<_>>>();
    runtime.shutdown_background();
    let report = build_report(topology, &outcomes, started.elapsed());
    finish_run(topology, report, failure)
}

/// The runtime that drives every task's async code (one thread: tasks run
/// on their own threads and only block on it).
pub(crate) fn io_runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("squall-io")
        .enable_all()
        .build()
}

/// The report as the run's result: an error naming the failed task, if any.
pub(crate) fn finish_run(
    topology: &Topology,
    report: RunReport,
    failure: Option<(usize, usize, String)>,
) -> Result<RunReport, RunError> {
    match failure {
        None => Ok(report),
        Some((c, task, message)) => {
            let spec = &topology.components[c].spec;
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

/// A thread per task that `here` says runs in this process (`None` for the
/// others).
pub(crate) type TaskThreads = Vec<Vec<Option<JoinHandle<TaskOutcome>>>>;

/// Starts the threads of the tasks for which `here(component, task)` holds.
pub(crate) fn spawn_tasks(
    topology: &Topology,
    wiring: &mut Wiring,
    options: &RunOptions,
    runtime: &tokio::runtime::Handle,
    events: &mpsc::Sender<control::Event>,
    here: &dyn Fn(usize, usize) -> bool,
) -> std::io::Result<TaskThreads> {
    let mut threads: TaskThreads = Vec::new();
    for (c, planned) in topology.components.iter().enumerate() {
        let mut handles = Vec::new();
        for t in 0..planned.spec.parallelism {
            if !here(c, t) {
                handles.push(None);
                continue;
            }
            let common = TaskCommon {
                ctx: wiring.context(topology, c, t),
                component: c,
                control: wiring.controls[c][t].clone(),
                emitter: wiring.emitters[c][t].take().expect("each emitter used once"),
                events: events.clone(),
                finished: false,
            };
            let handle = runtime.clone();
            let params = planned.params.clone();
            let restarts = planned.spec.max_restarts;
            let name = format!("{}#{t}", planned.spec.name);
            let spawned = match &planned.factory {
                Factory::Spout(f) => {
                    let acking =
                        planned.spec.ack.map(|p| (wiring.trackers[c][t].clone().expect("acking"), p));
                    let task = SpoutTask::new(common, acking, options.progress.clone(), options.stop.clone());
                    let f = f.clone();
                    std::thread::Builder::new()
                        .name(name)
                        .spawn(move || task::spout_thread(f, params, task, handle, restarts))
                }
                Factory::Bolt(f) => {
                    let tick = planned.spec.tick.or(planned.declared.tick);
                    let inbox = wiring.inboxes[c][t].clone();
                    // Inputs in file order, then the peer queue: only the
                    // non-feedback inputs wait while the bolt holds them.
                    let mut holdable: Vec<bool> = planned.spec.inputs.iter().map(|i| !i.feedback).collect();
                    holdable.resize(inbox.len(), false);
                    let task = BoltTask::new(common, inbox, holdable, tick);
                    let f = f.clone();
                    std::thread::Builder::new()
                        .name(name)
                        .spawn(move || task::bolt_thread(f, params, task, handle, restarts))
                }
            };
            handles.push(Some(spawned?));
        }
        threads.push(handles);
    }
    Ok(threads)
}

/// Joins the task threads. After a failure, threads that have not ended
/// within the abort's grace are left behind and give no outcome.
pub(crate) fn join_tasks(threads: TaskThreads, clean: bool) -> Vec<Vec<Option<TaskOutcome>>> {
    threads
        .into_iter()
        .map(|handles| {
            handles
                .into_iter()
                .map(|h| match h {
                    Some(h) if h.is_finished() || clean => Some(h.join().unwrap_or_else(|_| lost_outcome())),
                    Some(_) => Some(lost_outcome()),
                    None => None,
                })
                .collect()
        })
        .collect()
}

pub(crate) fn lost_outcome() -> TaskOutcome {
    TaskOutcome { stats: Default::default(), dropped: 0, undelivered: 0, queue_depth_max: 0 }
}

pub(crate) fn build_report(topology: &Topology, outcomes: &[Vec<TaskOutcome>], wall: Duration) -> RunReport {
    let components: Vec<_> = topology
        .components
        .iter()
        .zip(outcomes)
        .map(|(p, o)| component_report(&p.spec.name, &p.spec.kind, p.spec.role, o))
        .collect();
    let mut warnings = Vec::new();
    for c in &components {
        if c.undelivered > 0 {
            warnings.push(format!(
                "{} \"{}\": {} tuples arrived after it had exited or at an abort and were not executed",
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
        wall_secs: wall.as_secs_f64(),
        components,
        warnings,
        edges: Vec::new(),
    }
}
