//! Builds every task's queues, routes and emitter before the threads start.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use crate::context::TaskContext;
use crate::grouping::{Grouping, OverflowPolicy};
use crate::plan::Topology;
use crate::runtime::acker::AckTracker;
use crate::runtime::control::{Control, TaskSignal};
use crate::runtime::emitter::{Emitter, PeerRoute, Route, SpoutAcking, StreamRoute, Subscription};
use crate::runtime::queue::EdgeQueue;
use crate::runtime::target::Target;
use crate::runtime::{Progress, RunOptions, StopRequest};
use crate::tuple::Source;

/// Queues, controls and emitters of every task, before the threads start.
pub(crate) struct Wiring {
    pub(crate) controls: Vec<Vec<Arc<Control>>>,
    /// `inboxes[c][t]`: the input queues of task t (inputs in file order,
    /// then the peer queue).
    pub(crate) inboxes: Vec<Vec<Vec<Arc<EdgeQueue>>>>,
    pub(crate) emitters: Vec<Vec<Option<Emitter>>>,
    pub(crate) trackers: Vec<Vec<Option<Arc<AckTracker>>>>,
    /// `held[c][t]`: tuples task t of component c holds in batches, as it
    /// last published them.
    held: Vec<Vec<Arc<AtomicU64>>>,
    pub(crate) aborting: Arc<AtomicBool>,
    /// Tasks started again after their process was lost (cluster mode).
    pub(crate) replacements: std::collections::HashSet<(usize, usize)>,
    topology_name: Arc<str>,
    out_dir: Option<Arc<PathBuf>>,
    progress: Option<Arc<Progress>>,
    stop: Arc<StopRequest>,
}

/// One delivery path: from task `from` of component `producer` to task
/// `to` of component `consumer`, through the consumer's input `slot` (its
/// inputs in file order, then the peer queue).
#[derive(Debug, Clone, Copy)]
#[cfg_attr(not(feature = "cluster"), allow(dead_code))]
pub(crate) struct Hop {
    pub(crate) producer: usize,
    pub(crate) from: usize,
    pub(crate) consumer: usize,
    pub(crate) slot: usize,
    pub(crate) to: usize,
}

/// Gives the target of a hop whose consumer task runs in another process;
/// `None` for a task in this one.
pub(crate) type Elsewhere<'a> = &'a dyn Fn(&Hop) -> Option<Target>;

impl Wiring {
    /// The tuples dropped and undelivered at task `t` of component `c`'s
    /// input queues, as they stand: read once every thread has ended, so
    /// that a producer that ended after its consumer (and counted its
    /// held batch as undelivered there) is counted too.
    pub(crate) fn queue_losses(&self, c: usize, t: usize) -> (u64, u64) {
        self.inboxes.get(c).and_then(|tasks| tasks.get(t)).map_or((0, 0), |queues| {
            let sum = |f: fn(&EdgeQueue) -> u64| queues.iter().map(|q| f(q)).sum::<u64>();
            (
                sum(|q| q.counters.dropped.load(Ordering::Relaxed)),
                sum(|q| q.counters.undelivered.load(Ordering::Relaxed)),
            )
        })
    }

    /// Every task's queues and emitter; a hop to a task in another process
    /// gets the target `elsewhere` gives it.
    pub(crate) fn build(topology: &Topology, options: &RunOptions, elsewhere: Elsewhere<'_>) -> Self {
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
        let held = comps.iter().map(|c| (0..c.spec.parallelism).map(|_| Arc::default()).collect()).collect();
        let mut wiring = Wiring {
            controls,
            inboxes,
            held,
            emitters: Vec::new(),
            replacements: Default::default(),
            trackers,
            aborting,
            topology_name: topology.spec.name.as_str().into(),
            out_dir: options.out_dir.clone().map(Arc::new),
            progress: options.progress.clone(),
            stop: options.stop.clone(),
        };
        wiring.emitters = comps
            .iter()
            .enumerate()
            .map(|(c, p)| {
                (0..p.spec.parallelism).map(|t| Some(wiring.emitter(topology, c, t, elsewhere))).collect()
            })
            .collect();
        wiring
    }

    /// The emitter of task t of component c, routed by where every
    /// consumer task is now (`elsewhere`).
    pub(crate) fn emitter(
        &self,
        topology: &Topology,
        c: usize,
        t: usize,
        elsewhere: Elsewhere<'_>,
    ) -> Emitter {
        let comps = &topology.components;
        let p = &comps[c];
        let queue = |ci: usize, slot: usize, to: usize| {
            let hop = Hop { producer: c, from: t, consumer: ci, slot, to };
            elsewhere(&hop).unwrap_or_else(|| Target::Local(self.inboxes[ci][to][slot].clone()))
        };
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
                        let mut targets: Vec<Target> =
                            (0..consumer.spec.parallelism).map(|to| queue(ci, ii, to)).collect();
                        if input.grouping == Grouping::LocalOrShuffle
                            && targets.iter().any(|t| matches!(t, Target::Local(_)))
                        {
                            // Only the consumer tasks in this process.
                            targets.retain(|t| matches!(t, Target::Local(_)));
                        }
                        let route = match &input.grouping {
                            Grouping::Shuffle | Grouping::LocalOrShuffle => Route::RoundRobin,
                            Grouping::Fields(f) => Route::Fields(static_fields(decl.message.fields(), f)),
                            Grouping::All => Route::All,
                            Grouping::Global => Route::Global,
                            Grouping::Direct => Route::Direct,
                        };
                        // Producer tasks start their round-robin at different
                        // consumers so that they do not move in lockstep.
                        let next = t % targets.len();
                        subscriptions.push(Subscription::new(route, targets, next, input.batch));
                    }
                }
                let has_direct = subscriptions.iter().any(|s| matches!(s.route, Route::Direct));
                let held_only = !subscriptions.is_empty() && subscriptions.iter().all(|s| !s.batch.is_off());
                StreamRoute {
                    has_direct,
                    held_only,
                    name: name.clone(),
                    message: decl.message,
                    source: Source::Stream { component: component.clone(), stream: name, task: t }.interned(),
                    subscriptions,
                }
            })
            .collect();
        let peers = p.declared.peer.map(|message| PeerRoute {
            message,
            source: Source::Peer { task: t }.interned(),
            targets: (0..p.spec.parallelism).map(|to| queue(c, p.spec.inputs.len(), to)).collect(),
        });
        let acking = p.spec.ack.map(|a| SpoutAcking {
            tracker: self.trackers[c][t].clone().expect("tracker exists when acking"),
            timeout: a.timeout,
        });
        let mut emitter = Emitter::new(t, streams, peers, acking, self.aborting.clone());
        emitter.held_now = self.held[c][t].clone();
        emitter
    }

    pub(crate) fn context(&self, topology: &Topology, c: usize, t: usize) -> TaskContext {
        let spec = &topology.components[c].spec;
        TaskContext {
            topology: self.topology_name.clone(),
            component: spec.name.as_str().into(),
            task_index: t,
            task_count: spec.parallelism,
            seed: topology.spec.seed,
            out_dir: self.out_dir.clone(),
            progress: self.progress.clone(),
            replacement: self.replacements.contains(&(c, t)),
            stop: self.stop.clone(),
        }
    }

    pub(crate) fn all_queues(&self) -> impl Iterator<Item = &Arc<EdgeQueue>> {
        self.inboxes.iter().flatten().flatten()
    }

    /// (accepted, resolved) summed over every queue, tuples held in
    /// producers' batches counted as accepted. The held counts are read
    /// first: a hand-over between the two reads then counts a tuple twice
    /// (the run looks busy a moment longer), never not at all.
    pub(crate) fn queue_totals(&self) -> (u64, u64) {
        let held: u64 = self.held.iter().flatten().map(|h| h.load(Ordering::SeqCst)).sum();
        let (accepted, resolved) =
            self.all_queues().map(|q| q.totals()).fold((0, 0), |(a, r), (qa, qr)| (a + qa, r + qr));
        (accepted + held, resolved)
    }

    /// Closes every queue at an abort; the tuples left in them fail their
    /// acking trees.
    pub(crate) fn close_queues(&self) {
        for q in self.all_queues() {
            q.close().into_iter().for_each(crate::tuple::Tuple::lost);
        }
    }
}

/// The grouping field names as the type's own `'static` names (validation
/// has checked they exist).
fn static_fields(declared: Option<&'static [&'static str]>, wanted: &[String]) -> Vec<&'static str> {
    let declared = declared.unwrap_or(&[]);
    wanted.iter().filter_map(|w| declared.iter().find(|d| **d == w.as_str()).copied()).collect()
}
