//! The task runtime: one thread per task, bounded queues between them, the
//! emitter that routes each tuple by its grouping, acking, ticks, and a
//! coordinator that detects the end of the run and shuts down in order. Two
//! hosts run on it: [`in_process`] (every task in this process, the
//! default) and, with the `cluster` feature, the cluster host (tasks spread
//! over worker processes, queues joined by zenoh).
//!
//! Shutdown: when every spout task is exhausted (and its acked tuples
//! settled), idle tasks stop ticking and the coordinator waits for
//! quiescence: every tuple accepted by any queue resolved, read twice with
//! equal totals. Then it
//! finishes components one at a time in dependency order (feedback edges
//! ignored): `finish`/`close`, quiescence again, exit. Nothing in flight is
//! lost; a tuple sent over a feedback edge to a component that has already
//! exited is counted as undelivered and reported.
//!
//! Watchdogs: the coordinator fails the run, naming the cause, when a bolt
//! stays inside one `execute` or `tick` without progress for the
//! topology's `stall_secs`, or when the process's resident memory passes
//! its `memory_limit_mb`.

pub(crate) mod acker;
pub(crate) mod control;
pub(crate) mod coordinator;
pub mod emitter;
pub(crate) mod erased;
pub mod in_process;
pub(crate) mod memory;
mod options;
pub(crate) mod outcome;
pub(crate) mod queue;
pub(crate) mod target;
pub(crate) mod task;
pub(crate) mod threads;
pub(crate) mod wiring;

pub use in_process::run;
pub use options::{Progress, RunOptions, STOP_DRAIN, StopRequest, process_stop};
pub use outcome::RunError;
