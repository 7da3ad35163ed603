//! The coordinator of a cluster run: it reaches every worker of the
//! cluster file, places the tasks, ships the topology, starts the run once
//! every host is wired, drives the same shutdown protocol as the local
//! runtime over all hosts, and gathers every task's metrics and the
//! traffic between processes into one report.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use zenoh::Session;
use zenoh::Wait;

use crate::cluster::config::ClusterSpec;
use crate::cluster::identity::Signer;
use crate::cluster::run::host::{HostRun, HostTotals};
use crate::cluster::run::layout::Layout;
use crate::cluster::session::{
    self, SessionOptions, control_key, reply_key, send_as_coordinator, worker_key,
};
use crate::cluster::wire::{Control, DEFAULT_MAX_FRAME, EdgeTraffic, Frame, RunPlan, TaskEvent};
use crate::metrics::{EdgeReport, RunReport, TaskOutcome};
use crate::plan::Topology;
use crate::runtime::control::{Event, EventKind, Stage, TaskFailure};

use crate::runtime::coordinator::{Coordinator, Hosts};
use crate::runtime::outcome::{build_report_with_unsent, finish_run};
use crate::runtime::threads::lost_outcome;
use crate::runtime::{RunError, RunOptions};

/// How long the coordinator waits for a worker to answer at the start.
const REACH: Duration = Duration::from_secs(10);
/// How long it waits for every worker to be wired for the run.
const READY: Duration = Duration::from_secs(30);
/// How long a look at the workers' totals may take.
const STATUS: Duration = Duration::from_secs(2);
/// How long it waits for the workers' metrics at the end.
const COLLECT: Duration = Duration::from_secs(10);

/// A cluster run that could not start or failed.
#[derive(Debug, thiserror::Error)]
pub enum ClusterRunError {
    /// The run could not be set up (a worker unreachable or refusing,
    /// a placement that does not fit).
    #[error("{0}")]
    Setup(String),
    /// The run itself failed.
    #[error(transparent)]
    Run(#[from] RunError),
}

fn setup(message: impl std::fmt::Display) -> ClusterRunError {
    ClusterRunError::Setup(message.to_string())
}

/// What workers send up during a run, besides task events.
enum Up {
    Totals {
        nonce: u64,
        host: u16,
        totals: Option<HostTotals>,
    },
    Outcomes {
        host: u16,
        tasks: Vec<(u32, u32, crate::cluster::outcome::OutcomeWire)>,
        edges: Vec<EdgeTraffic>,
        refused: (u64, u64),
    },
}

/// Runs `topology` on the workers of `cluster` (and in this process, for
/// the tasks placed on the coordinator) until its spouts are exhausted and
/// every tuple is processed.
pub fn run_on_cluster(
    topology: &Topology,
    cluster: &ClusterSpec,
    options: &RunOptions,
) -> Result<RunReport, ClusterRunError> {
    let io = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("squall-coordinator")
        .enable_all()
        .build()
        .map_err(|e| setup(format!("cannot start the runtime: {e}")))?;
    for warning in cluster.exposure_warnings().into_iter().chain(topology.declared_warnings()) {
        tracing::warn!("{warning}");
    }
    let connect = cluster.workers.iter().map(|w| w.endpoint.clone()).collect();
    let session_options =
        SessionOptions { listen: Vec::new(), connect, tls: cluster.tls.clone(), allow: None };
    // With TLS, what the coordinator tells workers is signed with its
    // certificate's key: they check who sent it.
    let signer = cluster.tls.as_ref().map(Signer::load).transpose().map_err(setup)?;
    let session = io.block_on(session::open(&session_options)).map_err(setup)?;
    let result = coordinate(topology, cluster, options, &session, &io, signer.as_ref());
    let _ = session.close().wait();
    io.shutdown_background();
    result
}

/// The steps of a cluster run, in order: reach the workers, place the
/// tasks, ship the plan, start, drive the shutdown protocol, gather.
fn coordinate(
    topology: &Topology,
    cluster: &ClusterSpec,
    options: &RunOptions,
    session: &Session,
    io: &tokio::runtime::Runtime,
    signer: Option<&Signer>,
) -> Result<RunReport, ClusterRunError> {
    reach_workers(cluster, session, io)?;
    let hosts = placement(topology, cluster)?;
    let host_count = cluster.workers.len() + 1;
    let layout = Arc::new(Layout::new(topology, hosts.clone(), host_count).map_err(setup)?);
    refuse_acking_across_hosts(topology, &layout)?;
    let run = format!("squall/{}/run/{:016x}", cluster.name, session::rand_nonce());
    let _token = io.block_on(session::announce_coordinator(session)).map_err(setup)?;
    let (events_tx, events) = mpsc::channel::<Event>();
    let (up_tx, up) = mpsc::channel::<Up>();
    let plan = |host: u16| RunPlan {
        run: run.clone(),
        file: topology.spec().file().to_string(),
        topology: topology.spec().text().to_string(),
        hosts: hosts.clone(),
        host,
        host_count: host_count as u16,
        coordinator: session::coordinator_id(session),
    };
    let watched = options.live.clone().map(|live| (live, edge_names(&layout, topology)));
    let reports =
        subscribe_to_reports(session, &plan(0).report_key(), events_tx.clone(), up_tx, watched.clone())?;
    let mut local =
        HostRun::build(topology, layout.clone(), session, &run, (0, host_count), options).map_err(setup)?;
    start_workers(cluster, session, &plan, signer)?;
    let control = plan(0).control_key();
    send_as_coordinator(session, &control, Control::Go, signer).map_err(setup)?;
    let started = Instant::now();
    local.start(topology, options, &events_tx).map_err(setup)?;
    // The traffic this process's own tasks send, for the live view, each
    // second until the run ends.
    let (traffic_stop, traffic_stopped) = mpsc::channel::<()>();
    if let Some((live, names)) = &watched {
        let (live, names, link) = (live.clone(), names.clone(), local.link.clone());
        let tasks = (0..layout.components()).map(|c| layout.tasks_on(c, 0)).sum();
        std::thread::spawn(move || {
            while let Err(mpsc::RecvTimeoutError::Timeout) =
                traffic_stopped.recv_timeout(Duration::from_secs(1))
            {
                live.absorb_traffic(0, tasks, named_edges(&names, link.traffic()));
            }
        });
    }
    watch_for_lost_workers(io, session, cluster, events_tx.clone())?;
    let mut hosts_view = ClusterHosts {
        local: &mut local,
        topology,
        options,
        cluster,
        events: events_tx,
        session,
        signer,
        control: control.clone(),
        up: &up,
        workers: (1..host_count as u16).collect(),
        lost: Vec::new(),
        started,
        // A cluster reached without authentication says so in the run's
        // metrics, as it did at the start.
        warnings: cluster.exposure_warnings(),
        stash: Vec::new(),
        next_nonce: 1,
    };
    let failure = Coordinator::new(topology, &mut hosts_view).drive(&events, options);
    drop(traffic_stop);
    let ended = hosts_view.end();
    send_as_coordinator(session, &control, Control::Collect, signer).map_err(setup)?;
    let mut gathered = Gathered::new(topology, ended.warnings);
    gathered.local(&mut local, failure.is_none());
    gathered.workers(cluster, &up, ended.stash, &ended.lost);
    drop(reports);
    drop(local);
    let report = gathered.into_report(topology, &layout, started.elapsed());
    Ok(finish_run(topology, report, failure)?)
}

/// Every worker of the cluster file must answer before anything is placed.
fn reach_workers(
    cluster: &ClusterSpec,
    session: &Session,
    io: &tokio::runtime::Runtime,
) -> Result<(), ClusterRunError> {
    for w in &cluster.workers {
        io.block_on(session::ping(session, &w.endpoint, REACH)).map_err(|e| {
            setup(format!(
                "worker \"{}\" does not answer ({e}): is `squall worker --listen {}` running there?",
                w.name, w.endpoint
            ))
        })?;
    }
    Ok(())
}

/// Listens on the run's report key: task events go to the shutdown
/// protocol (`events`), totals and outcomes to `up`.
fn subscribe_to_reports(
    session: &Session,
    key: &str,
    events: mpsc::Sender<Event>,
    up: mpsc::Sender<Up>,
    reported: Option<(Arc<crate::live::LiveRun>, Vec<EdgeName>)>,
) -> Result<zenoh::pubsub::Subscriber<()>, ClusterRunError> {
    session
        .declare_subscriber(key.to_string())
        .callback(move |sample| match Frame::decode(&sample.payload().to_bytes(), DEFAULT_MAX_FRAME) {
            Ok(Frame::Control(Control::Event { component, task, event })) => {
                let kind = match event {
                    TaskEvent::SpoutDone => EventKind::SpoutDone,
                    TaskEvent::Finished => EventKind::Finished,
                    TaskEvent::Failed(m) => EventKind::Failed(m),
                    TaskEvent::Exited => EventKind::Exited,
                };
                let _ = events.send(Event { component: component as usize, task: task as usize, kind });
            }
            Ok(Frame::Control(Control::Totals {
                nonce,
                host,
                accepted,
                resolved,
                sent_to,
                received_from,
                ticking,
            })) => {
                let totals = (!ticking).then_some(HostTotals { accepted, resolved, sent_to, received_from });
                let _ = up.send(Up::Totals { nonce, host, totals });
            }
            Ok(Frame::Control(Control::Outcomes { host, tasks, edges, refused })) => {
                let _ = up.send(Up::Outcomes { host, tasks, edges, refused });
            }
            Ok(Frame::Control(Control::Live { host, tasks, edges })) => {
                if let Some((live, names)) = &reported {
                    live.absorb(host, tasks, named_edges(names, edges));
                }
            }
            Ok(other) => tracing::warn!("coordinator: unexpected report {other:?}"),
            Err(e) => tracing::warn!("coordinator: refused a report: {e}"),
        })
        .wait()
        .map_err(setup)
}

/// What the shutdown protocol leaves for the gathering.
struct Ended {
    /// Reports that came while waiting for totals.
    stash: Vec<Up>,
    /// Workers lost during the run.
    lost: Vec<u16>,
    warnings: Vec<String>,
}

/// Every task's outcome and the traffic between processes, as the hosts
/// hand them over at the end of a run.
struct Gathered {
    /// Per component, per task; `None` until its host reports it.
    outcomes: Vec<Vec<Option<TaskOutcome>>>,
    traffic: HashMap<u32, EdgeTraffic>,
    /// Frames refused: (over the size limit, malformed).
    refused: (u64, u64),
    warnings: Vec<String>,
}

impl Gathered {
    fn new(topology: &Topology, warnings: Vec<String>) -> Self {
        Gathered {
            outcomes: topology.components.iter().map(|c| vec![None; c.spec.parallelism]).collect(),
            traffic: HashMap::new(),
            refused: (0, 0),
            warnings,
        }
    }

    fn add_traffic(&mut self, edges: Vec<EdgeTraffic>) {
        for e in edges {
            let m = self.traffic.entry(e.edge).or_insert(EdgeTraffic { edge: e.edge, ..Default::default() });
            m.messages += e.messages;
            m.frames += e.frames;
            m.bytes += e.bytes;
            m.encode_ns += e.encode_ns;
            m.decode_ns += e.decode_ns;
            m.undelivered += e.undelivered;
        }
    }

    /// Joins the coordinator's own tasks and takes its traffic.
    fn local(&mut self, local: &mut HostRun, clean: bool) {
        for (c, t, o) in local.join(clean) {
            self.outcomes[c][t] = Some(o);
        }
        self.add_traffic(local.link.traffic());
        let (large, bad) = local.link.rejections.totals();
        self.refused = (self.refused.0 + large, self.refused.1 + bad);
    }

    /// Waits (at most `COLLECT`) for every worker still in the run to hand
    /// over its outcomes, starting with those already in `stash`; a worker
    /// that sends none is named in a warning and its tasks reported empty.
    fn workers(&mut self, cluster: &ClusterSpec, up: &mpsc::Receiver<Up>, stash: Vec<Up>, lost: &[u16]) {
        let host_count = cluster.workers.len() as u16 + 1;
        let mut missing: Vec<u16> = (1..host_count).filter(|h| !lost.contains(h)).collect();
        let deadline = Instant::now() + COLLECT;
        let mut pending = stash.into_iter();
        while !missing.is_empty() {
            let next = match pending.next() {
                Some(u) => u,
                None => match up.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                    Ok(u) => u,
                    Err(_) => break,
                },
            };
            let Up::Outcomes { host, tasks, edges, refused: (large, bad) } = next else { continue };
            missing.retain(|&h| h != host);
            for (c, t, wire) in tasks {
                let slot = self.outcomes.get_mut(c as usize).and_then(|c| c.get_mut(t as usize));
                match (slot, TaskOutcome::from_wire(wire)) {
                    (Some(slot), Ok(o)) => *slot = Some(o),
                    (_, Err(e)) => {
                        self.warnings.push(format!("worker {host}: a task's metrics did not decode: {e}"))
                    }
                    (None, _) => {
                        self.warnings.push(format!("worker {host}: metrics for a task that does not exist"))
                    }
                }
            }
            self.add_traffic(edges);
            self.refused = (self.refused.0 + large, self.refused.1 + bad);
        }
        for h in missing {
            self.warnings.push(format!(
                "worker \"{}\" sent no metrics: its tasks are reported empty",
                cluster.workers[usize::from(h) - 1].name
            ));
        }
    }

    /// The run's report: every task (lost ones empty), the warnings, the
    /// refused frames and the traffic per edge.
    fn into_report(self, topology: &Topology, layout: &Layout, elapsed: Duration) -> RunReport {
        let outcomes: Vec<Vec<TaskOutcome>> = self
            .outcomes
            .into_iter()
            .map(|c| c.into_iter().map(|o| o.unwrap_or_else(lost_outcome)).collect())
            .collect();
        let unsent: Vec<(usize, u64)> = self
            .traffic
            .values()
            .filter(|t| t.undelivered > 0)
            .filter_map(|t| Some((layout.edges.get(t.edge as usize)?.consumer, t.undelivered)))
            .collect();
        let mut report = build_report_with_unsent(topology, &outcomes, elapsed, &unsent);
        let mut warnings = self.warnings;
        report.warnings.append(&mut warnings);
        let (large, bad) = self.refused;
        if large + bad > 0 {
            report.warnings.push(format!(
                "frames refused between processes: {large} over the size limit, {bad} malformed"
            ));
        }
        report.edges = edge_reports(layout, topology, self.traffic);
        report
    }
}

/// Every task's host number: the cluster file's placement, or its default.
fn placement(topology: &Topology, cluster: &ClusterSpec) -> Result<Vec<Vec<u16>>, ClusterRunError> {
    for name in cluster.placement.keys() {
        if topology.spec().component(name).is_none() {
            return Err(setup(format!(
                "{}: placement of {name:?}: the topology \"{}\" has no such component",
                cluster.file,
                topology.name()
            )));
        }
    }
    topology
        .components
        .iter()
        .map(|c| {
            let hosts = cluster.place(&c.spec.name, c.spec.parallelism).map_err(setup)?;
            Ok(hosts.into_iter().map(|h| h.number()).collect())
        })
        .collect()
}

/// Acking trees do not yet span processes: a topology with acking must
/// keep every task in one process.
fn refuse_acking_across_hosts(topology: &Topology, layout: &Layout) -> Result<(), ClusterRunError> {
    let hosts = layout.hosts();
    let first = hosts.iter().flatten().next().copied().unwrap_or(0);
    let one_host = hosts.iter().flatten().all(|&h| h == first);
    match topology.components.iter().find(|c| c.spec.ack.is_some()) {
        Some(c) if !one_host => Err(setup(format!(
            "spout \"{}\" tracks its tuples (ack), which cluster mode does not support across processes yet: \
             place every component in one process, or run without ack",
            c.spec.name
        ))),
        _ => Ok(()),
    }
}

/// Ships the plan to every worker and waits until each is wired.
fn start_workers(
    cluster: &ClusterSpec,
    session: &Session,
    plan: &dyn Fn(u16) -> RunPlan,
    signer: Option<&Signer>,
) -> Result<(), ClusterRunError> {
    let mut replies = Vec::new();
    for (w, worker) in cluster.workers.iter().enumerate() {
        let subscriber = session.declare_subscriber(reply_key(&worker.endpoint)).wait().map_err(setup)?;
        let start = Control::Start(Box::new(plan(w as u16 + 1)));
        send_as_coordinator(session, &control_key(&worker.endpoint), start, signer).map_err(setup)?;
        replies.push(subscriber);
    }
    let deadline = Instant::now() + READY;
    for (worker, replies) in cluster.workers.iter().zip(&replies) {
        loop {
            let wait = deadline.saturating_duration_since(Instant::now());
            let sample = replies.recv_timeout(wait).map_err(setup)?.ok_or_else(|| {
                setup(format!("worker \"{}\" did not get ready within {} s", worker.name, READY.as_secs()))
            })?;
            match Frame::decode(&sample.payload().to_bytes(), DEFAULT_MAX_FRAME) {
                Ok(Frame::Control(Control::Ready { .. })) => break,
                Ok(Frame::Control(Control::Refused { reason, .. })) => {
                    return Err(setup(format!("worker \"{}\" refused the run: {reason}", worker.name)));
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// Reports the loss of a worker of the run to the shutdown protocol.
fn watch_for_lost_workers(
    io: &tokio::runtime::Runtime,
    session: &Session,
    cluster: &ClusterSpec,
    events: mpsc::Sender<Event>,
) -> Result<(), ClusterRunError> {
    let mut tokens = io.block_on(session::watch_workers(session)).map_err(setup)?;
    let keys: Vec<String> = cluster.workers.iter().map(|w| worker_key(&w.endpoint)).collect();
    io.spawn(async move {
        while let Some((key, alive)) = tokens.recv().await {
            if let (false, Some(w)) = (alive, keys.iter().position(|k| *k == key)) {
                let _ = events.send(Event { component: 0, task: 0, kind: EventKind::HostLost(w as u16 + 1) });
            }
        }
    });
    Ok(())
}

/// The run's hosts as the shutdown protocol sees them.
struct ClusterHosts<'a> {
    local: &'a mut HostRun,
    topology: &'a Topology,
    options: &'a RunOptions,
    cluster: &'a ClusterSpec,
    /// For the tasks that move to the coordinator's process.
    events: mpsc::Sender<Event>,
    session: &'a Session,
    /// Signs what is sent to the workers (with TLS).
    signer: Option<&'a Signer>,
    control: String,
    up: &'a mpsc::Receiver<Up>,
    /// Workers still in the run.
    workers: Vec<u16>,
    /// Workers lost.
    lost: Vec<u16>,
    started: Instant,
    warnings: Vec<String>,
    /// Reports that came while waiting for totals (outcomes of workers
    /// done early).
    stash: Vec<Up>,
    next_nonce: u64,
}

impl ClusterHosts<'_> {
    /// What the gathering needs once the shutdown protocol is over.
    fn end(self) -> Ended {
        Ended { stash: self.stash, lost: self.lost, warnings: self.warnings }
    }

    fn name(&self, host: u16) -> &str {
        self.cluster.workers.get(usize::from(host).wrapping_sub(1)).map_or("coordinator", |w| &w.name)
    }

    /// Adds one host's totals: its queues, and its traffic with the hosts
    /// still in the run (what went to or came from a lost one is gone).
    fn add(
        &self,
        sum: &mut (u64, u64),
        HostTotals { accepted, resolved, sent_to, received_from }: HostTotals,
    ) {
        let live = |h: &usize| !self.lost.contains(&(*h as u16));
        let over = |v: &[u64]| v.iter().enumerate().filter(|(h, _)| live(h)).map(|(_, n)| n).sum::<u64>();
        sum.0 += accepted + over(&sent_to);
        sum.1 += resolved + over(&received_from);
    }
}

impl Hosts for &mut ClusterHosts<'_> {
    fn advance(&mut self, component: usize, stage: Stage) {
        self.local.advance(component, stage);
        let advance = Control::Advance { component: component as u32, stage: stage as u8 };
        if let Err(e) = send_as_coordinator(self.session, &self.control, advance, self.signer) {
            tracing::warn!("coordinator: cannot reach the workers: {e}");
        }
    }

    fn totals(&mut self) -> Option<(u64, u64)> {
        let mut sum = (0, 0);
        let local = self.local.totals()?;
        self.add(&mut sum, local);
        let nonce = self.next_nonce;
        self.next_nonce += 1;
        send_as_coordinator(self.session, &self.control, Control::Status { nonce }, self.signer).ok()?;
        let mut waiting = self.workers.clone();
        let deadline = Instant::now() + STATUS;
        while !waiting.is_empty() {
            match self.up.recv_timeout(deadline.saturating_duration_since(Instant::now())).ok()? {
                Up::Totals { nonce: n, host, totals } if n == nonce && waiting.contains(&host) => {
                    waiting.retain(|&h| h != host);
                    self.add(&mut sum, totals?);
                }
                Up::Totals { .. } => {}
                other => self.stash.push(other),
            }
        }
        Some(sum)
    }

    fn abort(&mut self) {
        // An abort stops every task of every host, whichever component it
        // names: one message does.
        self.advance(0, Stage::Abort);
    }

    fn recover(&mut self, host: u16, running: bool) -> Result<(), TaskFailure> {
        if self.lost.contains(&host) || !self.workers.contains(&host) {
            return Ok(());
        }
        let name = self.name(host).to_string();
        let hosts = self.local.layout.hosts();
        let tasks: Vec<(usize, usize)> = hosts
            .iter()
            .enumerate()
            .flat_map(|(c, on)| on.iter().enumerate().filter(|(_, h)| **h == host).map(move |(t, _)| (c, t)))
            .collect();
        let Some(&(first_c, first_t)) = tasks.first() else {
            // It hosted nothing: nothing is lost.
            self.workers.retain(|&h| h != host);
            self.lost.push(host);
            return Ok(());
        };
        if !running {
            let message = format!("failed: its worker \"{name}\" was lost while the run was ending");
            return Err(TaskFailure { component: first_c, task: first_t, message });
        }
        if let Some(&(c, t)) =
            tasks.iter().find(|(c, _)| self.topology.components[*c].spec.role == crate::spec::Role::Spout)
        {
            let why = format!("failed: its worker \"{name}\" was lost, and its place in its source with it");
            return Err(TaskFailure { component: c, task: t, message: why });
        }
        let lost_at = |message: String| TaskFailure { component: first_c, task: first_t, message };
        self.workers.retain(|&h| h != host);
        self.lost.push(host);
        // Survivors take the tasks in turn; with none left, the coordinator.
        let survivors = if self.workers.is_empty() { vec![0] } else { self.workers.clone() };
        let moves: Vec<(usize, usize, u16)> =
            tasks.iter().enumerate().map(|(i, &(c, t))| (c, t, survivors[i % survivors.len()])).collect();
        let wire = moves.iter().map(|&(c, t, h)| (c as u32, t as u32, h)).collect();
        let reassign = Control::Reassign { lost: host, moves: wire };
        send_as_coordinator(self.session, &self.control, reassign, self.signer)
            .map_err(|e| lost_at(e.to_string()))?;
        self.local.reassign(self.topology, self.options, &self.events, &moves).map_err(|e| {
            lost_at(format!("failed: cannot start it again in the coordinator's process: {e}"))
        })?;
        let placed: Vec<String> = moves
            .iter()
            .map(|&(c, t, h)| format!("{} {t} → {}", self.topology.components[c].spec.name, self.name(h)))
            .collect();
        let message = format!(
            "worker \"{name}\" was lost {:.1} s into the run; its {} tasks moved: {}",
            self.started.elapsed().as_secs_f64(),
            moves.len(),
            placed.join(", ")
        );
        tracing::warn!("{message}");
        self.warnings.push(message);
        Ok(())
    }
}

/// The traffic per edge, named, in edge order.
/// (producer, stream, consumer) of an edge between processes.
type EdgeName = (String, String, String);

/// The name of each edge between processes, by id.
fn edge_names(layout: &Layout, topology: &Topology) -> Vec<EdgeName> {
    let name = |c: usize| topology.components[c].spec.name.clone();
    layout.edges.iter().map(|e| (name(e.producer), e.stream.to_string(), name(e.consumer))).collect()
}

/// Traffic with its edges named (ids not in `names` left out).
fn named_edges(names: &[EdgeName], traffic: Vec<EdgeTraffic>) -> Vec<EdgeReport> {
    traffic
        .into_iter()
        .filter_map(|t| {
            let (from, stream, to) = names.get(t.edge as usize)?.clone();
            Some(edge_report(from, stream, to, &t))
        })
        .collect()
}

fn edge_reports(layout: &Layout, topology: &Topology, traffic: HashMap<u32, EdgeTraffic>) -> Vec<EdgeReport> {
    let mut edges: Vec<_> = traffic.into_values().collect();
    edges.sort_by_key(|e| e.edge);
    edges
        .into_iter()
        .filter_map(|t| {
            let info = layout.edges.get(t.edge as usize)?;
            let name = |c: usize| topology.components[c].spec.name.clone();
            Some(edge_report(name(info.producer), info.stream.to_string(), name(info.consumer), &t))
        })
        .collect()
}

/// One edge's traffic as the report has it.
fn edge_report(from: String, stream: String, to: String, t: &EdgeTraffic) -> EdgeReport {
    EdgeReport {
        from,
        stream,
        to,
        messages: t.messages,
        frames: t.frames,
        bytes: t.bytes,
        encode_ms: t.encode_ns as f64 / 1e6,
        decode_ms: t.decode_ns as f64 / 1e6,
        undelivered: t.undelivered,
    }
}
