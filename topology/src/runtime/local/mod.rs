//! The in-process runtime: one thread per task, bounded queues between them,
//! a coordinator that detects the end of the run and shuts down in order.
//!
//! Shutdown: when every spout task is exhausted (and its acked tuples
//! settled), ticks stop and the coordinator waits for quiescence: every tuple
//! accepted by any queue resolved, read twice with equal totals. Then it
//! finishes components one at a time in dependency order (feedback edges
//! ignored): `finish`/`close`, quiescence again, exit. Nothing in flight is
//! lost; a tuple sent over a feedback edge to a component that has already
//! exited is counted as undelivered and reported.

pub(crate) mod acker;
pub(crate) mod control;
pub mod emitter;
pub(crate) mod erased;
pub(crate) mod queue;
pub(crate) mod target;
pub(crate) mod task;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::context::TaskContext;
use crate::grouping::{Grouping, OverflowPolicy};
use crate::metrics::{RunReport, TaskOutcome, component_report};
use crate::plan::{Factory, Topology};
use crate::spec::Role;
use crate::tuple::Source;
use acker::AckTracker;
use control::{Control, Event, EventKind, Stage, TaskSignal};
use emitter::{Emitter, PeerRoute, Route, SpoutAcking, StreamRoute, Subscription};
use queue::EdgeQueue;
use target::Target;
use task::{BoltTask, SpoutTask, TaskCommon};

/// How often the coordinator looks at the run while it waits.
const POLL: Duration = Duration::from_millis(1);

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
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("squall-io")
        .enable_all()
        .build()?;
    let mut wiring = Wiring::build(topology, options);
    let started = Instant::now();
    let (events_tx, events) = mpsc::channel();
    let mut threads: Vec<Vec<Option<JoinHandle<TaskOutcome>>>> = Vec::new();
    for (c, planned) in topology.components.iter().enumerate() {
        let mut handles = Vec::new();
        for t in 0..planned.spec.parallelism {
            let common = TaskCommon {
                ctx: wiring.context(topology, c, t),
                component: c,
                control: wiring.controls[c][t].clone(),
                emitter: wiring.emitters[c][t].take().expect("each emitter used once"),
                events: events_tx.clone(),
                finished: false,
            };
            let handle = runtime.handle().clone();
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
                    let task = BoltTask::new(common, wiring.inboxes[c][t].clone(), tick);
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
    drop(events_tx);
    let failure = Coordinator::new(topology, &wiring).drive(&events, options.abort_grace);
    let outcomes: Vec<Vec<TaskOutcome>> = threads
        .into_iter()
        .map(|handles| {
            handles
                .into_iter()
                .map(|h| match h {
                    Some(h) if h.is_finished() || failure.is_none() => {
                        h.join().unwrap_or_else(|_| lost_outcome())
                    }
                    _ => lost_outcome(),
                })
                .collect()
        })
        .collect();
    runtime.shutdown_background();
    let report = build_report(topology, &outcomes, started.elapsed());
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

fn lost_outcome() -> TaskOutcome {
    TaskOutcome { stats: Default::default(), dropped: 0, undelivered: 0, queue_depth_max: 0 }
}

fn build_report(topology: &Topology, outcomes: &[Vec<TaskOutcome>], wall: Duration) -> RunReport {
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
    }
}

/// Queues, controls and emitters of every task, before the threads start.
struct Wiring {
    controls: Vec<Vec<Arc<Control>>>,
    /// `inboxes[c][t]`: the input queues of task t (inputs in file order,
    /// then the peer queue).
    inboxes: Vec<Vec<Vec<Arc<EdgeQueue>>>>,
    emitters: Vec<Vec<Option<Emitter>>>,
    trackers: Vec<Vec<Option<Arc<AckTracker>>>>,
    aborting: Arc<AtomicBool>,
    topology_name: Arc<str>,
    out_dir: Option<Arc<PathBuf>>,
    progress: Option<Arc<Progress>>,
}

impl Wiring {
    fn build(topology: &Topology, options: &RunOptions) -> Self {
        let comps = &topology.components;
        let aborting = Arc::new(AtomicBool::new(false));
        let controls: Vec<Vec<Arc<Control>>> = comps
            .iter()
            .map(|c| {
                (0..c.spec.parallelism)
                    .map(|_| Arc::new(Control::new(Arc::new(TaskSignal::default()))))
                    .collect()
            })
            .collect();
        // edge[c][i][t]: queue of input i of component c at task t.
        let edge: Vec<Vec<Vec<Arc<EdgeQueue>>>> = comps
            .iter()
            .enumerate()
            .map(|(c, p)| {
                p.spec
                    .inputs
                    .iter()
                    .map(|input| {
                        (0..p.spec.parallelism)
                            .map(|t| {
                                Arc::new(EdgeQueue::new(
                                    input.queue,
                                    input.policy,
                                    controls[c][t].signal.clone(),
                                ))
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let peer: Vec<Option<Vec<Arc<EdgeQueue>>>> = comps
            .iter()
            .enumerate()
            .map(|(c, p)| {
                p.declared.peer.map(|_| {
                    (0..p.spec.parallelism)
                        .map(|t| {
                            Arc::new(EdgeQueue::new(
                                p.spec.peer_queue,
                                OverflowPolicy::Block,
                                controls[c][t].signal.clone(),
                            ))
                        })
                        .collect()
                })
            })
            .collect();
        let inboxes = comps
            .iter()
            .enumerate()
            .map(|(c, p)| {
                (0..p.spec.parallelism)
                    .map(|t| {
                        let mut inbox: Vec<Arc<EdgeQueue>> = edge[c].iter().map(|q| q[t].clone()).collect();
                        if let Some(peers) = &peer[c] {
                            inbox.push(peers[t].clone());
                        }
                        inbox
                    })
                    .collect()
            })
            .collect();
        let trackers: Vec<Vec<Option<Arc<AckTracker>>>> = comps
            .iter()
            .enumerate()
            .map(|(c, p)| {
                (0..p.spec.parallelism)
                    .map(|t| p.spec.ack.map(|_| AckTracker::new(controls[c][t].signal.clone())))
                    .collect()
            })
            .collect();
        let emitters = comps
            .iter()
            .enumerate()
            .map(|(c, p)| {
                (0..p.spec.parallelism)
                    .map(|t| {
                        let component: Arc<str> = p.spec.name.as_str().into();
                        let streams = p
                            .declared
                            .outputs()
                            .iter()
                            .map(|decl| {
                                let name: Arc<str> = decl.name.as_str().into();
                                let mut subscriptions = Vec::new();
                                for (ci, consumer) in comps.iter().enumerate() {
                                    for (ii, input) in consumer.spec.inputs.iter().enumerate() {
                                        if input.from != p.spec.name || input.stream != decl.name {
                                            continue;
                                        }
                                        let targets: Vec<Target> =
                                            edge[ci][ii].iter().cloned().map(Target::Local).collect();
                                        let route = match &input.grouping {
                                            Grouping::Shuffle | Grouping::LocalOrShuffle => Route::RoundRobin,
                                            Grouping::Fields(f) => {
                                                Route::Fields(static_fields(decl.message.fields(), f))
                                            }
                                            Grouping::All => Route::All,
                                            Grouping::Global => Route::Global,
                                            Grouping::Direct => Route::Direct,
                                        };
                                        // Producer tasks start their round-robin at different
                                        // consumers so that they do not move in lockstep.
                                        let next = t % targets.len();
                                        subscriptions.push(Subscription { route, targets, next });
                                    }
                                }
                                StreamRoute {
                                    name: name.clone(),
                                    message: decl.message,
                                    source: Source::Stream {
                                        component: component.clone(),
                                        stream: name,
                                        task: t,
                                    }
                                    .interned(),
                                    subscriptions,
                                }
                            })
                            .collect();
                        let peers = p.declared.peer.map(|message| PeerRoute {
                            message,
                            source: Source::Peer { task: t }.interned(),
                            targets: peer[c].iter().flatten().cloned().map(Target::Local).collect(),
                        });
                        let acking = p.spec.ack.map(|a| SpoutAcking {
                            tracker: trackers[c][t].clone().expect("tracker exists when acking"),
                            timeout: a.timeout,
                        });
                        Some(Emitter::new(t, streams, peers, acking, aborting.clone()))
                    })
                    .collect()
            })
            .collect();
        Wiring {
            controls,
            inboxes,
            emitters,
            trackers,
            aborting,
            topology_name: topology.spec.name.as_str().into(),
            out_dir: options.out_dir.clone().map(Arc::new),
            progress: options.progress.clone(),
        }
    }

    fn context(&self, topology: &Topology, c: usize, t: usize) -> TaskContext {
        let spec = &topology.components[c].spec;
        TaskContext {
            topology: self.topology_name.clone(),
            component: spec.name.as_str().into(),
            task_index: t,
            task_count: spec.parallelism,
            seed: topology.spec.seed,
            out_dir: self.out_dir.clone(),
            progress: self.progress.clone(),
        }
    }

    fn all_queues(&self) -> impl Iterator<Item = &Arc<EdgeQueue>> {
        self.inboxes.iter().flatten().flatten()
    }
}

/// The grouping field names as the type's own `'static` names (validation
/// has checked they exist).
fn static_fields(declared: Option<&'static [&'static str]>, wanted: &[String]) -> Vec<&'static str> {
    let declared = declared.unwrap_or(&[]);
    wanted.iter().filter_map(|w| declared.iter().find(|d| **d == w.as_str()).copied()).collect()
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Running,
    Draining,
    Finishing(usize),
    Exiting,
}

struct Coordinator<'a> {
    topology: &'a Topology,
    wiring: &'a Wiring,
    spouts_running: usize,
    finished: Vec<usize>,
    exited: usize,
    tasks: usize,
    last_scan: Option<(u64, u64)>,
}

impl<'a> Coordinator<'a> {
    fn new(topology: &'a Topology, wiring: &'a Wiring) -> Self {
        let comps = &topology.components;
        Coordinator {
            topology,
            wiring,
            spouts_running: comps
                .iter()
                .filter(|c| c.spec.role == Role::Spout)
                .map(|c| c.spec.parallelism)
                .sum(),
            finished: vec![0; comps.len()],
            exited: 0,
            tasks: comps.iter().map(|c| c.spec.parallelism).sum(),
            last_scan: None,
        }
    }

    fn advance(&self, component: usize, stage: Stage) {
        for control in &self.wiring.controls[component] {
            control.advance(stage);
        }
    }

    /// True when all queues have resolved everything they accepted, no tick
    /// is running, and the totals equal those of the previous look.
    fn quiescent(&mut self) -> bool {
        let ticking = self.wiring.controls.iter().flatten().any(|c| c.ticking.load(Ordering::SeqCst));
        let (mut accepted, mut resolved) = (0, 0);
        for q in self.wiring.all_queues() {
            let (a, r) = q.totals();
            accepted += a;
            resolved += r;
        }
        let scan = (accepted, resolved);
        let stable = !ticking && accepted == resolved && self.last_scan == Some(scan);
        self.last_scan = if ticking { None } else { Some(scan) };
        stable
    }

    /// Runs the shutdown protocol; returns the first failure, if any.
    fn drive(mut self, events: &mpsc::Receiver<Event>, grace: Duration) -> Option<(usize, usize, String)> {
        let order = &self.topology.order;
        let mut phase = Phase::Running;
        loop {
            match events.recv_timeout(POLL) {
                Ok(Event { component, task, kind }) => match kind {
                    EventKind::SpoutDone => self.spouts_running -= 1,
                    EventKind::Finished => self.finished[component] += 1,
                    EventKind::Exited => self.exited += 1,
                    EventKind::Failed(message) => {
                        self.abort(events, grace);
                        return Some((component, task, message));
                    }
                },
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => return None,
            }
            phase = match phase {
                Phase::Running if self.spouts_running == 0 => {
                    for c in 0..self.topology.components.len() {
                        self.advance(c, Stage::Drain);
                    }
                    self.last_scan = None;
                    Phase::Draining
                }
                Phase::Draining if self.quiescent() => {
                    self.advance(order[0], Stage::Finish);
                    Phase::Finishing(0)
                }
                Phase::Finishing(i) => {
                    let c = order[i];
                    if self.finished[c] == self.topology.components[c].spec.parallelism && self.quiescent() {
                        self.advance(c, Stage::Exit);
                        self.last_scan = None;
                        if i + 1 < order.len() {
                            self.advance(order[i + 1], Stage::Finish);
                            Phase::Finishing(i + 1)
                        } else {
                            Phase::Exiting
                        }
                    } else {
                        phase
                    }
                }
                Phase::Exiting if self.exited == self.tasks => return None,
                other => other,
            };
        }
    }

    fn abort(&mut self, events: &mpsc::Receiver<Event>, grace: Duration) {
        self.wiring.aborting.store(true, Ordering::SeqCst);
        for c in 0..self.topology.components.len() {
            self.advance(c, Stage::Abort);
        }
        for q in self.wiring.all_queues() {
            for t in q.close() {
                if let Some(a) = t.anchor {
                    a.fail();
                }
            }
        }
        let deadline = Instant::now() + grace;
        while self.exited < self.tasks {
            match events.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(Event { kind: EventKind::Exited, .. }) => self.exited += 1,
                Ok(_) => {}
                Err(_) => break,
            }
        }
    }
}
