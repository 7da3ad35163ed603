//! Tuples between processes: one process's side of a run's links.
//!
//! A tuple for a task elsewhere is serialized with its stream's codec and
//! published to the key of the task's host. Each process has one
//! subscriber for its tuples; its callback never blocks (a slow consumer
//! must not stall the zenoh link that every edge shares), it hands each
//! tuple to a forwarder for the consumer's queue, which pushes it with the
//! queue's own overflow policy.
//!
//! A `block` edge is credit-based, as in Flink: a sending task holds as
//! many credits per remote consumer task as that input's queue bound, and
//! spends one per tuple; the receiver gives one back each time it has
//! queued one of the sender's tuples. A full queue therefore stops the
//! sender without stopping the link. Drop policies need no credits: the
//! receiving queue drops, and counts, as it does in process.
//!
//! For shutdown detection every process counts tuples sent to and
//! received from each other process; the coordinator adds them to the
//! queues' totals, leaving out processes that were lost.
//!
//! When a worker is lost its tasks move: a target looks its task's host up
//! at every send, and the pair's credits and incremental-codec records
//! start afresh (what was in flight to the lost process is gone).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::{Duration, Instant};

use tokio::sync::Semaphore;
use zenoh::Session;
use zenoh::Wait;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;

use crate::cluster::HostError;
use crate::cluster::run::layout::Layout;
use crate::cluster::wire::{DEFAULT_MAX_FRAME, EdgeTraffic, Frame, Rejections, WireError};
use crate::error::EmitError;
use crate::grouping::OverflowPolicy;
use crate::message::CodecState;
use crate::runtime::queue::EdgeQueue;
use crate::tuple::Tuple;

/// Traffic counters of one edge in this process.
#[derive(Debug, Default)]
struct EdgeCounters {
    messages: AtomicU64,
    frames: AtomicU64,
    bytes: AtomicU64,
    encode_ns: AtomicU64,
    decode_ns: AtomicU64,
    /// Tuples held for a task in another process and never sent: their
    /// producer task ended (failed, or the run aborted) first.
    undelivered: AtomicU64,
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// The key tuples for `host` are published on.
pub(crate) fn data_key(prefix: &str, host: u16) -> String {
    format!("{prefix}/data/{host}")
}

/// One sender-to-receiver pair on an edge: (edge, sending task, receiving task).
type Pair = (u32, u32, u32);

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// One process's side of a run's links.
pub(crate) struct Link {
    pub(crate) layout: Arc<Layout>,
    host: u16,
    /// A publisher per host, this one included (a task moved here may still
    /// be sent to through the link).
    publishers: Vec<Publisher<'static>>,
    credits: Mutex<HashMap<Pair, Arc<Semaphore>>>,
    /// Senders' records of incremental messages.
    sent_records: Mutex<HashMap<Pair, CodecState>>,
    /// Receivers' records of incremental messages.
    held: Mutex<HashMap<Pair, CodecState>>,
    traffic: Vec<EdgeCounters>,
    /// Tuples sent to each host.
    sent_to: Vec<AtomicU64>,
    /// Tuples received from each host (queued, dropped, or refused).
    received_from: Vec<AtomicU64>,
    pub(crate) rejections: Rejections,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link").field("host", &self.host).finish_non_exhaustive()
    }
}

impl Link {
    /// Publishers to every host of the run; `host_count` hosts in all.
    pub(crate) fn open(
        session: &Session,
        prefix: &str,
        layout: Arc<Layout>,
        host: u16,
        host_count: usize,
    ) -> Result<Self, HostError> {
        let mut publishers = Vec::with_capacity(host_count);
        for h in 0..host_count as u16 {
            let publisher = session
                .declare_publisher(data_key(prefix, h))
                .congestion_control(CongestionControl::Block)
                .wait()
                .map_err(|e| HostError::transport(format!("cannot publish to host {h}"), e))?;
            publishers.push(publisher);
        }
        let traffic = layout.edges.iter().map(|_| EdgeCounters::default()).collect();
        let counters = || (0..host_count).map(|_| AtomicU64::new(0)).collect();
        Ok(Link {
            layout,
            host,
            publishers,
            credits: Mutex::new(HashMap::new()),
            sent_records: Mutex::new(HashMap::new()),
            held: Mutex::new(HashMap::new()),
            traffic,
            sent_to: counters(),
            received_from: counters(),
            rejections: Rejections::default(),
        })
    }

    /// Waits, at most `limit`, until every host's subscription for its
    /// tuples has reached this process; how long that took. zenoh drops a
    /// put that no known subscriber matches, and another worker's
    /// subscription arrives only once the two workers have linked up (gossip
    /// tells them of each other after the coordinator connects to both):
    /// a tuple sent before that would be lost without a trace.
    pub(crate) fn wait_until_heard(&self, limit: Duration) -> Result<Duration, HostError> {
        let started = Instant::now();
        for (host, publisher) in self.publishers.iter().enumerate() {
            loop {
                let heard = publisher
                    .matching_status()
                    .wait()
                    .map_err(|e| HostError::Zenoh(e.to_string()))?
                    .matching();
                if heard {
                    break;
                }
                if started.elapsed() > limit {
                    return Err(HostError::Unheard { host: self.host, other: host, secs: limit.as_secs() });
                }
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        Ok(started.elapsed())
    }

    /// Tuples sent to and received from each host.
    pub(crate) fn counts(&self) -> (Vec<u64>, Vec<u64>) {
        let read = |v: &[AtomicU64]| v.iter().map(|c| c.load(Ordering::SeqCst)).collect();
        (read(&self.sent_to), read(&self.received_from))
    }

    /// The traffic this process sent (and decoded) per edge.
    pub(crate) fn traffic(&self) -> Vec<EdgeTraffic> {
        self.traffic
            .iter()
            .enumerate()
            .filter(|(_, t)| {
                let seen = [&t.messages, &t.decode_ns, &t.undelivered];
                seen.iter().any(|c| c.load(Ordering::Relaxed) > 0)
            })
            .map(|(edge, t)| EdgeTraffic {
                edge: edge as u32,
                messages: t.messages.load(Ordering::Relaxed),
                frames: t.frames.load(Ordering::Relaxed),
                bytes: t.bytes.load(Ordering::Relaxed),
                encode_ns: t.encode_ns.load(Ordering::Relaxed),
                decode_ns: t.decode_ns.load(Ordering::Relaxed),
                undelivered: t.undelivered.load(Ordering::Relaxed),
            })
            .collect()
    }

    /// The target for task `to` of `consumer`'s input `slot`, wherever it
    /// runs, as sent by task `from` of its producer.
    pub(crate) fn target(
        self: &Arc<Self>,
        consumer: usize,
        slot: usize,
        from: usize,
        to: usize,
    ) -> RemoteTarget {
        let edge = self.layout.edge_id(consumer, slot);
        let info = &self.layout.edges[edge as usize];
        let pair = (edge, from as u32, to as u32);
        let credits = (info.policy == OverflowPolicy::Block).then(|| {
            let credits = Arc::new(Semaphore::new(info.capacity));
            lock(&self.credits).insert(pair, credits.clone());
            credits
        });
        RemoteTarget { link: self.clone(), consumer, pair, credits }
    }

    /// Task t of component c has moved (its process was lost): the pairs
    /// that send to it start with full credits and empty records, and so
    /// do the records of what its old incarnation sent here.
    pub(crate) fn task_moved(&self, c: usize, t: usize) {
        let to_it =
            |&(edge, _, to): &Pair| self.layout.edges[edge as usize].consumer == c && to as usize == t;
        let from_it =
            |&(edge, from, _): &Pair| self.layout.edges[edge as usize].producer == c && from as usize == t;
        for (pair, credits) in lock(&self.credits).iter() {
            if to_it(pair) {
                let capacity = self.layout.edges[pair.0 as usize].capacity;
                credits.add_permits(capacity.saturating_sub(credits.available_permits()));
            }
        }
        lock(&self.sent_records).retain(|pair, _| !to_it(pair));
        lock(&self.held).retain(|pair, _| !from_it(pair));
    }

    /// Ends every wait for credits (the run is aborting).
    pub(crate) fn close(&self) {
        for c in lock(&self.credits).values() {
            c.close();
        }
    }

    async fn publish(&self, host: u16, bytes: Vec<u8>) -> Result<(), HostError> {
        let publisher = self.publishers.get(usize::from(host)).ok_or(HostError::NoSuchHost)?;
        publisher.put(bytes).await.map_err(|e| HostError::Zenoh(e.to_string()))
    }

    /// Handles a frame that arrived on this host's data key: a tuple goes
    /// to its queue's forwarder, a credit to its sender. Anything else is
    /// refused and counted.
    pub(crate) fn on_frame(&self, bytes: &[u8], inbound: &Inbound) {
        match Frame::decode(bytes, DEFAULT_MAX_FRAME) {
            Ok(Frame::Tuple { sender, edge, from, to, payload }) => {
                self.accept_all(sender, (edge, from, to), std::slice::from_ref(&payload), inbound);
            }
            Ok(Frame::Tuples { sender, edge, from, to, payloads }) => {
                self.accept_all(sender, (edge, from, to), &payloads, inbound);
            }
            Ok(Frame::Credit { edge, from, to, n }) => match lock(&self.credits).get(&(edge, from, to)) {
                Some(c) => c.add_permits(n as usize),
                None => self.rejections.count(&WireError::Malformed(format!(
                    "credit for an unknown edge {edge} ({from} → {to})"
                ))),
            },
            Ok(other) => {
                self.rejections
                    .count(&WireError::Malformed(format!("unexpected on the data key: {other:?}")));
            }
            Err(e) => self.rejections.count(&e),
        }
    }

    /// Decodes the tuples of a frame, in order, and hands those that
    /// decode to their queue's forwarder together. Each one refused is
    /// logged and counted, and counted as received (the sender counted it
    /// sent).
    fn accept_all(&self, sender: u16, pair: Pair, payloads: &[Vec<u8>], inbound: &Inbound) {
        let (edge, from, to) = pair;
        let received = self.received_from.get(usize::from(sender));
        let refuse = |why: WireError| {
            tracing::warn!("host {}: refused a tuple on edge {edge}: {why}", self.host);
            self.rejections.count(&why);
            if let Some(c) = received {
                c.fetch_add(1, Ordering::SeqCst);
            }
        };
        let refused = |why: &str| WireError::Malformed(why.to_string());
        let route = || {
            if received.is_none() {
                return Err(refused(&format!("from host {sender}, which is not in the run")));
            }
            let info = self.layout.edges.get(edge as usize).ok_or_else(|| refused("no such edge"))?;
            let source = *info.sources.get(from as usize).ok_or_else(|| refused("no such sending task"))?;
            let forward = inbound
                .forwarder(edge, to)
                .ok_or_else(|| refused(&format!("task {to} of the consumer is not on this host")))?;
            Ok((info, source, forward))
        };
        let (info, source, forward) = match route() {
            Ok(r) => r,
            Err(why) => {
                for _ in payloads {
                    refuse(why.clone());
                }
                return;
            }
        };
        let mut tuples = Vec::with_capacity(payloads.len());
        for payload in payloads {
            let started = Instant::now();
            let decoded = match info.message.incremental_codec() {
                None => info.message.decode(payload).map_err(|e| e.to_string()),
                Some(codec) => {
                    let mut held = lock(&self.held);
                    (codec.decode)(payload, held.entry(pair).or_insert_with(codec.new_held))
                        .map_err(|e| e.to_string())
                }
            };
            self.traffic[edge as usize].decode_ns.fetch_add(nanos(started.elapsed()), Ordering::Relaxed);
            match decoded {
                Ok(payload) => tuples.push(Tuple { source, payload, anchor: None }),
                Err(e) => refuse(refused(&format!("payload does not decode: {e}"))),
            }
        }
        if tuples.is_empty() {
            return;
        }
        if let Err(lost) = forward.send(Forwarded { tuples, sender, from }) {
            for _ in &lost.0.tuples {
                refuse(refused("the run is over"));
            }
        }
    }
}

/// A consumer task's input as one producer task sends to it through the
/// link: in another process, or moved here after a loss.
#[derive(Debug)]
pub(crate) struct RemoteTarget {
    link: Arc<Link>,
    consumer: usize,
    pair: Pair,
    /// Room at the receiver, on a block edge.
    credits: Option<Arc<Semaphore>>,
}

/// Most payload bytes gathered into one frame: a quarter of the frame
/// limit, so that a batch of large messages (maps) goes as several
/// frames; a single message past it goes alone.
const FRAME_BUDGET: usize = DEFAULT_MAX_FRAME / 4;

impl RemoteTarget {
    /// Sends a producer's batch, in order, as few frames as the frame
    /// budget and the edge's credits allow; on a `block` edge each frame
    /// first waits for as many credits as it carries tuples (the wait is
    /// added to `blocked`). Without `wait`, only what the credits at hand
    /// cover is sent and the rest stays in `tuples`.
    pub(crate) async fn deliver_batch(
        &self,
        tuples: &mut Vec<Tuple>,
        wait: bool,
        blocked: &mut Duration,
    ) -> Result<(), EmitError> {
        let link = &self.link;
        let (edge, from, to) = self.pair;
        let info = &link.layout.edges[edge as usize];
        let counters = &link.traffic[edge as usize];
        while !tuples.is_empty() {
            // A frame never needs more credits than the edge has, nor,
            // when it may not wait, more than there are now.
            let most = match &self.credits {
                None => usize::MAX,
                Some(_) if wait => info.capacity.max(1),
                Some(credits) => credits.available_permits(),
            };
            if most == 0 {
                return Ok(());
            }
            let started = Instant::now();
            let (mut payloads, mut bytes) = (Vec::new(), 0usize);
            for tuple in tuples.iter() {
                if payloads.len() == most || bytes >= FRAME_BUDGET {
                    break;
                }
                let payload = match info.message.incremental_codec() {
                    None => info.message.encode(&*tuple.payload).map_err(|e| e.to_string()),
                    Some(codec) => {
                        let mut records = lock(&link.sent_records);
                        (codec.encode)(
                            &*tuple.payload,
                            records.entry(self.pair).or_insert_with(codec.new_sent),
                        )
                        .map_err(|e| e.to_string())
                    }
                }
                .map_err(EmitError::Transport)?;
                bytes += payload.len();
                payloads.push(payload);
            }
            let n = payloads.len();
            let frame = if n == 1 {
                let payload = payloads.pop().expect("one");
                Frame::Tuple { sender: link.host, edge, from, to, payload }.encode()
            } else {
                Frame::Tuples { sender: link.host, edge, from, to, payloads }.encode()
            };
            counters.encode_ns.fetch_add(nanos(started.elapsed()), Ordering::Relaxed);
            if let Some(credits) = &self.credits {
                let waited = Instant::now();
                credits.acquire_many(n as u32).await.map_err(|_| EmitError::ShuttingDown)?.forget();
                *blocked += waited.elapsed();
            }
            tuples.drain(..n);
            counters.messages.fetch_add(n as u64, Ordering::Relaxed);
            counters.frames.fetch_add(1, Ordering::Relaxed);
            counters.bytes.fetch_add(frame.len() as u64, Ordering::Relaxed);
            let host = link.layout.host(self.consumer, to as usize);
            // Counted before they can arrive, so no look at the totals
            // sees them received but not sent.
            link.sent_to[usize::from(host)].fetch_add(n as u64, Ordering::SeqCst);
            link.publish(host, frame).await.map_err(|e| EmitError::Transport(e.to_string()))?;
        }
        Ok(())
    }

    /// Counts `n` tuples held for this target that will never be sent
    /// (their producer task ended first) as undelivered on the edge.
    pub(crate) fn abandon(&self, n: usize) {
        let (edge, _, _) = self.pair;
        self.link.traffic[edge as usize].undelivered.fetch_add(n as u64, Ordering::Relaxed);
    }

    /// Sends `tuple`, first waiting for a credit on a block edge (the wait
    /// is added to `blocked`).
    pub(crate) async fn deliver(&self, tuple: Tuple, blocked: &mut Duration) -> Result<(), EmitError> {
        let link = &self.link;
        let (edge, from, to) = self.pair;
        let info = &link.layout.edges[edge as usize];
        let counters = &link.traffic[edge as usize];
        let started = Instant::now();
        let payload = match info.message.incremental_codec() {
            None => info.message.encode(&*tuple.payload).map_err(|e| e.to_string()),
            Some(codec) => {
                let mut records = lock(&link.sent_records);
                (codec.encode)(&*tuple.payload, records.entry(self.pair).or_insert_with(codec.new_sent))
                    .map_err(|e| e.to_string())
            }
        }
        .map_err(EmitError::Transport)?;
        let frame = Frame::Tuple { sender: link.host, edge, from, to, payload }.encode();
        counters.encode_ns.fetch_add(nanos(started.elapsed()), Ordering::Relaxed);
        if let Some(credits) = &self.credits {
            let waited = Instant::now();
            credits.acquire().await.map_err(|_| EmitError::ShuttingDown)?.forget();
            *blocked += waited.elapsed();
        }
        counters.messages.fetch_add(1, Ordering::Relaxed);
        counters.frames.fetch_add(1, Ordering::Relaxed);
        counters.bytes.fetch_add(frame.len() as u64, Ordering::Relaxed);
        let host = link.layout.host(self.consumer, to as usize);
        // Counted before it can arrive, so no look at the totals sees it
        // received but not sent.
        link.sent_to[usize::from(host)].fetch_add(1, Ordering::SeqCst);
        link.publish(host, frame).await.map_err(|e| EmitError::Transport(e.to_string()))
    }
}

/// Tuples of one frame on their way to their queue: the host and task
/// that sent them.
struct Forwarded {
    tuples: Vec<Tuple>,
    sender: u16,
    from: u32,
}

/// Where this host's incoming tuples go: a forwarder per local queue.
#[derive(Default)]
pub(crate) struct Inbound {
    forwarders: RwLock<HashMap<(u32, u32), tokio::sync::mpsc::UnboundedSender<Forwarded>>>,
}

impl std::fmt::Debug for Inbound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Inbound").finish_non_exhaustive()
    }
}

impl Inbound {
    fn forwarder(&self, edge: u32, to: u32) -> Option<tokio::sync::mpsc::UnboundedSender<Forwarded>> {
        self.forwarders.read().unwrap_or_else(|e| e.into_inner()).get(&(edge, to)).cloned()
    }

    /// Forwarders, on `runtime`, for every input of task t of component c
    /// (a task of this host). `queue(slot)` is the queue of its input.
    pub(crate) fn serve_task(
        &self,
        link: &Arc<Link>,
        runtime: &tokio::runtime::Handle,
        c: usize,
        t: usize,
        queue: &dyn Fn(usize) -> Arc<EdgeQueue>,
    ) {
        let layout = &link.layout;
        let mut forwarders = self.forwarders.write().unwrap_or_else(|e| e.into_inner());
        for (edge, info) in layout.edges.iter().enumerate().filter(|(_, i)| i.consumer == c) {
            let (send, mut receive) = tokio::sync::mpsc::unbounded_channel::<Forwarded>();
            let target = queue(info.slot);
            let link = link.clone();
            let (edge, to, block) = (edge as u32, t as u32, info.policy == OverflowPolicy::Block);
            runtime.spawn(async move {
                while let Some(Forwarded { mut tuples, sender, from }) = receive.recv().await {
                    let (n, mut blocked, mut failed) = (tuples.len(), Duration::ZERO, Vec::new());
                    // Tuples from another process carry no anchors, so
                    // nothing dropped has a tree to fail.
                    let closed = target.push_batch(&mut tuples, true, &mut blocked, &mut failed).await;
                    link.received_from[usize::from(sender)].fetch_add(n as u64, Ordering::SeqCst);
                    if block && !closed {
                        let credit = Frame::Credit { edge, from, to, n: n as u32 }.encode();
                        if let Err(e) = link.publish(sender, credit).await {
                            tracing::warn!("cannot return a credit to host {sender}: {e}");
                        }
                    }
                }
            });
            forwarders.insert((edge, to), send);
        }
    }
}
