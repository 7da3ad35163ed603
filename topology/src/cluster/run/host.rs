//! One process's share of a cluster run: its tasks, their queues, and its
//! links to the other processes. The coordinator and every worker each
//! hold one.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc;

use zenoh::Session;
use zenoh::Wait;

use crate::cluster::run::layout::Layout;
use crate::cluster::run::link::{Inbound, Link, data_key};
use crate::metrics::TaskOutcome;
use crate::plan::Topology;
use crate::runtime::local::control::{Event, Stage};
use crate::runtime::local::target::Target;
use crate::runtime::local::wiring::{Hop, Wiring};
use crate::runtime::local::{RunOptions, TaskThreads, io_runtime, join_tasks, spawn_tasks};

/// This process's tasks of a run and its links.
pub(crate) struct HostRun {
    pub(crate) host: u16,
    pub(crate) layout: Arc<Layout>,
    pub(crate) link: Arc<Link>,
    wiring: Wiring,
    /// Drives the tasks' async code and the forwarders; `None` once shut down.
    runtime: Option<tokio::runtime::Runtime>,
    subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    threads: Option<TaskThreads>,
}

impl HostRun {
    /// Wires the tasks of `host` and starts listening for their tuples.
    pub(crate) fn build(
        topology: &Topology,
        layout: Arc<Layout>,
        session: &Session,
        prefix: &str,
        host: u16,
        options: &RunOptions,
    ) -> Result<Self, String> {
        let runtime = io_runtime().map_err(|e| format!("cannot start the runtime: {e}"))?;
        let host_count = layout.hosts.iter().flatten().map(|&h| usize::from(h) + 1).max().unwrap_or(1);
        let link = Arc::new(Link::open(session, prefix, layout.clone(), host, host_count.max(1))?);
        let elsewhere = |hop: &Hop| -> Option<Target> {
            let sends_from_here = layout.host(hop.producer, hop.from) == host;
            let to_elsewhere = layout.host(hop.consumer, hop.to) != host;
            (sends_from_here && to_elsewhere)
                .then(|| Target::Remote(Arc::new(link.target(hop.consumer, hop.slot, hop.from, hop.to))))
        };
        let wiring = Wiring::build(topology, options, &elsewhere);
        let inbound = Arc::new(Inbound::start(&link, runtime.handle(), &|c, slot, t| {
            wiring.inboxes[c][t][slot].clone()
        }));
        let (l, i) = (link.clone(), inbound);
        let subscriber = session
            .declare_subscriber(data_key(prefix, host))
            .callback(move |sample| l.on_frame(&sample.payload().to_bytes(), &i))
            .wait()
            .map_err(|e| format!("cannot subscribe to this host's tuples: {e}"))?;
        Ok(HostRun {
            host,
            layout,
            link,
            wiring,
            runtime: Some(runtime),
            subscriber: Some(subscriber),
            threads: None,
        })
    }

    /// Starts this host's tasks; they report on `events`.
    pub(crate) fn start(
        &mut self,
        topology: &Topology,
        options: &RunOptions,
        events: &mpsc::Sender<Event>,
    ) -> std::io::Result<()> {
        let (layout, host) = (&self.layout, self.host);
        let runtime = self.runtime.as_ref().expect("running").handle();
        let threads = spawn_tasks(topology, &mut self.wiring, options, runtime, events, &|c, t| {
            layout.host(c, t) == host
        })?;
        self.threads = Some(threads);
        Ok(())
    }

    /// (accepted, resolved) here, tuples sent and received over links
    /// included; `None` while a tick runs.
    pub(crate) fn totals(&self) -> Option<(u64, u64)> {
        if self.wiring.controls.iter().flatten().any(|c| c.ticking.load(Ordering::SeqCst)) {
            return None;
        }
        let (accepted, resolved) = self.wiring.queue_totals();
        let (sent, received) = self.link.counts();
        Some((accepted + sent, resolved + received))
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
        let Some(threads) = self.threads.take() else { return Vec::new() };
        let mut out = Vec::new();
        for (c, tasks) in join_tasks(threads, clean).into_iter().enumerate() {
            for (t, outcome) in tasks.into_iter().enumerate() {
                if let Some(o) = outcome {
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
