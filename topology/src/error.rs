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
