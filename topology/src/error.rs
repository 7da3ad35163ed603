//! Error types of the engine.

use std::fmt;

/// The error a component returns from its own code.
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A component's parameters are invalid; raised by the component's factory.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ParamError(pub String);

impl ParamError {
    /// A parameter error with a message saying what was expected.
    pub fn new(message: impl fmt::Display) -> Self {
        ParamError(message.to_string())
    }
}

/// A message could not be encoded for, or decoded from, another process:
/// the error of an [`Incremental`](crate::Incremental) codec.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct CodecError(pub String);

impl CodecError {
    /// A codec error saying what is wrong with the bytes or the state.
    pub fn new(message: impl fmt::Display) -> Self {
        CodecError(message.to_string())
    }
}

/// An emit that the engine refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EmitError {
    /// The component did not declare a stream of this name.
    #[error("stream \"{0}\" was not declared")]
    UnknownStream(String),
    /// The value's type is not the stream's declared type.
    #[error("stream \"{stream}\" carries {expected}, not {actual}")]
    WrongType {
        /// The stream.
        stream: String,
        /// The declared type.
        expected: &'static str,
        /// The emitted type.
        actual: &'static str,
    },
    /// A `direct` subscriber exists but the emit named no task.
    #[error("stream \"{0}\" has a direct subscriber: use emit_direct and name the task")]
    DirectNeedsTask(String),
    /// The named task does not exist.
    #[error("task {task} does not exist (the component has {count} tasks)")]
    NoSuchTask {
        /// The requested task.
        task: usize,
        /// Tasks of the target component.
        count: usize,
    },
    /// The component declared no peer message type.
    #[error("no peer message type was declared (Declarer::peer)")]
    NoPeerStream,
    /// A `fields` grouping could not hash the message.
    #[error("fields grouping failed: {0}")]
    FieldHash(#[from] crate::field_hash::FieldHashError),
    /// The run is being aborted.
    #[error("the run is shutting down")]
    ShuttingDown,
    /// The tuple could not be sent to a task in another process.
    #[error("cannot send to another process: {0}")]
    Transport(String),
}

/// Any error of the engine, for callers that chain its steps with `?`
/// (read a topology, validate it, run it) and report what went wrong.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The topology file does not check.
    #[error(transparent)]
    Spec(#[from] crate::spec::SpecErrors),
    /// A `--set` override does not parse or fit the file.
    #[error(transparent)]
    Override(#[from] crate::spec::OverrideError),
    /// A component's parameters are invalid.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// An emit was refused.
    #[error(transparent)]
    Emit(#[from] EmitError),
    /// A message did not cross processes.
    #[error(transparent)]
    Codec(#[from] CodecError),
    /// The run failed.
    #[error(transparent)]
    Run(#[from] crate::runtime::RunError),
    /// A cluster run could not start or failed.
    #[cfg(feature = "cluster")]
    #[error(transparent)]
    Cluster(#[from] crate::cluster::run::ClusterRunError),
    /// A process of a cluster run could not take part.
    #[cfg(feature = "cluster")]
    #[error(transparent)]
    Host(#[from] crate::cluster::HostError),
}

/// The engine's result: [`Error`] unless a step names its own error.
pub type Result<T, E = Error> = std::result::Result<T, E>;
