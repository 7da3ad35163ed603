//! Cluster mode (feature `cluster`): the same topologies across worker
//! processes joined by zenoh. In so far: the cluster file, the frames that
//! cross processes with their checks, and workers' sessions, presence and
//! control. Running a topology's tasks on workers is to come.

pub mod config;
pub mod session;
pub mod wire;

/// The zenoh this build uses, for components that talk to it directly
/// (the live robot link).
pub use zenoh;
