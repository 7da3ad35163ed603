//! Watches a run and shuts it down in order.
//!
//! When every spout task is exhausted it tells idle tasks to stop ticking
//! and waits for quiescence (every tuple accepted by any queue resolved, read twice with
//! equal totals); then it finishes components one at a time in dependency
//! order: finish, quiescence again, exit. On a failure it aborts every task.

use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use crate::bounds::MemoryBudget;
use crate::plan::Topology;
use crate::runtime::control::{Event, EventKind, Failure, Stage, TaskFailure};
use crate::runtime::memory;
use crate::runtime::options::RunOptions;
use crate::runtime::wiring::Wiring;
use crate::spec::Role;

/// The tasks of a run as the coordinator sees them, wherever they run:
/// in this process, or (cluster mode) also on workers.
pub(crate) trait Hosts {
    /// Moves every task of `component` forward to `stage` and wakes it.
    fn advance(&mut self, component: usize, stage: Stage);
    /// (tuples accepted, tuples resolved) over every queue and every link
    /// between processes, tuples held in producers' batches counted as
    /// accepted, or `None` while a task is inside `tick`. Resolved only
    /// grows and never passes accepted (which shrinks when a held tuple is
    /// dropped by a full `drop_newest` queue).
    fn totals(&mut self) -> Option<(u64, u64)>;
    /// Stops everything now: marks the run aborting and closes the queues.
    fn abort(&mut self);

    /// The task that has been inside one call without progress the
    /// longest, if that is `limit` or more: (component, task, how long).
    /// Hosts that cannot see their tasks' calls say `None`.
    fn stalled(&mut self, limit: Duration) -> Option<(usize, usize, Duration)> {
        let _ = limit;
        None
    }

    /// A process of the run was lost: moves its tasks to the others, or
    /// says why the run cannot go on, naming a task it lost (component,
    /// task, why). `running`: the spouts are not done.
    fn recover(&mut self, host: u16, running: bool) -> Result<(), TaskFailure> {
        let _ = running;
        Err(TaskFailure { component: 0, task: 0, message: format!("failed: host {host} was lost") })
    }
}

impl Hosts for &Wiring {
    fn advance(&mut self, component: usize, stage: Stage) {
        for control in &self.controls[component] {
            control.advance(stage);
        }
    }

    fn totals(&mut self) -> Option<(u64, u64)> {
        if self.controls.iter().flatten().any(|c| c.ticking.load(Ordering::SeqCst)) {
            return None;
        }
        Some(self.queue_totals())
    }

    fn stalled(&mut self, limit: Duration) -> Option<(usize, usize, Duration)> {
        let now = Instant::now();
        let mut longest = None;
        for (c, controls) in self.controls.iter().enumerate() {
            for (t, control) in controls.iter().enumerate() {
                if let Some(stuck) = control.stuck_for(now)
                    && stuck >= limit
                    && longest.is_none_or(|(_, _, l)| stuck > l)
                {
                    longest = Some((c, t, stuck));
                }
            }
        }
        longest
    }

    fn abort(&mut self) {
        self.aborting.store(true, Ordering::SeqCst);
        for c in 0..self.controls.len() {
            self.advance(c, Stage::Abort);
        }
        self.close_queues();
    }
}

/// How often the coordinator looks at the run while it waits.
const POLL: Duration = Duration::from_millis(1);
/// How often the watchdogs look (stalls, memory).
const WATCH: Duration = Duration::from_millis(100);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Running,
    Draining,
    Finishing(usize),
    Exiting,
}

pub(crate) struct Coordinator<'a, H: Hosts> {
    topology: &'a Topology,
    hosts: H,
    spouts_running: usize,
    finished: Vec<usize>,
    exited: usize,
    tasks: usize,
    last_scan: Option<(u64, u64)>,
    /// When the watchdogs last looked.
    last_watch: Instant,
    /// The memory limit, bytes (`None`: not watched).
    memory_limit: Option<u64>,
}

impl<'a, H: Hosts> Coordinator<'a, H> {
    pub(crate) fn new(topology: &'a Topology, hosts: H) -> Self {
        let comps = &topology.components;
        Coordinator {
            topology,
            hosts,
            spouts_running: comps
                .iter()
                .filter(|c| c.spec.role == Role::Spout)
                .map(|c| c.spec.parallelism)
                .sum(),
            finished: vec![0; comps.len()],
            exited: 0,
            tasks: comps.iter().map(|c| c.spec.parallelism).sum(),
            last_scan: None,
            last_watch: Instant::now(),
            memory_limit: MemoryBudget::for_run(topology.spec.memory_limit).limit(),
        }
    }

    fn advance(&mut self, component: usize, stage: Stage) {
        self.hosts.advance(component, stage);
    }

    /// True when everything accepted has been resolved, no tick is running,
    /// and the totals equal those of the previous look.
    fn quiescent(&mut self) -> bool {
        let scan = self.hosts.totals();
        let stable = matches!(scan, Some((a, r)) if a == r) && self.last_scan == scan;
        self.last_scan = scan;
        stable
    }

    /// The watchdogs' verdict, looked at every [`WATCH`]: a bolt stuck in
    /// one call for the topology's `stall_secs`, or resident memory past
    /// the limit. Either is logged as it is found.
    fn watch(&mut self) -> Option<Failure> {
        if self.last_watch.elapsed() < WATCH {
            return None;
        }
        self.last_watch = Instant::now();
        let limit = self.topology.spec.stall;
        if let Some((component, task, stuck)) = self.hosts.stalled(limit) {
            let message = format!(
                "stalled: no progress for {:.1} s inside one execute or tick (waits for queue space aside); \
                 the limit is [topology] stall_secs = {}",
                stuck.as_secs_f64(),
                limit.as_secs_f64()
            );
            let name = &self.topology.components[component].spec.name;
            tracing::error!(component = %name, task, "{message}");
            return Some(Failure::Task(TaskFailure { component, task, message }));
        }
        let limit = self.memory_limit?;
        let rss = memory::resident_bytes()?;
        (rss > limit).then(|| {
            tracing::error!(
                rss_mib = rss >> 20,
                limit_mib = limit >> 20,
                "resident memory past the run's limit"
            );
            Failure::Memory { rss, limit }
        })
    }

    /// Runs the shutdown protocol; returns the first failure, if any.
    /// A run whose stop was requested (`options.stop`) and that has not
    /// drained within `options.stop_drain` is aborted.
    pub(crate) fn drive(&mut self, events: &mpsc::Receiver<Event>, options: &RunOptions) -> Option<Failure> {
        let grace = options.abort_grace;
        let order = &self.topology.order;
        let mut phase = Phase::Running;
        let mut stopped_at: Option<Instant> = None;
        loop {
            if stopped_at.is_none() && options.stop.is_made() {
                stopped_at = Some(Instant::now());
            }
            if stopped_at.is_some_and(|at| at.elapsed() > options.stop_drain) {
                tracing::warn!(
                    "the stopped run did not drain within {:.0} s: aborting what is left",
                    options.stop_drain.as_secs_f64()
                );
                self.abort(events, grace);
                return Some(Failure::DrainTimedOut(options.stop_drain));
            }
            match events.recv_timeout(POLL) {
                Ok(Event { component, task, kind }) => match kind {
                    EventKind::SpoutDone => self.spouts_running -= 1,
                    EventKind::Finished => self.finished[component] += 1,
                    EventKind::Exited => self.exited += 1,
                    EventKind::Failed(message) => {
                        self.abort(events, grace);
                        return Some(Failure::Task(TaskFailure { component, task, message }));
                    }
                    EventKind::HostLost(host) => {
                        if let Err(failure) = self.hosts.recover(host, phase == Phase::Running) {
                            self.abort(events, grace);
                            return Some(Failure::Task(failure));
                        }
                        self.last_scan = None;
                    }
                },
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => return None,
            }
            if let Some(failure) = self.watch() {
                self.abort(events, grace);
                return Some(failure);
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
        self.hosts.abort();
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
