//! A worker's side of a run: validate the shipped topology, wire this
//! host's tasks, say ready, start on `Go`, follow the coordinator's stages,
//! report task events and totals, and hand over the metrics at the end.

use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use zenoh::Session;
use zenoh::Wait;

use crate::cluster::HostError;
use crate::cluster::identity::Verifier;
use crate::cluster::run::host::{HostRun, HostTotals};
use crate::cluster::run::layout::Layout;
use crate::cluster::session::send_control;
use crate::cluster::wire::{Control, DEFAULT_MAX_FRAME, Frame, Rejections, RunPlan, TaskEvent};
use crate::plan::Topology;
use crate::registry::Registry;
use crate::runtime::RunOptions;
use crate::runtime::control::{Event, EventKind, Stage};
use crate::spec::SpecErrors;
use crate::spec::TopologySpec;

/// How long a worker waits for `Go` after saying it is ready.
const PATIENCE: Duration = Duration::from_secs(60);
/// How often a worker reports its tasks' counters while a run goes.
const LIVE_PERIOD: Duration = Duration::from_secs(1);

/// What a worker did in one run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hosted {
    /// The topology's name.
    pub topology: String,
    /// Tasks it ran.
    pub tasks: usize,
    /// Whether the run was aborted.
    pub aborted: bool,
}

fn put(session: &Session, key: &str, control: Control) -> Result<(), HostError> {
    send_control(session, key, control).map_err(|e| HostError::transport("cannot reach the coordinator", e))
}

/// What one run may take of a worker, whatever its plan asks: the
/// worker's own bounds (`squall worker --max-tasks`, `--max-queued`,
/// `--max-run-secs`, `--max-memory-mb`, and `--insecure` for links
/// without authentication). A plan over the first two, or with such a
/// link without the last, is refused before anything starts; a run past
/// the others fails, naming the limit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WorkerLimits {
    /// Tasks of one run on this worker.
    pub max_tasks: usize,
    /// Tuples that may wait in this worker's input queues: the bounds of
    /// every input queue (and peer queue) of the tasks it hosts, summed.
    pub max_queued: usize,
    /// Wall time of one run on this worker (`None`: unbounded, for a live
    /// robot that streams for hours).
    pub max_run: Option<Duration>,
    /// Resident memory of the worker process, bytes (`None`: unbounded).
    pub max_memory: Option<u64>,
    /// Whether plans may make this worker talk beyond loopback without
    /// authentication (a live link with `insecure = true` placed here):
    /// the worker's own `--insecure`.
    pub insecure: bool,
}

/// What a worker holds a run to: its limits, and, with mutual TLS, the
/// check of signatures and the name of the coordinator whose plan it is
/// (only it may drive the run).
#[derive(Debug, Clone, Copy)]
pub struct HostPolicy<'a> {
    /// The worker's bounds.
    pub limits: &'a WorkerLimits,
    /// The signature check and the plan's coordinator.
    pub authority: Option<(&'a Verifier, &'a str)>,
}

impl Default for WorkerLimits {
    /// 64 tasks, a million queued tuples, no time limit, 90% of the
    /// machine's memory.
    fn default() -> Self {
        WorkerLimits {
            max_tasks: 64,
            max_queued: 1 << 20,
            max_run: None,
            max_memory: crate::runtime::memory::default_limit(),
            insecure: false,
        }
    }
}

impl WorkerLimits {
    /// Why a plan placing these tasks here is refused, if it is.
    fn refusal(&self, topology: &Topology, layout: &Layout, host: u16) -> Option<String> {
        let (mut tasks, mut queued) = (0usize, 0usize);
        for (c, component) in topology.components.iter().enumerate() {
            let here = layout.tasks_on(c, host);
            let spec = &component.spec;
            let peers = if component.declared.peer_type().is_some() { spec.peer_queue } else { 0 };
            let per_task = spec.inputs.iter().map(|i| i.queue).sum::<usize>() + peers;
            tasks += here;
            queued = queued.saturating_add(here.saturating_mul(per_task));
        }
        let hosted = |c: usize| layout.tasks_on(c, host) > 0;
        if let Some(exposed) = topology.exposures(hosted).first().filter(|_| !self.insecure) {
            return Some(format!(
                "{exposed}; this worker hosts unauthenticated links only if started with --insecure"
            ));
        }
        if tasks > self.max_tasks {
            return Some(format!(
                "the plan places {tasks} tasks on this worker, past its limit of {} (--max-tasks)",
                self.max_tasks
            ));
        }
        (queued > self.max_queued).then(|| {
            format!(
                "the plan's input queues on this worker hold up to {queued} tuples, past its limit of {} \
                 (--max-queued)",
                self.max_queued
            )
        })
    }
}

/// Hosts `plan` on this worker until the coordinator collects it; answers
/// on `reply_key`. `release` is told the coordinator once the run is over
/// for this worker (refused or collected), so its going is not a loss. The
/// topology is validated against `registry`; a plan that does not fit, or
/// that asks more than `limits` allow, is refused with the reason.
pub fn host_run(
    session: &Session,
    plan: &RunPlan,
    registry: &Registry,
    reply_key: &str,
    options: &RunOptions,
    policy: HostPolicy<'_>,
    release: &dyn Fn(&str),
) -> Result<Hosted, HostError> {
    let HostPolicy { limits, authority } = policy;
    let refuse = |reason: HostError| {
        release(&plan.coordinator);
        let _ =
            put(session, reply_key, Control::Refused { run: plan.run.clone(), reason: reason.to_string() });
        reason
    };
    // The tasks publish their counters, for the reports of `Control::Live`.
    let live = crate::live::LiveRun::new();
    let options = &RunOptions { live: Some(live.clone()), ..options.clone() };
    let (topology, mut control, mut host) =
        prepare(session, plan, registry, options, limits).map_err(refuse)?;
    control.authority = authority.map(|(verifier, name)| (verifier, name.to_string(), plan.control_key()));
    put(session, reply_key, Control::Ready { run: plan.run.clone() })?;
    let name = topology.name().to_string();
    if !control.wait_for_go()? {
        return Ok(Hosted { topology: name, tasks: 0, aborted: true });
    }
    let report_key = plan.report_key();
    let (events_tx, events) = mpsc::channel();
    if let Err(e) = host.start(&topology, options, &events_tx) {
        // Fail the run in the coordinator's eyes too, rather than leave it
        // waiting for tasks that never start.
        fail_here(session, &report_key, &host.layout, plan.host, e.to_string())?;
        return Err(e);
    }
    let mut run = Following {
        session,
        plan,
        topology: &topology,
        options,
        host: &mut host,
        report_key,
        live,
        next_live: Instant::now() + LIVE_PERIOD,
        limits,
        started: Instant::now(),
        next_limit_check: Instant::now(),
        over_limit: false,
    };
    let aborted = run.follow(&control, &events_tx, &events)?;
    let tasks = run.hand_over(&control, aborted, release)?;
    Ok(Hosted { topology: name, tasks, aborted })
}

/// Validates the shipped topology, subscribes to run control and wires
/// this host's tasks; the error is the reason to refuse the plan.
fn prepare(
    session: &Session,
    plan: &RunPlan,
    registry: &Registry,
    options: &RunOptions,
    limits: &WorkerLimits,
) -> Result<(Topology, ControlInbox<'static>, HostRun), HostError> {
    let topology = TopologySpec::parse(&plan.file, &plan.topology)
        .and_then(|spec| Topology::validate(spec, registry))
        .map_err(HostError::Invalid)?;
    let layout = Arc::new(Layout::new(&topology, plan.hosts.clone(), usize::from(plan.host_count))?);
    if let Some(refusal) = limits.refusal(&topology, &layout, plan.host) {
        return Err(HostError::Limit(refusal));
    }
    if let Some(policy) = crate::confine::policy() {
        // Before any task starts (and opens what it declared): every
        // path a component hosted here reads or writes is inside the
        // worker's folders. (What components read while they validate
        // was checked as they read it.)
        let hosted = |c: usize| layout.tasks_on(c, plan.host) > 0;
        let errors = topology.confinement_errors(policy, hosted);
        if !errors.is_empty() {
            return Err(HostError::Confined(SpecErrors(errors)));
        }
    }
    let subscriber = session
        .declare_subscriber(plan.control_key())
        .wait()
        .map_err(|e| HostError::transport("cannot subscribe to run control", e))?;
    let control = ControlInbox { subscriber, refused: Rejections::default(), authority: None };
    let hosts = (plan.host, usize::from(plan.host_count));
    let host = HostRun::build(&topology, layout, session, &plan.run, hosts, options)?;
    Ok((topology, control, host))
}

/// The coordinator's run control messages, as this worker receives them;
/// frames that do not decode are counted, not followed. With an
/// authority (mutual TLS), only frames the plan's own coordinator signed
/// for this run's key are followed.
struct ControlInbox<'a> {
    subscriber: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    refused: Rejections,
    /// The check, the coordinator's name and the run's control key.
    authority: Option<(&'a Verifier, String, String)>,
}

impl ControlInbox<'_> {
    /// The next control message within `wait`, if any.
    fn next(&self, wait: Duration) -> Result<Option<Control>, HostError> {
        match self.subscriber.recv_timeout(wait) {
            Ok(Some(sample)) => match Frame::decode(&sample.payload().to_bytes(), DEFAULT_MAX_FRAME) {
                Ok(frame) if self.authority.is_some() => Ok(self.authorized(frame)),
                Ok(Frame::Control(c)) => Ok(Some(c)),
                Ok(_) => Ok(None),
                Err(e) => {
                    tracing::warn!("worker: refused a run control frame: {e}");
                    self.refused.count(&e);
                    Ok(None)
                }
            },
            Ok(None) => Ok(None),
            Err(e) => Err(HostError::ControlClosed(e.to_string())),
        }
    }

    /// What `frame` says, if the run's own coordinator signed it for
    /// this run; a refusal is logged and counted.
    fn authorized(&self, frame: Frame) -> Option<Control> {
        let (verifier, coordinator, key) = self.authority.as_ref()?;
        let (name, control) = verifier.accept(frame, key)?;
        if name != *coordinator {
            verifier.count_refusal(&format!(
                "coordinator {name:?} tried to drive a run of coordinator {coordinator:?}"
            ));
            return None;
        }
        Some(control)
    }

    /// Waits (at most `PATIENCE`) for `Go`: true once it comes, false if
    /// the run is aborted first. Stages may not come before it.
    fn wait_for_go(&self) -> Result<bool, HostError> {
        let deadline = Instant::now() + PATIENCE;
        loop {
            match self.next(Duration::from_millis(50))? {
                Some(Control::Go) => return Ok(true),
                Some(Control::Advance { stage, .. }) if stage == Stage::Abort as u8 => return Ok(false),
                _ if Instant::now() > deadline => return Err(HostError::NoGo),
                _ => {}
            }
        }
    }
}

/// Fails the run through a task of `host` (the first it has), reporting
/// `message` on `report_key`: the coordinator then aborts the run, as for
/// any failed task.
fn fail_here(
    session: &Session,
    report_key: &str,
    layout: &Layout,
    host: u16,
    message: String,
) -> Result<(), HostError> {
    match layout.first_task_on(host) {
        Some((c, t)) => {
            let event = TaskEvent::Failed(message);
            put(session, report_key, Control::Event { component: c as u32, task: t as u32, event })
        }
        None => Ok(()),
    }
}

/// How often a run is checked against the worker's time and memory
/// limits.
const LIMIT_CHECK: Duration = Duration::from_millis(100);

/// A started run on this worker, following the coordinator.
struct Following<'a> {
    session: &'a Session,
    plan: &'a RunPlan,
    topology: &'a Topology,
    options: &'a RunOptions,
    host: &'a mut HostRun,
    report_key: String,
    live: Arc<crate::live::LiveRun>,
    next_live: Instant,
    limits: &'a WorkerLimits,
    started: Instant,
    next_limit_check: Instant,
    /// Whether the run went past a limit (and was failed for it).
    over_limit: bool,
}

impl Following<'_> {
    /// Reports task events and follows stages, status requests and moves
    /// until the coordinator collects; returns whether the run was aborted.
    fn follow(
        &mut self,
        control: &ControlInbox,
        events_tx: &mpsc::Sender<Event>,
        events: &mpsc::Receiver<Event>,
    ) -> Result<bool, HostError> {
        let mut aborted = false;
        loop {
            while let Ok(Event { component, task, kind }) = events.try_recv() {
                let event = match kind {
                    EventKind::SpoutDone => TaskEvent::SpoutDone,
                    EventKind::Finished => TaskEvent::Finished,
                    EventKind::Failed(m) => TaskEvent::Failed(m),
                    EventKind::Exited => TaskEvent::Exited,
                    EventKind::HostLost(_) => continue,
                };
                let event = Control::Event { component: component as u32, task: task as u32, event };
                put(self.session, &self.report_key, event)?;
            }
            if Instant::now() >= self.next_live {
                self.next_live = Instant::now() + LIVE_PERIOD;
                put(self.session, &self.report_key, self.live_report())?;
            }
            if !self.over_limit && Instant::now() >= self.next_limit_check {
                self.next_limit_check = Instant::now() + LIMIT_CHECK;
                if let Some(why) = self.past_limit() {
                    self.fail_for_limit(&why)?;
                }
            }
            match control.next(Duration::from_millis(1))? {
                Some(Control::Advance { component, stage }) => {
                    let Some(stage) = Stage::from_u8(stage) else { continue };
                    aborted |= stage == Stage::Abort;
                    if (component as usize) < self.topology.components.len() {
                        self.host.advance(component as usize, stage);
                    }
                }
                Some(Control::Status { nonce }) => put(self.session, &self.report_key, self.totals(nonce))?,
                Some(Control::Reassign { moves, .. }) => {
                    let moves = checked_moves(self.topology, &moves, self.plan.host_count);
                    self.host.reassign(self.topology, self.options, events_tx, &moves).map_err(|source| {
                        HostError::Os { doing: "cannot start a task moved here", source }
                    })?;
                }
                Some(Control::Collect) => return Ok(aborted),
                Some(_) | None => {}
            }
        }
    }

    /// Which of the worker's limits the run is past, if any.
    fn past_limit(&self) -> Option<String> {
        if let Some(max) = self.limits.max_run
            && self.started.elapsed() > max
        {
            return Some(format!(
                "the run went past this worker's time limit of {} s (--max-run-secs)",
                max.as_secs_f64()
            ));
        }
        let limit = self.limits.max_memory?;
        let rss = crate::runtime::memory::resident_bytes()?;
        (rss > limit).then(|| {
            format!(
                "the worker's resident memory, {} MiB, went past its limit of {} MiB (--max-memory-mb)",
                rss >> 20,
                limit >> 20
            )
        })
    }

    /// Fails the run for a limit: a task of this host reports the failure
    /// (the coordinator then aborts the run, as for any failed task).
    fn fail_for_limit(&mut self, why: &str) -> Result<(), HostError> {
        self.over_limit = true;
        tracing::error!("worker: {why}");
        fail_here(
            self.session,
            &self.report_key,
            &self.host.layout,
            self.plan.host,
            format!("worker limit: {why}"),
        )
    }

    /// This host's tasks and traffic now.
    fn live_report(&self) -> Control {
        let (layout, host) = (&self.host.layout, self.plan.host);
        let tasks = self.live.report_tasks(|c, t| layout.host(c, t) == host);
        Control::Live { host, tasks, edges: self.host.link.traffic() }
    }

    /// This host's totals for status request `nonce` (none while a tick runs).
    fn totals(&self, nonce: u64) -> Control {
        let host = self.plan.host;
        match self.host.totals() {
            Some(HostTotals { accepted, resolved, sent_to, received_from }) => {
                Control::Totals { nonce, host, accepted, resolved, sent_to, received_from, ticking: false }
            }
            None => Control::Totals {
                nonce,
                host,
                accepted: 0,
                resolved: 0,
                sent_to: Vec::new(),
                received_from: Vec::new(),
                ticking: true,
            },
        }
    }

    /// Joins this host's tasks and hands their metrics and the traffic to
    /// the coordinator; returns how many tasks ran here.
    fn hand_over(
        &mut self,
        control: &ControlInbox,
        aborted: bool,
        release: &dyn Fn(&str),
    ) -> Result<usize, HostError> {
        // Every task has exited when the coordinator collects (after an
        // abort, those still running after the grace are left behind).
        let tasks = self.host.join(!aborted);
        let count = tasks.len();
        let outcomes = Control::Outcomes {
            host: self.plan.host,
            tasks: tasks.into_iter().map(|(c, t, o)| (c as u32, t as u32, o.to_wire())).collect(),
            edges: self.host.link.traffic(),
            refused: {
                let ((a, b), (c, d)) = (self.host.link.rejections.totals(), control.refused.totals());
                (a + c, b + d)
            },
        };
        release(&self.plan.coordinator);
        put(self.session, &self.report_key, outcomes)?;
        Ok(count)
    }
}

/// The moves that name tasks of this topology and hosts of this run.
fn checked_moves(
    topology: &Topology,
    moves: &[(u32, u32, u16)],
    host_count: u16,
) -> Vec<(usize, usize, u16)> {
    moves
        .iter()
        .map(|&(c, t, h)| (c as usize, t as usize, h))
        .filter(|&(c, t, h)| {
            let fits = topology.components.get(c).is_some_and(|p| t < p.spec.parallelism) && h < host_count;
            if !fits {
                tracing::warn!("worker: refused a move of task {t} of component {c} to host {h}");
            }
            fits
        })
        .collect()
}
