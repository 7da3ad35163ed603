//! The unit a bolt receives.

use std::collections::HashSet;
use std::sync::{Arc, Mutex, OnceLock};

use crate::message::Payload;
use crate::runtime::acker::Anchor;

/// Where a tuple came from.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Source {
    /// A subscribed stream of another component.
    Stream {
        /// The producing component.
        component: Arc<str>,
        /// The stream's name.
        stream: Arc<str>,
        /// The producing task's index.
        task: usize,
    },
    /// A peer task of the same component.
    Peer {
        /// The sending task's index.
        task: usize,
    },
}

/// A message delivered to a bolt, with where it came from.
#[derive(Debug)]
pub struct Tuple {
    pub(crate) source: &'static Source,
    pub(crate) payload: Payload,
    /// Boxed: only spouts with acking have anchors, and a small tuple moves
    /// faster through the queues.
    pub(crate) anchor: Option<Box<Anchor>>,
}

impl Tuple {
    /// The message as `T`, if it is one.
    pub fn get<T: 'static>(&self) -> Option<&T> {
        self.payload.downcast_ref::<T>()
    }

    /// Whether the message is a `T`.
    pub fn is<T: 'static>(&self) -> bool {
        self.payload.is::<T>()
    }

    /// Gives up a tuple that will not be executed (dropped, refused,
    /// discarded): its acking tree, if it has one, fails.
    pub(crate) fn lost(self) {
        if let Some(a) = self.anchor {
            a.fail();
        }
    }

    /// The message as a shared `T` (to forward it without copying), or the
    /// tuple back if it is not a `T`.
    pub fn into_arc<T: Send + Sync + 'static>(self) -> Result<Arc<T>, Tuple> {
        let Tuple { source, payload, anchor } = self;
        payload.downcast::<T>().map_err(|payload| Tuple { source, payload, anchor })
    }

    /// The shared, type-erased message.
    pub fn payload(&self) -> &Payload {
        &self.payload
    }

    /// Where the tuple came from.
    pub fn source(&self) -> &Source {
        self.source
    }

    /// The producing component's name (`None` for peer messages).
    pub fn source_component(&self) -> Option<&str> {
        match self.source {
            Source::Stream { component, .. } => Some(&**component),
            Source::Peer { .. } => None,
        }
    }

    /// The stream's name (`None` for peer messages).
    pub fn stream(&self) -> Option<&str> {
        match self.source {
            Source::Stream { stream, .. } => Some(&**stream),
            Source::Peer { .. } => None,
        }
    }

    /// The index of the task that sent it.
    pub fn source_task(&self) -> usize {
        match self.source {
            Source::Stream { task, .. } | Source::Peer { task } => *task,
        }
    }
}

impl Source {
    /// The process-wide copy of this source. Tuples refer to their source by
    /// a plain reference, so no reference count shared by two cores is
    /// touched per tuple. Distinct sources are few (components × streams ×
    /// tasks, by name) and repeated runs reuse them, so the table stays small.
    pub(crate) fn interned(self) -> &'static Source {
        static TABLE: OnceLock<Mutex<HashSet<&'static Source>>> = OnceLock::new();
        let mut table = TABLE.get_or_init(Default::default).lock().unwrap_or_else(|e| e.into_inner());
        if let Some(existing) = table.get(&self) {
            return existing;
        }
        let leaked: &'static Source = Box::leak(Box::new(self));
        table.insert(leaked);
        leaked
    }
}
