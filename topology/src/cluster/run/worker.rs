//! A worker's side of a run: validate the shipped topology, wire this
//! host's tasks, say ready, start on `Go`, follow the coordinator's stages,
//! report task events and totals, and hand over the metrics at the end.

use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use zenoh::Session;
use zenoh::Wait;

use crate::cluster::HostError;
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

/// Hosts `plan` on this worker until the coordinator collects it; answers
/// on `reply_key`. `release` is told the coordinator once the run is over
/// for this worker (refused or collected), so its going is not a loss. The
/// topology is validated against `registry`; a plan that does not fit is
/// refused with the reason.
pub fn host_run(
    session: &Session,
    plan: &RunPlan,
    registry: &Registry,
    reply_key: &str,
    options: &RunOptions,
    release: &dyn Fn(&str),
) -> Result<Hosted, HostError> {
    let refuse = |reason: HostError| {
        release(&plan.coordinator);
        let _ =
            put(session, reply_key, Control::Refused { run: plan.run.clone(), reason: reason.to_string() });
        reason
    };
    // The tasks publish their counters, for the reports of `Control::Live`.
    let live = crate::live::LiveRun::new();
    let options = &RunOptions { live: Some(live.clone()), ..options.clone() };
    let (topology, control, mut host) = prepare(session, plan, registry, options).map_err(refuse)?;
    put(session, reply_key, Control::Ready { run: plan.run.clone() })?;
    let name = topology.name().to_string();
    if !control.wait_for_go()? {
        return Ok(Hosted { topology: name, tasks: 0, aborted: true });
    }
    let report_key = plan.report_key();
    let (events_tx, events) = mpsc::channel();
    if let Err(e) = host.start(&topology, options, &events_tx) {
        // Fail the run in the coordinator's eyes too (in a task of this
        // host's), rather than leave it waiting for tasks that never start.
        let layout = &host.layout;
        let here = (0..layout.components())
            .flat_map(|c| (0..layout.tasks(c)).map(move |t| (c, t)))
            .find(|&(c, t)| layout.host(c, t) == plan.host);
        if let Some((c, t)) = here {
            let failed = TaskEvent::Failed(e.to_string());
            put(session, &report_key, Control::Event { component: c as u32, task: t as u32, event: failed })?;
        }
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
) -> Result<(Topology, ControlInbox, HostRun), HostError> {
    let topology = TopologySpec::parse(&plan.file, &plan.topology)
        .and_then(|spec| Topology::validate(spec, registry))
        .map_err(HostError::Invalid)?;
    let layout = Arc::new(Layout::new(&topology, plan.hosts.clone(), usize::from(plan.host_count))?);
    if let Some(policy) = crate::confine::policy() {
        // Before any task starts (and opens what it declared): every
        // path a component hosted here reads or writes is inside the
        // worker's folders. (What components read while they validate
        // was checked as they read it.)
        let hosted = |c: usize| (0..layout.tasks(c)).any(|t| layout.host(c, t) == plan.host);
        let errors = topology.confinement_errors(policy, hosted);
        if !errors.is_empty() {
            return Err(HostError::Confined(SpecErrors(errors)));
        }
    }
    let subscriber = session
        .declare_subscriber(plan.control_key())
        .wait()
        .map_err(|e| HostError::transport("cannot subscribe to run control", e))?;
    let control = ControlInbox { subscriber, refused: Rejections::default() };
    let hosts = (plan.host, usize::from(plan.host_count));
    let host = HostRun::build(&topology, layout, session, &plan.run, hosts, options)?;
    Ok((topology, control, host))
}

/// The coordinator's run control messages, as this worker receives them;
/// frames that do not decode are counted, not followed.
struct ControlInbox {
    subscriber: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    refused: Rejections,
}

impl ControlInbox {
    /// The next control message within `wait`, if any.
    fn next(&self, wait: Duration) -> Result<Option<Control>, HostError> {
        match self.subscriber.recv_timeout(wait) {
            Ok(Some(sample)) => match Frame::decode(&sample.payload().to_bytes(), DEFAULT_MAX_FRAME) {
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
