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
    /// Delivers a producer's batch, front first (see
    /// [`EdgeQueue::push_batch`]): without `wait`, what a full `block`
    /// queue cannot take stays in `tuples`. Tuples dropped by policy or
    /// refused by an exited consumer fail their acking trees; only an
    /// abort is an error.
    #[cfg_attr(not(feature = "cluster"), allow(clippy::infallible_destructuring_match))]
    pub(crate) async fn deliver_batch(
        &self,
        tuples: &mut Vec<Tuple>,
        wait: bool,
        aborting: &AtomicBool,
        blocked: &mut Duration,
    ) -> Result<(), EmitError> {
        let queue = match self {
            Target::Local(queue) => queue,
            #[cfg(feature = "cluster")]
            Target::Remote(remote) => {
                // As few frames as the batch fits in, each under its
                // credits.
                return shutting_down_if(
                    aborting,
                    Box::pin(remote.deliver_batch(tuples, wait, blocked)).await,
                );
            }
        };
        let mut failed = Vec::new();
        let closed = queue.push_batch(tuples, wait, blocked, &mut failed).await;
        failed.into_iter().for_each(Tuple::lost);
        if closed && aborting.load(Ordering::Relaxed) { Err(EmitError::ShuttingDown) } else { Ok(()) }
    }

    /// Counts tuples that can no longer be delivered (a producer's batch
    /// when its task ends without a shutdown) as undelivered at this
    /// target, and fails their acking trees.
    pub(crate) fn abandon(&self, tuples: &mut Vec<Tuple>) {
        match self {
            Target::Local(queue) => {
                queue.counters.undelivered.fetch_add(tuples.len() as u64, Ordering::Relaxed);
            }
            // The receiving process never saw them: the edge counts them
            // here, and the run's report adds them to the consumer's.
            #[cfg(feature = "cluster")]
            Target::Remote(remote) => remote.abandon(tuples.len()),
        }
        tuples.drain(..).for_each(Tuple::lost);
    }

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
                return shutting_down_if(aborting, remote.deliver(tuple, blocked).await);
            }
        };
        match queue.push(tuple, blocked).await {
            Push::Queued => Ok(()),
            Push::Dropped(victim) => {
                victim.lost();
                Ok(())
            }
            Push::Closed(refused) => {
                refused.lost();
                if aborting.load(Ordering::Relaxed) { Err(EmitError::ShuttingDown) } else { Ok(()) }
            }
        }
    }
}

/// A failed send to another process is the run shutting down when it is
/// aborting (the link closed under it), else the error itself.
#[cfg(feature = "cluster")]
fn shutting_down_if(aborting: &AtomicBool, result: Result<(), EmitError>) -> Result<(), EmitError> {
    match result {
        Err(_) if aborting.load(Ordering::Relaxed) => Err(EmitError::ShuttingDown),
        other => other,
    }
}
