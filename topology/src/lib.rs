//! squall-topology: the stream topology engine.
//!
//! Storm's model, in Rust: **spouts** produce tuples, **bolts** consume and
//! emit them, each component runs as `parallelism` tasks, and every
//! subscription chooses a **grouping** (shuffle, fields, all, global, direct,
//! local-or-shuffle). Topologies are declared in TOML ([`spec`]), checked
//! against a [`Registry`] of component kinds ([`Topology::validate`]) and run
//! by a runtime ([`runtime::run`]). The engine knows nothing about
//! robots. [`testing`] runs one bolt task alone, for unit tests.
//!
//! Guarantees of the in-process runtime:
//! - every queue is bounded; a full queue blocks the producer or drops by
//!   policy, and every drop is counted;
//! - a run ends when the spouts are exhausted and every tuple is processed;
//! - a panic names its component and fails the run (or restarts the task);
//! - opt-in acking replays failed or timed-out spout tuples.

pub mod bounds;
pub mod cluster;
mod component;
pub mod confine;
mod context;
mod declare;
mod error;
mod field_hash;
pub mod fsio;
pub mod graph;
mod grouping;
pub mod hash;
mod introspect;
pub mod live;
mod message;
pub mod metrics;
mod params;
mod plan;
mod registry;
pub mod runtime;
pub mod spec;
pub mod testing;
mod tuple;

pub use component::{Bolt, MessageId, Spout, SpoutStatus};
pub use context::{ReadingCounter, TaskContext};
pub use declare::{Accepts, DEFAULT_STREAM, Declarer, StreamDecl};
pub use error::{BoxError, CodecError, EmitError, Error, ParamError, Result};
pub use field_hash::FieldHashError;
pub use grouping::{Grouping, OverflowPolicy};
pub use live::LiveRun;
pub use message::{Incremental, Message, MessageType, Payload};
pub use metrics::{ComponentReport, CustomMetric, EdgeReport, RunReport, TaskReport};
pub use params::Params;
pub use plan::Topology;
pub use registry::Registry;
pub use runtime::emitter::Emitter;
pub use runtime::{Progress, RunError, RunOptions, StopRequest, run};
pub use spec::{Override, OverrideError, TopologySpec};
pub use tuple::{Source, Tuple};
