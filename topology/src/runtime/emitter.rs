//! The handle through which a component emits, sends to peers, fails its
//! input and records its own metrics.
//!
//! Routing happens here, on the emitting task's thread: the grouping picks
//! the consumer task(s) and the tuple goes into this producer's batch for
//! that task, handed over to the task's bounded queue as a whole (or at
//! once, on an edge with batching off; see [`crate::spec::BatchSpec`] and
//! decision 0032). This is the transport boundary: a task in another
//! process is another kind of target behind the same calls.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crate::error::EmitError;
use crate::message::{Message, MessageType, Payload};
use crate::metrics::TaskStats;
use crate::runtime::acker::{AckTracker, Anchor, Replay};
use crate::runtime::control::Control;
use crate::runtime::target::Target;
use crate::spec::BatchSpec;
use crate::tuple::{Source, Tuple};

/// How one subscription picks consumer tasks.
#[derive(Debug, Clone)]
pub(crate) enum Route {
    RoundRobin,
    Fields(Vec<&'static str>),
    All,
    Global,
    Direct,
}

/// One subscriber of a stream: its tasks' queues for this edge, and what
/// this producer holds for each of them.
#[derive(Debug)]
pub(crate) struct Subscription {
    pub(crate) route: Route,
    pub(crate) targets: Vec<Target>,
    pub(crate) next: usize,
    pub(crate) batch: BatchSpec,
    /// Per target: emits not yet handed over (empty when batching is off).
    pub(crate) held: Vec<Held>,
}

impl Subscription {
    pub(crate) fn new(route: Route, targets: Vec<Target>, next: usize, batch: BatchSpec) -> Self {
        let held = targets.iter().map(|_| Held::default()).collect();
        Subscription { route, targets, next, batch, held }
    }

    /// The consumer tasks a payload goes to (`direct`: the task an
    /// `emit_direct` names).
    fn pick(
        &mut self,
        message: MessageType,
        payload: &(dyn std::any::Any + Send + Sync),
        direct: Option<usize>,
    ) -> Result<std::ops::Range<usize>, EmitError> {
        let n = self.targets.len();
        Ok(match &self.route {
            Route::RoundRobin => {
                let i = self.next;
                self.next = if i + 1 == n { 0 } else { i + 1 };
                i..i + 1
            }
            Route::Fields(fields) => {
                let i = (message.hash_fields(payload, fields)? % n as u64) as usize;
                i..i + 1
            }
            Route::Global => 0..1,
            Route::Direct => {
                let task = direct.expect("a direct subscription has its task");
                if task >= n {
                    return Err(EmitError::NoSuchTask { task, count: n });
                }
                task..task + 1
            }
            Route::All => 0..n,
        })
    }

    /// Holds `tuple` for target `i` (its batch starts waiting at `now`);
    /// returns whether the batch reached its bound.
    fn hold(&mut self, i: usize, tuple: Tuple, now: Instant) -> bool {
        let held = &mut self.held[i];
        if held.tuples.is_empty() {
            held.since = now;
        }
        held.tuples.push(tuple);
        held.tuples.len() >= self.batch.max
    }
}

/// Tuples a producer holds for one consumer task, and since when.
#[derive(Debug)]
pub(crate) struct Held {
    tuples: Vec<Tuple>,
    since: Instant,
}

impl Default for Held {
    fn default() -> Self {
        Held { tuples: Vec::new(), since: Instant::now() }
    }
}

/// A declared output stream and its subscribers.
#[derive(Debug)]
pub(crate) struct StreamRoute {
    pub(crate) name: Arc<str>,
    pub(crate) message: MessageType,
    pub(crate) source: &'static Source,
    pub(crate) subscriptions: Vec<Subscription>,
    /// Whether any subscription is `direct` (emits must then name a task).
    pub(crate) has_direct: bool,
    /// Whether every subscription batches its emits (and there is one).
    pub(crate) held_only: bool,
}

/// Queues of the sibling tasks for peer exchange.
#[derive(Debug)]
pub(crate) struct PeerRoute {
    pub(crate) message: MessageType,
    pub(crate) source: &'static Source,
    pub(crate) targets: Vec<Target>,
}

/// Root creation for a spout with acking.
#[derive(Debug)]
pub(crate) struct SpoutAcking {
    pub(crate) tracker: Arc<AckTracker>,
    pub(crate) timeout: Duration,
}

/// Emits tuples on a component's declared streams.
#[derive(Debug)]
pub struct Emitter {
    pub(crate) streams: Vec<StreamRoute>,
    pub(crate) peers: Option<PeerRoute>,
    pub(crate) acking: Option<SpoutAcking>,
    /// The anchor of the tuple being executed.
    pub(crate) anchor: Option<Box<Anchor>>,
    pub(crate) input_failed: bool,
    pub(crate) stats: TaskStats,
    pub(crate) aborting: Arc<AtomicBool>,
    /// Set by [`Emitter::hold_inputs`].
    pub(crate) holding: bool,
    /// A bolt task's control, told when an emit stops waiting for queue
    /// space (the stall watchdog does not count that wait).
    pub(crate) watch: Option<Arc<Control>>,
    /// The task's time as of the batch (or `next` call) being executed:
    /// when a held tuple started waiting, without a clock read per emit.
    pub(crate) clock: Instant,
    /// Tuples held in batches, over every target.
    held: usize,
    /// `held` as the coordinator reads it: published at the end of every
    /// flush that found tuples held, so equal to `held` after any flush.
    /// A task flushes before it releases its input, ends a tick, reports
    /// `finish` or waits, so no look at the run sees it quiescent while a
    /// tuple is held.
    pub(crate) held_now: Arc<AtomicU64>,
    task: usize,
}

impl Emitter {
    pub(crate) fn new(
        task: usize,
        streams: Vec<StreamRoute>,
        peers: Option<PeerRoute>,
        acking: Option<SpoutAcking>,
        aborting: Arc<AtomicBool>,
    ) -> Self {
        Emitter {
            streams,
            peers,
            acking,
            anchor: None,
            input_failed: false,
            stats: TaskStats::default(),
            aborting,
            holding: false,
            watch: None,
            clock: Instant::now(),
            held: 0,
            held_now: Arc::new(AtomicU64::new(0)),
            task,
        }
    }

    /// Whether anything subscribes to `stream`: a component can leave
    /// unbuilt what nobody would receive (a view's extra output).
    pub fn is_subscribed(&self, stream: &str) -> bool {
        self.streams.iter().any(|s| &*s.name == stream && !s.subscriptions.is_empty())
    }

    /// Emits `value` on `stream`.
    pub async fn emit<T: Message>(&mut self, stream: &str, value: T) -> Result<(), EmitError> {
        self.emit_shared(stream, Arc::new(value)).await
    }

    /// Emits an already shared value (forwarding without a copy).
    pub async fn emit_shared<T: Message>(&mut self, stream: &str, value: Arc<T>) -> Result<(), EmitError> {
        let index = self.stream_index::<T>(stream)?;
        if self.acking.is_none() && self.streams[index].held_only {
            // The common case, without building the general path's
            // futures: into the batches, awaiting only a full one.
            self.stats.emitted += 1;
            let full = self.hold(index, value, None, None)?;
            return if full { Box::pin(self.flush(None)).await } else { Ok(()) };
        }
        self.emit_payload(index, value, None, None).await
    }

    /// Emits `value` on `stream`; `direct` subscribers receive it at `task`,
    /// others by their own grouping.
    pub async fn emit_direct<T: Message>(
        &mut self,
        stream: &str,
        task: usize,
        value: T,
    ) -> Result<(), EmitError> {
        let index = self.stream_index::<T>(stream)?;
        self.emit_payload(index, Arc::new(value), Some(task), None).await
    }

    /// Holds back this bolt's inputs (`true`) or lets them through again
    /// (`false`). While held, the task takes tuples only from its
    /// feedback edges and its peer queue; the other inputs wait in their
    /// bounded queues, so their producers block once those are full: a
    /// bolt waiting on feedback holds back its sources without losing or
    /// buffering anything. Takes effect from the next tuple.
    pub fn hold_inputs(&mut self, hold: bool) {
        self.holding = hold;
    }

    /// Sends `value` to sibling task `task` of this component (peer
    /// exchange; the type is the one declared with `Declarer::peer`).
    pub async fn send_peer<T: Message>(&mut self, task: usize, value: T) -> Result<(), EmitError> {
        let peers = self.peers.as_ref().ok_or(EmitError::NoPeerStream)?;
        if !peers.message.is::<T>() {
            return Err(EmitError::WrongType {
                stream: "<peer>".to_string(),
                expected: peers.message.name(),
                actual: std::any::type_name::<T>(),
            });
        }
        let count = peers.targets.len();
        let queue = peers.targets.get(task).ok_or(EmitError::NoSuchTask { task, count })?.clone();
        let source = peers.source;
        let payload: Payload = Arc::new(value);
        let anchor = self.anchor.as_ref().map(|a| Box::new(a.child()));
        self.stats.emitted += 1;
        let blocked = self.stats.blocked;
        let delivered =
            queue.deliver(Tuple { source, payload, anchor }, &self.aborting, &mut self.stats.blocked).await;
        waited(self.watch.as_deref(), blocked, self.stats.blocked);
        delivered
    }

    /// Marks the tuple being executed as failed: its spout (if it acks)
    /// replays it.
    pub fn fail(&mut self) {
        self.input_failed = true;
    }

    /// Adds `delta` to the component's counter `name` (reported in
    /// metrics.json).
    pub fn count(&mut self, name: &str, delta: u64) {
        self.stats.count(name, delta);
    }

    /// Records `value` in the component's value metric `name` (reported as
    /// count, mean, p50, p99, max).
    pub fn record(&mut self, name: &str, value: u64) {
        self.stats.record(name, value);
    }

    /// Sets the component's gauge `name` to `value`: a level such as the
    /// bytes of map this task holds (metrics.json and the live views show
    /// the last value, summed over the component's tasks).
    pub fn gauge(&mut self, name: &str, value: u64) {
        self.stats.gauge(name, value);
    }

    /// Sets the component's measured quantity `name` to `value`: a
    /// calibration or a choice made from the data (the laser's clock
    /// offset, in the unit the name says), reported as a number.
    pub fn measured(&mut self, name: &str, value: f64) {
        self.stats.measured(name, value);
    }

    /// This task's index.
    pub fn task_index(&self) -> usize {
        self.task
    }

    /// Emit calls so far.
    pub fn emitted(&self) -> u64 {
        self.stats.emitted
    }

    fn stream_index<T: 'static>(&self, stream: &str) -> Result<usize, EmitError> {
        let index = self
            .streams
            .iter()
            .position(|s| &*s.name == stream)
            .ok_or_else(|| EmitError::UnknownStream(stream.to_string()))?;
        let declared = self.streams[index].message;
        if declared.is::<T>() {
            Ok(index)
        } else {
            Err(EmitError::WrongType {
                stream: stream.to_string(),
                expected: declared.name(),
                actual: std::any::type_name::<T>(),
            })
        }
    }

    /// Routes one payload to every subscriber of stream `index`. A spout
    /// with acking makes it a root (`replay` gives the id and attempt).
    pub(crate) async fn emit_payload(
        &mut self,
        index: usize,
        payload: Payload,
        direct: Option<usize>,
        replay: Option<(u64, u32)>,
    ) -> Result<(), EmitError> {
        let root = self.acking.as_ref().map(|a| {
            let (seq, attempt) = replay.unwrap_or((self.stats.emitted, 0));
            a.tracker.begin(seq, attempt, index, payload.clone(), Instant::now() + a.timeout)
        });
        if replay.is_none() {
            self.stats.emitted += 1;
        }
        let result = self.route(index, payload, direct, root.as_ref()).await;
        if let Some(root) = root {
            match result {
                Ok(()) => root.complete(),
                Err(_) => root.fail(),
            }
        }
        result
    }

    async fn route(
        &mut self,
        index: usize,
        payload: Payload,
        direct: Option<usize>,
        root: Option<&Anchor>,
    ) -> Result<(), EmitError> {
        if self.streams[index].held_only {
            // Every subscriber batched: routing is plain code, and only a
            // full batch awaits (boxed: a large future kept off the
            // per-emit path).
            let full = self.hold(index, payload, direct, root)?;
            return if full { Box::pin(self.flush(None)).await } else { Ok(()) };
        }
        let stream = &mut self.streams[index];
        let parent = root.or(self.anchor.as_deref());
        if direct.is_none() && stream.has_direct {
            return Err(EmitError::DirectNeedsTask(stream.name.to_string()));
        }
        let mut payload = Some(payload);
        // Whether a batch reached its bound.
        let mut full = false;
        let subscriptions = stream.subscriptions.len();
        for (k, sub) in stream.subscriptions.iter_mut().enumerate() {
            let shared = payload.as_ref().expect("present until the last delivery");
            let targets = sub.pick(stream.message, &**shared, direct)?;
            let last = targets.end - 1;
            for i in targets {
                let tuple =
                    delivery(stream.source, &mut payload, k + 1 == subscriptions && i == last, parent);
                if sub.batch.is_off() {
                    let blocked = self.stats.blocked;
                    let delivered =
                        sub.targets[i].deliver(tuple, &self.aborting, &mut self.stats.blocked).await;
                    waited(self.watch.as_deref(), blocked, self.stats.blocked);
                    delivered?;
                    continue;
                }
                full |= sub.hold(i, tuple, self.clock);
                self.held += 1;
            }
        }
        if full { self.flush(None).await } else { Ok(()) }
    }

    /// Routes a payload into the batches of a stream whose subscribers
    /// all batch; returns whether a batch reached its bound.
    fn hold(
        &mut self,
        index: usize,
        payload: Payload,
        direct: Option<usize>,
        root: Option<&Anchor>,
    ) -> Result<bool, EmitError> {
        let stream = &mut self.streams[index];
        let parent = root.or(self.anchor.as_deref());
        if direct.is_none() && stream.has_direct {
            return Err(EmitError::DirectNeedsTask(stream.name.to_string()));
        }
        let mut payload = Some(payload);
        let mut full = false;
        let subscriptions = stream.subscriptions.len();
        for (k, sub) in stream.subscriptions.iter_mut().enumerate() {
            let shared = payload.as_ref().expect("present until the last delivery");
            let targets = sub.pick(stream.message, &**shared, direct)?;
            let last = targets.end - 1;
            for i in targets {
                let tuple =
                    delivery(stream.source, &mut payload, k + 1 == subscriptions && i == last, parent);
                full |= sub.hold(i, tuple, self.clock);
                self.held += 1;
            }
        }
        Ok(full)
    }

    /// Hands over held tuples: every one (`due` = `None`), or those that
    /// have waited their edge's linger by `due`. A first pass hands each
    /// target what its queue has room for without waiting; a second waits
    /// for room, target by target. So a producer never waits on one full
    /// queue while holding tuples another could take, as it would not
    /// unbatched.
    pub(crate) async fn flush(&mut self, due: Option<Instant>) -> Result<(), EmitError> {
        if self.held == 0 {
            return Ok(());
        }
        for wait in [false, true] {
            if self.held == 0 {
                break;
            }
            for stream in &mut self.streams {
                for sub in &mut stream.subscriptions {
                    let linger = sub.batch.linger;
                    for (target, held) in sub.targets.iter().zip(&mut sub.held) {
                        if held.tuples.is_empty() || due.is_some_and(|now| now < held.since + linger) {
                            continue;
                        }
                        let before = held.tuples.len();
                        let blocked = self.stats.blocked;
                        let delivered = target
                            .deliver_batch(&mut held.tuples, wait, &self.aborting, &mut self.stats.blocked)
                            .await;
                        waited(self.watch.as_deref(), blocked, self.stats.blocked);
                        self.held -= before - held.tuples.len();
                        delivered?;
                    }
                }
            }
        }
        self.publish_held();
        Ok(())
    }

    /// Whether any tuple is held in a batch.
    pub(crate) fn holds_tuples(&self) -> bool {
        self.held > 0
    }

    /// Publishes how many tuples are held, for the coordinator's look at
    /// the run.
    fn publish_held(&self) {
        self.held_now.store(self.held as u64, Ordering::SeqCst);
    }

    /// Gives up the held tuples of a task that ends without handing them
    /// over (an abort, a failure): each counts as undelivered at its
    /// target, its acking tree failed.
    pub(crate) fn abandon_held(&mut self) {
        for stream in &mut self.streams {
            for sub in &mut stream.subscriptions {
                for (target, held) in sub.targets.iter().zip(&mut sub.held) {
                    target.abandon(&mut held.tuples);
                }
            }
        }
        self.held = 0;
        self.publish_held();
    }

    /// Replays a failed root.
    pub(crate) async fn replay(&mut self, r: Replay) -> Result<(), EmitError> {
        self.emit_payload(r.stream, r.payload, None, Some((r.seq, r.attempt + 1))).await
    }
}

/// The tuple of one delivery of `payload`: the payload is moved into the
/// `last` delivery rather than cloned and then dropped (one reference-count
/// round trip less per tuple); each carries a child of `parent`.
fn delivery(
    source: &'static Source,
    payload: &mut Option<Payload>,
    last: bool,
    parent: Option<&Anchor>,
) -> Tuple {
    let payload = if last {
        payload.take().expect("taken once")
    } else {
        payload.as_ref().expect("present until the last delivery").clone()
    };
    Tuple { source, payload, anchor: parent.map(|a| Box::new(a.child())) }
}

/// After a delivery: if it waited for queue space (the blocked time grew
/// from `before` to `after`), the call it was made in (if any) progressed
/// now.
fn waited(watch: Option<&Control>, before: Duration, after: Duration) {
    if after != before
        && let Some(watch) = watch
    {
        watch.wait_ended(Instant::now());
    }
}
