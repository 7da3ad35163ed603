//! One process's share of a cluster run: its tasks, their queues, and its
//! links to the other processes. The coordinator and every worker each
//! hold one. When a worker is lost, every host applies the same moves; the
//! host a task moves to starts a fresh instance of it (a replacement, as
//! after a restart), routed by where every task is now.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::Duration;

use zenoh::Session;
use zenoh::Wait;

use crate::cluster::HostError;
use crate::cluster::run::layout::Layout;
use crate::cluster::run::link::{Inbound, Link, data_key};
use crate::metrics::TaskOutcome;
use crate::plan::Topology;
use crate::runtime::RunOptions;
use crate::runtime::control::{Event, Stage};
use crate::runtime::target::Target;
use crate::runtime::threads::{TaskThreads, io_runtime, join_tasks, spawn_tasks};
use crate::runtime::wiring::{Hop, Wiring};

/// How long a host waits, once told to go, for every other host's
/// subscription to reach it.
const HEARD: Duration = Duration::from_secs(10);

/// Where task t of component c's tuples to each consumer go, from this
/// host: a link target unless the consumer is here too.
fn elsewhere(link: &Arc<Link>, host: u16) -> impl Fn(&Hop) -> Option<Target> + '_ {
    move |hop: &Hop| {
        let sends_from_here = link.layout.host(hop.producer, hop.from) == host;
        let to_elsewhere = link.layout.host(hop.consumer, hop.to) != host;
        (sends_from_here && to_elsewhere)
            .then(|| Target::Remote(Arc::new(link.target(hop.consumer, hop.slot, hop.from, hop.to))))
    }
}

/// A host's counts for the shutdown protocol's quiescence test.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct HostTotals {
    /// Tuples its queues accepted.
    pub(crate) accepted: u64,
    /// Tuples its queues resolved (executed or dropped).
    pub(crate) resolved: u64,
    /// Tuples it sent to each host.
    pub(crate) sent_to: Vec<u64>,
    /// Tuples it received from each host.
    pub(crate) received_from: Vec<u64>,
}

/// This process's tasks of a run and its links.
pub(crate) struct HostRun {
    pub(crate) host: u16,
    pub(crate) layout: Arc<Layout>,
    pub(crate) link: Arc<Link>,
    wiring: Wiring,
    inbound: Arc<Inbound>,
    /// Drives the tasks' async code and the forwarders; `None` once shut down.
    runtime: Option<tokio::runtime::Runtime>,
    subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    threads: TaskThreads,
}

impl HostRun {
    /// Wires the tasks of `host` and starts listening for their tuples.
    pub(crate) fn build(
        topology: &Topology,
        layout: Arc<Layout>,
        session: &Session,
        prefix: &str,
        (host, host_count): (u16, usize),
        options: &RunOptions,
    ) -> Result<Self, HostError> {
        let runtime =
            io_runtime().map_err(|source| HostError::Os { doing: "cannot start the runtime", source })?;
        let link = Arc::new(Link::open(session, prefix, layout.clone(), host, host_count)?);
        let wiring = Wiring::build(topology, options, &elsewhere(&link, host));
        let inbound = Arc::new(Inbound::default());
        for c in 0..layout.components() {
            for t in (0..layout.tasks(c)).filter(|&t| layout.host(c, t) == host) {
                inbound.serve_task(&link, runtime.handle(), c, t, &|slot| wiring.inboxes[c][t][slot].clone());
            }
        }
        let (l, i) = (link.clone(), inbound.clone());
        let subscriber = session
            .declare_subscriber(data_key(prefix, host))
            .callback(move |sample| l.on_frame(&sample.payload().to_bytes(), &i))
            .wait()
            .map_err(|e| HostError::transport("cannot subscribe to this host's tuples", e))?;
        let threads = layout.hosts().iter().map(|tasks| tasks.iter().map(|_| None).collect()).collect();
        Ok(HostRun {
            host,
            layout,
            link,
            wiring,
            inbound,
            runtime: Some(runtime),
            subscriber: Some(subscriber),
            threads,
        })
    }

    fn handle(&self) -> &tokio::runtime::Handle {
        self.runtime.as_ref().expect("running until dropped").handle()
    }

    /// Starts this host's tasks, once every host's subscription has reached
    /// this one (at most `HEARD` after `Go`); they report on `events`.
    pub(crate) fn start(
        &mut self,
        topology: &Topology,
        options: &RunOptions,
        events: &mpsc::Sender<Event>,
    ) -> Result<(), HostError> {
        let waited = self.link.wait_until_heard(HEARD)?;
        tracing::debug!("host {}: heard every host after {:.1} ms", self.host, waited.as_secs_f64() * 1e3);
        let (layout, host) = (self.layout.clone(), self.host);
        let runtime = self.handle().clone();
        self.threads = spawn_tasks(topology, &mut self.wiring, options, &runtime, events, &|c, t| {
            layout.host(c, t) == host
        })
        .map_err(|source| HostError::Os { doing: "cannot start tasks", source })?;
        Ok(())
    }

    /// Applies the moves of a lost host's tasks: every host reroutes, and
    /// this one starts the tasks that move here.
    pub(crate) fn reassign(
        &mut self,
        topology: &Topology,
        options: &RunOptions,
        events: &mpsc::Sender<Event>,
        moves: &[(usize, usize, u16)],
    ) -> std::io::Result<()> {
        for &(c, t, to) in moves {
            self.layout.move_task(c, t, to);
        }
        for &(c, t, _) in moves {
            self.link.task_moved(c, t);
        }
        let runtime = self.handle().clone();
        for &(c, t, to) in moves.iter().filter(|m| m.2 == self.host) {
            let emitter = self.wiring.emitter(topology, c, t, &elsewhere(&self.link, self.host));
            self.wiring.emitters[c][t] = Some(emitter);
            let wiring = &self.wiring;
            self.inbound.serve_task(&self.link, &runtime, c, t, &|slot| wiring.inboxes[c][t][slot].clone());
            self.wiring.replacements.insert((c, t));
            let replacement = |cc: usize, tt: usize| (cc, tt) == (c, t);
            let mut spawned =
                spawn_tasks(topology, &mut self.wiring, options, &runtime, events, &replacement)?;
            self.threads[c][t] = spawned[c][t].take();
            tracing::warn!("host {}: took over task {t} of component {c} (now on host {to})", self.host);
        }
        Ok(())
    }

    /// (accepted, resolved) by this host's queues, the tuples sent to and
    /// received from each host; `None` while a tick runs.
    pub(crate) fn totals(&self) -> Option<HostTotals> {
        if self.wiring.controls.iter().flatten().any(|c| c.ticking.load(Ordering::SeqCst)) {
            return None;
        }
        let (accepted, resolved) = self.wiring.queue_totals();
        let (sent_to, received_from) = self.link.counts();
        Some(HostTotals { accepted, resolved, sent_to, received_from })
    }

    /// Moves this host's tasks of `component` to `stage`; an abort also
    /// closes the queues and ends waits for credits.
    pub(crate) fn advance(&self, component: usize, stage: Stage) {
        if stage == Stage::Abort {
            self.wiring.aborting.store(true, Ordering::SeqCst);
            for controls in &self.wiring.controls {
                controls.iter().for_each(|c| c.advance(Stage::Abort));
            }
            self.wiring.close_queues();
            self.link.close();
            return;
        }
        for control in &self.wiring.controls[component] {
            control.advance(stage);
        }
    }

    /// Joins this host's task threads: (component, task, outcome).
    pub(crate) fn join(&mut self, clean: bool) -> Vec<(usize, usize, TaskOutcome)> {
        let threads = std::mem::take(&mut self.threads);
        let mut out = Vec::new();
        for (c, tasks) in join_tasks(threads, clean).into_iter().enumerate() {
            for (t, outcome) in tasks.into_iter().enumerate() {
                if let Some(mut o) = outcome {
                    // As in-process: a producer that ended after its
                    // consumer added its abandoned batch to the queue.
                    (o.dropped, o.undelivered) = self.wiring.queue_losses(c, t);
                    out.push((c, t, o));
                }
            }
        }
        out
    }
}

impl Drop for HostRun {
    fn drop(&mut self) {
        if let Some(s) = self.subscriber.take() {
            let _ = s.undeclare().wait();
        }
        if let Some(r) = self.runtime.take() {
            r.shutdown_background();
        }
    }
}

impl std::fmt::Debug for HostRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HostRun").field("host", &self.host).finish_non_exhaustive()
    }
}
