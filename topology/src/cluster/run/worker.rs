//! A worker's side of a run: validate the shipped topology, wire this
//! host's tasks, say ready, start on `Go`, follow the coordinator's stages,
//! report task events and totals, and hand over the metrics at the end.

use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use zenoh::Session;
use zenoh::Wait;

use crate::cluster::run::host::HostRun;
use crate::cluster::run::layout::Layout;
use crate::cluster::session::send_control;
use crate::cluster::wire::{Control, DEFAULT_MAX_FRAME, Frame, Rejections, RunPlan, TaskEvent};
use crate::plan::Topology;
use crate::registry::Registry;
use crate::runtime::RunOptions;
use crate::runtime::control::{Event, EventKind, Stage};
use crate::spec::TopologySpec;

/// How long a worker waits for `Go` after saying it is ready.
const PATIENCE: Duration = Duration::from_secs(60);

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

fn put(session: &Session, key: &str, control: Control) -> Result<(), String> {
    send_control(session, key, control).map_err(|e| format!("cannot reach the coordinator: {e}"))
}

/// Hosts `plan` on this worker until the coordinator collects it; answers
/// on `reply_key`. `release` is told the coordinator once the run is over
/// for this worker (refused or collected), so its going is not a loss. The topology is validated against `registry`; a plan
/// that does not fit is refused with the reason.
pub fn host_run(
    session: &Session,
    plan: &RunPlan,
    registry: &Registry,
    reply_key: &str,
    options: &RunOptions,
    release: &dyn Fn(&str),
) -> Result<Hosted, String> {
    let refuse = |reason: String| {
        release(&plan.coordinator);
        let _ = put(session, reply_key, Control::Refused { run: plan.run.clone(), reason: reason.clone() });
        reason
    };
    let topology = TopologySpec::parse(&plan.file, &plan.topology)
        .and_then(|spec| Topology::validate(spec, registry))
        .map_err(|e| refuse(format!("the topology does not validate here: {e}")))?;
    let layout =
        Arc::new(Layout::new(&topology, plan.hosts.clone(), usize::from(plan.host_count)).map_err(refuse)?);
    let control = session
        .declare_subscriber(plan.control_key())
        .wait()
        .map_err(|e| refuse(format!("cannot subscribe to run control: {e}")))?;
    let hosts = (plan.host, usize::from(plan.host_count));
    let mut host = HostRun::build(&topology, layout, session, &plan.run, hosts, options).map_err(refuse)?;
    put(session, reply_key, Control::Ready { run: plan.run.clone() })?;
    let report_key = plan.report_key();
    let control_refused = Rejections::default();
    let next = |wait: Duration| -> Result<Option<Control>, String> {
        match control.recv_timeout(wait) {
            Ok(Some(sample)) => match Frame::decode(&sample.payload().to_bytes(), DEFAULT_MAX_FRAME) {
                Ok(Frame::Control(c)) => Ok(Some(c)),
                Ok(_) => Ok(None),
                Err(e) => {
                    tracing::warn!("worker: refused a run control frame: {e}");
                    control_refused.count(&e);
                    Ok(None)
                }
            },
            Ok(None) => Ok(None),
            Err(e) => Err(format!("run control closed: {e}")),
        }
    };
    // Wait for Go; stages may not come before it.
    let deadline = Instant::now() + PATIENCE;
    loop {
        match next(Duration::from_millis(50))? {
            Some(Control::Go) => break,
            Some(Control::Advance { stage, .. }) if stage == Stage::Abort as u8 => {
                return Ok(Hosted { topology: topology.name().to_string(), tasks: 0, aborted: true });
            }
            _ if Instant::now() > deadline => return Err("no Go from the coordinator".into()),
            _ => {}
        }
    }
    let (events_tx, events) = mpsc::channel();
    if let Err(e) = host.start(&topology, options, &events_tx) {
        // Fail the run in the coordinator's eyes too (in a task of this
        // host's), rather than leave it waiting for tasks that never start.
        let layout = &host.layout;
        let here = (0..layout.components())
            .flat_map(|c| (0..layout.tasks(c)).map(move |t| (c, t)))
            .find(|&(c, t)| layout.host(c, t) == plan.host);
        if let Some((c, t)) = here {
            let failed = TaskEvent::Failed(e.clone());
            put(session, &report_key, Control::Event { component: c as u32, task: t as u32, event: failed })?;
        }
        return Err(e);
    }
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
            put(
                session,
                &report_key,
                Control::Event { component: component as u32, task: task as u32, event },
            )?;
        }
        match next(Duration::from_millis(1))? {
            Some(Control::Advance { component, stage }) => {
                let Some(stage) = Stage::from_u8(stage) else { continue };
                aborted |= stage == Stage::Abort;
                if (component as usize) < topology.components.len() {
                    host.advance(component as usize, stage);
                }
            }
            Some(Control::Status { nonce }) => {
                let totals = match host.totals() {
                    Some((accepted, resolved, sent_to, received_from)) => Control::Totals {
                        nonce,
                        host: plan.host,
                        accepted,
                        resolved,
                        sent_to,
                        received_from,
                        ticking: false,
                    },
                    None => Control::Totals {
                        nonce,
                        host: plan.host,
                        accepted: 0,
                        resolved: 0,
                        sent_to: Vec::new(),
                        received_from: Vec::new(),
                        ticking: true,
                    },
                };
                put(session, &report_key, totals)?;
            }
            Some(Control::Reassign { moves, .. }) => {
                let moves = checked_moves(&topology, &moves, plan.host_count);
                host.reassign(&topology, options, &events_tx, &moves)
                    .map_err(|e| format!("cannot start a task moved here: {e}"))?;
            }
            Some(Control::Collect) => break,
            Some(_) | None => {}
        }
    }
    // Every task has exited when the coordinator collects (after an
    // abort, those still running after the grace are left behind).
    let tasks = host.join(!aborted);
    let count = tasks.len();
    let outcomes = Control::Outcomes {
        host: plan.host,
        tasks: tasks.into_iter().map(|(c, t, o)| (c as u32, t as u32, o.to_wire())).collect(),
        edges: host.link.traffic(),
        refused: {
            let ((a, b), (c, d)) = (host.link.rejections.totals(), control_refused.totals());
            (a + c, b + d)
        },
    };
    release(&plan.coordinator);
    put(session, &report_key, outcomes)?;
    Ok(Hosted { topology: topology.name().to_string(), tasks: count, aborted })
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
