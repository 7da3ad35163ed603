//! The transport boundary: where a routed tuple goes.
//!
//! Routing (groupings, anchors, metrics) is done by the emitter and knows
//! nothing about where a consumer task lives. A [`Target`] is one consumer
//! task's input for one subscription. In-process it is a bounded queue and
//! the tuple travels as an `Arc`; the cluster runtime adds a remote variant
//! that serializes with the stream's [`crate::MessageType`] codec and applies
//! the same overflow policy across the network.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::error::EmitError;
use crate::runtime::queue::{EdgeQueue, Push};
use crate::tuple::Tuple;

/// One consumer task's input for one subscription.
#[derive(Debug, Clone)]
pub(crate) enum Target {
    /// A task in this process.
    Local(Arc<EdgeQueue>),
    /// A task in another process of a cluster run.
    #[cfg(feature = "cluster")]
    Remote(Arc<crate::cluster::run::link::RemoteTarget>),
}

impl Target {
    /// Delivers `tuple`, waiting under `block` (the wait is added to
    /// `blocked`). A tuple dropped by policy or refused by an exited consumer
    /// fails its acking tree; only an abort is an error.
    #[cfg_attr(not(feature = "cluster"), allow(clippy::infallible_destructuring_match))]
    pub(crate) async fn deliver(
        &self,
        tuple: Tuple,
        aborting: &AtomicBool,
        blocked: &mut Duration,
    ) -> Result<(), EmitError> {
        let queue = match self {
            Target::Local(queue) => queue,
            #[cfg(feature = "cluster")]
            Target::Remote(remote) => {
                // Cluster runs refuse acking topologies that span
                // processes, so a remote tuple has no anchor.
                return match remote.deliver(tuple, blocked).await {
                    Err(_) if aborting.load(Ordering::Relaxed) => Err(EmitError::ShuttingDown),
                    other => other,
                };
            }
        };
        match queue.push(tuple, blocked).await {
            Push::Queued => Ok(()),
            Push::Dropped(victim) => {
                if let Some(a) = victim.anchor {
                    a.fail();
                }
                Ok(())
            }
            Push::Closed(refused) => {
                if let Some(a) = refused.anchor {
                    a.fail();
                }
                if aborting.load(Ordering::Relaxed) { Err(EmitError::ShuttingDown) } else { Ok(()) }
            }
        }
    }
}
