//! What goes wrong in one process of a cluster run: its links to the other
//! processes, its share of the tasks, and a worker's side of the protocol.

use crate::spec::SpecErrors;

/// Why a host (the coordinator's process or a worker) could not take part
/// in a run, or stopped taking part.
#[derive(Debug, thiserror::Error)]
pub enum HostError {
    /// zenoh refused an operation (declaring, publishing, subscribing).
    #[error("{doing}: {reason}")]
    Transport {
        /// What the host was doing.
        doing: String,
        /// zenoh's reason.
        reason: String,
    },
    /// zenoh refused an operation, its reason alone saying which.
    #[error("{0}")]
    Zenoh(String),
    /// The OS refused a runtime or the task threads.
    #[error("{doing}: {source}")]
    Os {
        /// What the host was starting.
        doing: &'static str,
        /// The OS's reason.
        source: std::io::Error,
    },
    /// Another host's subscription never reached this one.
    #[error("host {host} never heard from host {other} within {secs} s: can the workers reach each other?")]
    Unheard {
        /// This host.
        host: u16,
        /// The host not heard.
        other: usize,
        /// How long it waited.
        secs: u64,
    },
    /// A tuple for a host that is not in the run.
    #[error("no such host")]
    NoSuchHost,
    /// The placement does not fit the topology or the cluster.
    #[error(transparent)]
    Placement(#[from] PlacementError),
    /// The shipped topology does not validate in this process.
    #[error("the topology does not validate here: {0}")]
    Invalid(SpecErrors),
    /// The plan names files this worker may not touch (its `--data-dir`
    /// and `--out`); nothing was read or started.
    #[error("the plan touches files outside this worker's folders: {0}")]
    Confined(SpecErrors),
    /// The plan asks more of this worker than its limits allow.
    #[error("{0}")]
    Limit(String),
    /// The coordinator never said go.
    #[error("no Go from the coordinator")]
    NoGo,
    /// The run control subscription closed.
    #[error("run control closed: {0}")]
    ControlClosed(String),
}

#[cfg(feature = "cluster")]
impl HostError {
    /// zenoh's error `reason` while the host was `doing` something.
    pub(crate) fn transport(doing: impl Into<String>, reason: impl std::fmt::Display) -> Self {
        HostError::Transport { doing: doing.into(), reason: reason.to_string() }
    }
}

/// A placement table (the host of every task) that does not fit the
/// topology or the cluster.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlacementError {
    /// A table for another number of components.
    #[error("placement for {given} components, the topology has {expected}")]
    Components {
        /// Components in the table.
        given: usize,
        /// Components of the topology.
        expected: usize,
    },
    /// A component placed with another number of tasks.
    #[error("placement of \"{component}\" has {given} tasks, the topology {expected}")]
    Tasks {
        /// The component.
        component: String,
        /// Tasks in the table.
        given: usize,
        /// Its parallelism.
        expected: usize,
    },
    /// A task placed on a host the run does not have.
    #[error("placement of \"{component}\" names host {host} of {hosts}")]
    Host {
        /// The component.
        component: String,
        /// The host named.
        host: u16,
        /// Hosts in the run.
        hosts: usize,
    },
    /// The cluster file lists another number of hosts than the component
    /// has tasks.
    #[error("{file}: placement of {component:?} names {listed} hosts, but it has {tasks} tasks")]
    Listed {
        /// The cluster file.
        file: String,
        /// The component.
        component: String,
        /// Hosts the file lists for it.
        listed: usize,
        /// Its tasks.
        tasks: usize,
    },
    /// More edges than the wire format numbers.
    #[error("too many edges")]
    TooManyEdges,
}
