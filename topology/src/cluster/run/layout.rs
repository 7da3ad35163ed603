//! Where every task of a run lives, and the numbering of edges that all
//! processes of the run share.

use std::sync::Arc;
use std::sync::atomic::{AtomicU16, Ordering};

use crate::cluster::PlacementError;
use crate::grouping::OverflowPolicy;
use crate::message::MessageType;
use crate::plan::Topology;
use crate::tuple::Source;

/// The coordinator's host number; worker w of the cluster file is w + 1.
pub const COORDINATOR: u16 = 0;

/// One edge: a consumer's input (or its peer messages) with what crosses it.
#[derive(Debug)]
pub(crate) struct EdgeInfo {
    pub(crate) consumer: usize,
    /// The consumer's input index; its input count for peer messages.
    pub(crate) slot: usize,
    pub(crate) producer: usize,
    /// The stream's name (`peer` for peer messages).
    pub(crate) stream: Arc<str>,
    pub(crate) message: MessageType,
    pub(crate) policy: OverflowPolicy,
    pub(crate) capacity: usize,
    /// The source of a tuple from each producer task, as receivers see it.
    pub(crate) sources: Vec<&'static Source>,
}

/// Tasks' hosts and the edge table. A task's host changes when its worker
/// is lost and the task moves to a survivor.
#[derive(Debug)]
pub(crate) struct Layout {
    hosts: Vec<Vec<AtomicU16>>,
    offsets: Vec<u32>,
    pub(crate) edges: Vec<EdgeInfo>,
}

impl Layout {
    /// The layout of `topology` with task t of component c on
    /// `hosts[c][t]`; an error if the table does not fit the topology.
    pub(crate) fn new(
        topology: &Topology,
        hosts: Vec<Vec<u16>>,
        host_count: usize,
    ) -> Result<Self, PlacementError> {
        let comps = &topology.components;
        if hosts.len() != comps.len() {
            return Err(PlacementError::Components { given: hosts.len(), expected: comps.len() });
        }
        for (c, h) in comps.iter().zip(&hosts) {
            if h.len() != c.spec.parallelism {
                return Err(PlacementError::Tasks {
                    component: c.spec.name.clone(),
                    given: h.len(),
                    expected: c.spec.parallelism,
                });
            }
            if let Some(bad) = h.iter().find(|&&x| usize::from(x) >= host_count) {
                return Err(PlacementError::Host {
                    component: c.spec.name.clone(),
                    host: *bad,
                    hosts: host_count,
                });
            }
        }
        let mut offsets = Vec::with_capacity(comps.len());
        let mut edges = Vec::new();
        for (ci, consumer) in comps.iter().enumerate() {
            offsets.push(u32::try_from(edges.len()).map_err(|_| PlacementError::TooManyEdges)?);
            for (slot, input) in consumer.spec.inputs.iter().enumerate() {
                let producer = comps
                    .iter()
                    .position(|p| p.spec.name == input.from)
                    .expect("validated: inputs name components");
                let stream: Arc<str> = input.stream.as_str().into();
                let message = comps[producer]
                    .declared
                    .stream(&input.stream)
                    .expect("validated: inputs name declared streams")
                    .message;
                let component: Arc<str> = input.from.as_str().into();
                let sources = (0..comps[producer].spec.parallelism)
                    .map(|task| {
                        Source::Stream { component: component.clone(), stream: stream.clone(), task }
                            .interned()
                    })
                    .collect();
                edges.push(EdgeInfo {
                    consumer: ci,
                    slot,
                    producer,
                    stream,
                    message,
                    policy: input.policy,
                    capacity: input.queue,
                    sources,
                });
            }
            if let Some(message) = consumer.declared.peer {
                edges.push(EdgeInfo {
                    consumer: ci,
                    slot: consumer.spec.inputs.len(),
                    producer: ci,
                    stream: "peer".into(),
                    message,
                    policy: OverflowPolicy::Block,
                    capacity: consumer.spec.peer_queue,
                    sources: (0..consumer.spec.parallelism)
                        .map(|task| Source::Peer { task }.interned())
                        .collect(),
                });
            }
        }
        let hosts = hosts.into_iter().map(|h| h.into_iter().map(AtomicU16::new).collect()).collect();
        Ok(Layout { hosts, offsets, edges })
    }

    /// The id of consumer `c`'s input `slot`.
    pub(crate) fn edge_id(&self, c: usize, slot: usize) -> u32 {
        self.offsets[c] + slot as u32
    }

    /// The host of task t of component c.
    pub(crate) fn host(&self, c: usize, t: usize) -> u16 {
        self.hosts[c][t].load(Ordering::Acquire)
    }

    /// Moves task t of component c to `host`.
    pub(crate) fn move_task(&self, c: usize, t: usize, host: u16) {
        self.hosts[c][t].store(host, Ordering::Release);
    }

    /// Every task's host now.
    pub(crate) fn hosts(&self) -> Vec<Vec<u16>> {
        self.hosts.iter().map(|h| h.iter().map(|x| x.load(Ordering::Acquire)).collect()).collect()
    }

    /// Tasks per component.
    pub(crate) fn tasks(&self, c: usize) -> usize {
        self.hosts[c].len()
    }

    /// How many tasks of component c are on `host` now.
    pub(crate) fn tasks_on(&self, c: usize, host: u16) -> usize {
        (0..self.tasks(c)).filter(|&t| self.host(c, t) == host).count()
    }

    /// The first task (component, task) on `host` now, if any.
    pub(crate) fn first_task_on(&self, host: u16) -> Option<(usize, usize)> {
        (0..self.components())
            .flat_map(|c| (0..self.tasks(c)).map(move |t| (c, t)))
            .find(|&(c, t)| self.host(c, t) == host)
    }

    /// Components.
    pub(crate) fn components(&self) -> usize {
        self.hosts.len()
    }
}
