//! Runtimes that host a validated topology.
//!
//! The in-process runtime ([`local`]) is the default. Everything a task sees
//! (its emitter, its input queues) goes through [`local::emitter::Emitter`]
//! and [`local::queue`], the boundary a cluster transport plugs into.

pub mod local;
