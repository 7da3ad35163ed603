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
//! For shutdown detection every process counts tuples sent and tuples
//! received (queued, dropped or refused by an exited consumer); the
//! coordinator adds them to the queues' totals.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::Semaphore;
use zenoh::Session;
use zenoh::Wait;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;

use crate::cluster::run::layout::Layout;
use crate::cluster::wire::{DEFAULT_MAX_FRAME, EdgeTraffic, Frame, Rejections};
use crate::error::EmitError;
use crate::grouping::OverflowPolicy;
use crate::message::CodecState;
use crate::runtime::local::queue::{EdgeQueue, Push};
use crate::tuple::Tuple;

/// Traffic counters of one edge in this process.
#[derive(Debug, Default)]
struct EdgeCounters {
    messages: AtomicU64,
    bytes: AtomicU64,
    encode_ns: AtomicU64,
    decode_ns: AtomicU64,
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// The key tuples for `host` are published on.
pub(crate) fn data_key(prefix: &str, host: u16) -> String {
    format!("{prefix}/data/{host}")
}

/// One process's side of a run's links.
pub(crate) struct Link {
    layout: Arc<Layout>,
    host: u16,
    /// A publisher per host (`None` for this one).
    publishers: Vec<Option<Publisher<'static>>>,
    /// Credits of block edges, by (edge, sending task, receiving task).
    credits: Mutex<HashMap<(u32, u32, u32), Arc<Semaphore>>>,
    traffic: Vec<EdgeCounters>,
    sent: AtomicU64,
    received: AtomicU64,
    /// Receivers' records of incremental messages, by (edge, sending
    /// task, receiving task).
    held: Mutex<HashMap<(u32, u32, u32), CodecState>>,
    pub(crate) rejections: Rejections,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link").field("host", &self.host).finish_non_exhaustive()
    }
}

impl Link {
    /// Publishers to every other host of the run; `host_count` hosts in all.
    pub(crate) fn open(
        session: &Session,
        prefix: &str,
        layout: Arc<Layout>,
        host: u16,
        host_count: usize,
    ) -> Result<Self, String> {
        let mut publishers = Vec::with_capacity(host_count);
        for h in 0..host_count as u16 {
            if h == host {
                publishers.push(None);
                continue;
            }
            let publisher = session
                .declare_publisher(data_key(prefix, h))
                .congestion_control(CongestionControl::Block)
                .wait()
                .map_err(|e| format!("cannot publish to host {h}: {e}"))?;
            publishers.push(Some(publisher));
        }
        let traffic = layout.edges.iter().map(|_| EdgeCounters::default()).collect();
        Ok(Link {
            layout,
            host,
            publishers,
            credits: Mutex::new(HashMap::new()),
            traffic,
            sent: AtomicU64::new(0),
            received: AtomicU64::new(0),
            held: Mutex::new(HashMap::new()),
            rejections: Rejections::default(),
        })
    }

    /// Tuples sent to and received from other processes.
    pub(crate) fn counts(&self) -> (u64, u64) {
        (self.sent.load(Ordering::SeqCst), self.received.load(Ordering::SeqCst))
    }

    /// The traffic this process sent (and decoded) per edge.
    pub(crate) fn traffic(&self) -> Vec<EdgeTraffic> {
        self.traffic
            .iter()
            .enumerate()
            .filter(|(_, t)| t.messages.load(Ordering::Relaxed) + t.decode_ns.load(Ordering::Relaxed) > 0)
            .map(|(edge, t)| EdgeTraffic {
                edge: edge as u32,
                messages: t.messages.load(Ordering::Relaxed),
                bytes: t.bytes.load(Ordering::Relaxed),
                encode_ns: t.encode_ns.load(Ordering::Relaxed),
                decode_ns: t.decode_ns.load(Ordering::Relaxed),
            })
            .collect()
    }

    /// The target for task `to` of `consumer`'s input `slot`, on another
    /// host, as sent by task `from` of its producer.
    pub(crate) fn target(
        self: &Arc<Self>,
        consumer: usize,
        slot: usize,
        from: usize,
        to: usize,
    ) -> RemoteTarget {
        let edge = self.layout.edge_id(consumer, slot);
        let info = &self.layout.edges[edge as usize];
        let host = self.layout.host(consumer, to);
        let credits = (info.policy == OverflowPolicy::Block).then(|| {
            let credits = Arc::new(Semaphore::new(info.capacity));
            self.credits
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .insert((edge, from as u32, to as u32), credits.clone());
            credits
        });
        let sent = info.message.incremental_codec().map(|codec| Mutex::new((codec.new_sent)()));
        RemoteTarget { link: self.clone(), host, edge, from: from as u32, to: to as u32, credits, sent }
    }

    /// Ends every wait for credits (the run is aborting).
    pub(crate) fn close(&self) {
        for c in self.credits.lock().unwrap_or_else(|e| e.into_inner()).values() {
            c.close();
        }
    }

    async fn publish(&self, host: u16, bytes: Vec<u8>) -> Result<(), String> {
        let publisher =
            self.publishers[usize::from(host)].as_ref().ok_or("no link to this process itself")?;
        publisher.put(bytes).await.map_err(|e| e.to_string())
    }

    /// Handles a frame that arrived on this host's data key: a tuple goes
    /// to its queue's forwarder, a credit to its sender. Anything else is
    /// refused and counted.
    pub(crate) fn on_frame(&self, bytes: &[u8], inbound: &Inbound) {
        match Frame::decode(bytes, DEFAULT_MAX_FRAME) {
            Ok(Frame::Tuple { edge, from, to, payload }) => {
                // The sender counted it; whatever becomes of it here, it
                // has been received.
                if let Err(why) = self.accept(edge, from, to, &payload, inbound) {
                    tracing::warn!("host {}: refused a tuple on edge {edge}: {why}", self.host);
                    self.rejections.count(&crate::cluster::wire::WireError::Malformed(why));
                    self.received.fetch_add(1, Ordering::SeqCst);
                }
            }
            Ok(Frame::Credit { edge, from, to, n }) => {
                let credits = self.credits.lock().unwrap_or_else(|e| e.into_inner());
                match credits.get(&(edge, from, to)) {
                    Some(c) => c.add_permits(n as usize),
                    None => self.rejections.count(&crate::cluster::wire::WireError::Malformed(format!(
                        "credit for an unknown edge {edge} ({from} → {to})"
                    ))),
                }
            }
            Ok(other) => {
                let why = format!("unexpected on the data key: {other:?}");
                self.rejections.count(&crate::cluster::wire::WireError::Malformed(why));
            }
            Err(e) => self.rejections.count(&e),
        }
    }

    fn accept(&self, edge: u32, from: u32, to: u32, payload: &[u8], inbound: &Inbound) -> Result<(), String> {
        let info = self.layout.edges.get(edge as usize).ok_or("no such edge")?;
        let source = *info.sources.get(from as usize).ok_or("no such sending task")?;
        let forward = inbound
            .forwarders
            .get(&(edge, to))
            .ok_or_else(|| format!("task {to} of the consumer is not on this host"))?;
        let started = Instant::now();
        let decoded = match info.message.incremental_codec() {
            None => info.message.decode(payload).map_err(|e| e.to_string()),
            Some(codec) => {
                let mut held = self.held.lock().unwrap_or_else(|e| e.into_inner());
                let state = held.entry((edge, from, to)).or_insert_with(codec.new_held);
                (codec.decode)(payload, state)
            }
        }
        .map_err(|e| format!("payload does not decode: {e}"));
        self.traffic[edge as usize].decode_ns.fetch_add(nanos(started.elapsed()), Ordering::Relaxed);
        let tuple = Tuple { source, payload: decoded?, anchor: None };
        forward.send((tuple, from)).map_err(|_| "the run is over".to_string())
    }
}

/// A consumer task's input on another host, as one producer task sends
/// to it.
#[derive(Debug)]
pub(crate) struct RemoteTarget {
    link: Arc<Link>,
    host: u16,
    edge: u32,
    from: u32,
    to: u32,
    /// Room at the receiver, on a block edge.
    credits: Option<Arc<Semaphore>>,
    /// What the receiver holds, for an incremental message type.
    sent: Option<Mutex<CodecState>>,
}

impl RemoteTarget {
    /// Sends `tuple`, first waiting for a credit on a block edge (the wait
    /// is added to `blocked`).
    pub(crate) async fn deliver(&self, tuple: Tuple, blocked: &mut Duration) -> Result<(), EmitError> {
        let info = &self.link.layout.edges[self.edge as usize];
        let counters = &self.link.traffic[self.edge as usize];
        let started = Instant::now();
        let payload = match &self.sent {
            None => info.message.encode(&*tuple.payload).map_err(|e| e.to_string()),
            Some(sent) => {
                let codec = info.message.incremental_codec().expect("an incremental type");
                (codec.encode)(&*tuple.payload, &mut sent.lock().unwrap_or_else(|e| e.into_inner()))
            }
        }
        .map_err(EmitError::Transport)?;
        let frame = Frame::Tuple { edge: self.edge, from: self.from, to: self.to, payload }.encode();
        counters.encode_ns.fetch_add(nanos(started.elapsed()), Ordering::Relaxed);
        if let Some(credits) = &self.credits {
            let waited = Instant::now();
            credits.acquire().await.map_err(|_| EmitError::ShuttingDown)?.forget();
            *blocked += waited.elapsed();
        }
        counters.messages.fetch_add(1, Ordering::Relaxed);
        counters.bytes.fetch_add(frame.len() as u64, Ordering::Relaxed);
        // Counted before it can arrive, so no look at the totals sees it
        // received but not sent.
        self.link.sent.fetch_add(1, Ordering::SeqCst);
        self.link.publish(self.host, frame).await.map_err(EmitError::Transport)
    }
}

/// A queued tuple and the task that sent it.
type Forwarded = (Tuple, u32);

/// Where this host's incoming tuples go: a forwarder per local queue.
#[derive(Debug, Default)]
pub(crate) struct Inbound {
    forwarders: HashMap<(u32, u32), tokio::sync::mpsc::UnboundedSender<Forwarded>>,
}

impl Inbound {
    /// Forwarders for every local queue that a task elsewhere sends to,
    /// on `runtime`. `queue(c, slot, t)` is the queue of a local task.
    pub(crate) fn start(
        link: &Arc<Link>,
        runtime: &tokio::runtime::Handle,
        queue: &dyn Fn(usize, usize, usize) -> Arc<EdgeQueue>,
    ) -> Self {
        let layout = &link.layout;
        let mut forwarders = HashMap::new();
        for (edge, info) in layout.edges.iter().enumerate() {
            let fed_from_elsewhere =
                (0..info.sources.len()).any(|from| layout.host(info.producer, from) != link.host);
            if !fed_from_elsewhere {
                continue;
            }
            for to in 0..layout.hosts[info.consumer].len() {
                if layout.host(info.consumer, to) != link.host {
                    continue;
                }
                let (send, mut receive) = tokio::sync::mpsc::unbounded_channel::<Forwarded>();
                let target = queue(info.consumer, info.slot, to);
                let link = link.clone();
                let (edge, producer, block) =
                    (edge as u32, info.producer, info.policy == OverflowPolicy::Block);
                runtime.spawn(async move {
                    while let Some((tuple, from)) = receive.recv().await {
                        let mut blocked = Duration::ZERO;
                        let pushed = target.push(tuple, &mut blocked).await;
                        link.received.fetch_add(1, Ordering::SeqCst);
                        if block && matches!(pushed, Push::Queued) {
                            let credit = Frame::Credit { edge, from, to: to as u32, n: 1 }.encode();
                            let host = link.layout.host(producer, from as usize);
                            if let Err(e) = link.publish(host, credit).await {
                                tracing::warn!("cannot return a credit to host {host}: {e}");
                            }
                        }
                    }
                });
                forwarders.insert((edge, to as u32), send);
            }
        }
        Inbound { forwarders }
    }
}
