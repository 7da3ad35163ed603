//! How a subscription spreads a stream over the consumer's tasks, and what a
//! full queue does.

use std::fmt;

/// How the tuples of a subscribed stream are spread over the subscriber's
/// tasks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Grouping {
    /// Evenly: each producer task deals round-robin over the consumer tasks.
    Shuffle,
    /// By key: tuples with equal values in these fields always reach the
    /// same task (a stable hash, identical in every process).
    Fields(Vec<String>),
    /// Every task receives every tuple (broadcast).
    All,
    /// Task 0 receives everything.
    Global,
    /// The emitter names the task (`Emitter::emit_direct`).
    Direct,
    /// Shuffle over the consumer tasks in the producer's own process if
    /// there are any, else over all of them. In-process every task is
    /// local, so this is shuffle.
    LocalOrShuffle,
}

impl Grouping {
    /// Names accepted in topology files.
    pub const NAMES: &'static [&'static str] =
        &["shuffle", "fields", "all", "global", "direct", "local_or_shuffle"];

    /// The name used in topology files.
    pub fn name(&self) -> &'static str {
        match self {
            Grouping::Shuffle => "shuffle",
            Grouping::Fields(_) => "fields",
            Grouping::All => "all",
            Grouping::Global => "global",
            Grouping::Direct => "direct",
            Grouping::LocalOrShuffle => "local_or_shuffle",
        }
    }
}

impl fmt::Display for Grouping {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Grouping::Fields(fields) => write!(f, "fields({})", fields.join(", ")),
            other => f.write_str(other.name()),
        }
    }
}

/// What an input queue does when it is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OverflowPolicy {
    /// The producer waits (backpressure). Nothing is lost.
    #[default]
    Block,
    /// The oldest waiting tuple is dropped to make room: the consumer always
    /// sees the newest data. Drops are counted.
    DropOldest,
    /// The arriving tuple is dropped. Drops are counted.
    DropNewest,
}

impl OverflowPolicy {
    /// Names accepted in topology files.
    pub const NAMES: &'static [&'static str] = &["block", "drop_oldest", "drop_newest"];

    /// Parses a topology-file name.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "block" => Some(OverflowPolicy::Block),
            "drop_oldest" => Some(OverflowPolicy::DropOldest),
            "drop_newest" => Some(OverflowPolicy::DropNewest),
            _ => None,
        }
    }

    /// The topology-file name.
    pub fn name(self) -> &'static str {
        match self {
            OverflowPolicy::Block => "block",
            OverflowPolicy::DropOldest => "drop_oldest",
            OverflowPolicy::DropNewest => "drop_newest",
        }
    }
}
