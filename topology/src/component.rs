//! The two component traits.
//!
//! Both are small on purpose: declare what you produce, then react. Each task
//! of a component is one instance driven by one thread, so methods take
//! `&mut self` and need no locking; CPU-heavy work inside them never blocks
//! another task.

use std::future::Future;

use crate::context::TaskContext;
use crate::declare::Declarer;
use crate::error::BoxError;
use crate::runtime::emitter::Emitter;
use crate::tuple::Tuple;

/// What a spout's `next` reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpoutStatus {
    /// Call `next` again.
    Continue,
    /// The source is exhausted; the run ends once everything emitted is
    /// processed.
    Done,
}

/// Identifies a tuple a spout emitted with acking enabled: the n-th emit of
/// the task is `MessageId(n)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MessageId(pub u64);

/// A source of messages.
pub trait Spout: Send + 'static {
    /// Declares the output streams.
    fn declare(&self, declarer: &mut Declarer);

    /// Called once on the task's thread before the first `next`.
    fn open(&mut self, ctx: &TaskContext) -> impl Future<Output = Result<(), BoxError>> {
        let _ = ctx;
        async { Ok(()) }
    }

    /// Emits zero or more messages. Emits wait while a `block` queue
    /// downstream is full, which is how backpressure slows a spout.
    fn next(&mut self, out: &mut Emitter) -> impl Future<Output = Result<SpoutStatus, BoxError>>;

    /// With acking on: the tuple tree of `id` was fully processed.
    fn ack(&mut self, id: MessageId) {
        let _ = id;
    }

    /// With acking on: the tuple tree of `id` failed or timed out; the engine
    /// replays it (up to the retry limit) after this call.
    fn fail(&mut self, id: MessageId) {
        let _ = id;
    }

    /// Called once when the run shuts down.
    fn close(&mut self) -> impl Future<Output = Result<(), BoxError>> {
        async { Ok(()) }
    }
}

/// A processing step.
pub trait Bolt: Send + 'static {
    /// Declares the output streams, accepted inputs, peer type and tick.
    fn declare(&self, declarer: &mut Declarer);

    /// Called once on the task's thread before the first tuple.
    fn prepare(&mut self, ctx: &TaskContext) -> impl Future<Output = Result<(), BoxError>> {
        let _ = ctx;
        async { Ok(()) }
    }

    /// Processes one tuple. Emits are anchored to it when its spout acks.
    /// An `Err` is fatal for the task (see the component's restart policy);
    /// to fail just this tuple, call [`Emitter::fail`].
    fn execute(&mut self, input: Tuple, out: &mut Emitter) -> impl Future<Output = Result<(), BoxError>>;

    /// Called at the declared tick period.
    fn tick(&mut self, out: &mut Emitter) -> impl Future<Output = Result<(), BoxError>> {
        let _ = out;
        async { Ok(()) }
    }

    /// Called once after every upstream component has finished and this
    /// task's queues are drained; emits here still reach downstream.
    fn finish(&mut self, out: &mut Emitter) -> impl Future<Output = Result<(), BoxError>> {
        let _ = out;
        async { Ok(()) }
    }
}
