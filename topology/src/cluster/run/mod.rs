//! Running a topology across processes: the coordinator's side
//! ([`run_on_cluster`]) and a worker's ([`host_run`]). Every process wires
//! the whole topology the same way; a hop to a task in another process
//! becomes a link (see `link`), and the local runtime's shutdown protocol
//! runs over all hosts.

mod coordinator;
pub(crate) mod host;
pub(crate) mod layout;
pub(crate) mod link;
mod worker;

pub use coordinator::{ClusterRunError, run_on_cluster};
pub use layout::COORDINATOR;
pub use worker::{HostPolicy, Hosted, WorkerLimits, host_run};
