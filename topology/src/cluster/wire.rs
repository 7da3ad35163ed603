//! What crosses between processes, and the checks every incoming message
//! passes before anything reads it: a size limit, a magic and version
//! header, a complete postcard body with nothing after it. A message that
//! fails is rejected with a reason and counted, never a panic: peers may
//! be buggy, old, or hostile.

use std::sync::atomic::{AtomicU64, Ordering};

use serde::{Deserialize, Serialize};

/// The first bytes of every frame.
const MAGIC: [u8; 2] = *b"SQ";
/// The frame format; a peer speaking another is refused (2: batches of
/// tuples travel as one frame).
pub const WIRE_VERSION: u8 = 5;
/// Frames larger than this are refused unread, unless the cluster sets
/// another limit: a map with its tiles fits many times over.
pub const DEFAULT_MAX_FRAME: usize = 64 << 20;

/// A message between the processes of a cluster.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Frame {
    /// A tuple on an edge of the topology, from one task of the producer
    /// to one task of the consumer.
    Tuple {
        /// The sending process's host number.
        sender: u16,
        /// The edge, by its index in the plan all processes share (a
        /// consumer's inputs in file order, then its peer messages).
        edge: u32,
        /// The sending task.
        from: u32,
        /// The receiving task.
        to: u32,
        /// The message, postcard-encoded as the stream's type.
        payload: Vec<u8>,
    },
    /// Room given back on a `block` edge: the receiving side has queued
    /// `n` more of the sender's tuples, so the sender may send `n` more.
    Credit {
        /// The edge.
        edge: u32,
        /// The sending task the room is for.
        from: u32,
        /// The receiving task.
        to: u32,
        /// Tuples.
        n: u32,
    },
    /// Coordinator and workers managing a run.
    Control(Control),
    /// A producer task's batch for one consumer task, in emit order: as
    /// that many `Tuple` frames, in one message (and, on a `block` edge,
    /// under that many credits).
    Tuples {
        /// The sending process's host number.
        sender: u16,
        /// The edge.
        edge: u32,
        /// The sending task.
        from: u32,
        /// The receiving task.
        to: u32,
        /// The messages, each postcard-encoded as the stream's type.
        payloads: Vec<Vec<u8>>,
    },
    /// A control from a coordinator, signed with its certificate's key
    /// (see [`crate::cluster::identity`]).
    Signed(Box<Signed>),
}

/// The signature algorithms, as the wire names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Algorithm {
    /// ECDSA on P-256 with SHA-256 (openssl's `-newkey ec` with prime256v1).
    EcdsaP256Sha256,
    /// ECDSA on P-384 with SHA-384.
    EcdsaP384Sha384,
    /// Ed25519.
    Ed25519,
    /// RSA PKCS#1 v1.5 with SHA-256.
    RsaPkcs1Sha256,
}

/// What a coordinator signs: the control and what makes it fresh and
/// addressed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SignedBody {
    /// The key it is sent on (a worker's control key, a run's): a frame
    /// for one worker or run is no good on another's.
    pub to: String,
    /// The coordinator's session, and a counter that only grows within
    /// it: a frame seen once is not taken again.
    pub coordinator: String,
    /// See `coordinator`.
    pub counter: u64,
    /// When it was signed, ms since the Unix epoch.
    pub issued_ms: u64,
    /// What the coordinator says.
    pub control: Control,
}

/// A signed control frame's parts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Signed {
    /// The coordinator's certificate chain, DER, leaf first.
    pub certificates: Vec<Vec<u8>>,
    /// The signature's algorithm.
    pub algorithm: Algorithm,
    /// The postcard bytes of a [`SignedBody`].
    pub body: Vec<u8>,
    /// The signature over `body`.
    pub signature: Vec<u8>,
}

/// A run as the coordinator ships it to a worker.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunPlan {
    /// The key prefix of the run's traffic.
    pub run: String,
    /// The topology's file name, for messages.
    pub file: String,
    /// The topology's text, overrides applied.
    pub topology: String,
    /// `hosts[c][t]`: where task t of component c runs (0 the
    /// coordinator, w + 1 the w-th worker of the cluster file).
    pub hosts: Vec<Vec<u16>>,
    /// The host number of the worker this is sent to.
    pub host: u16,
    /// Hosts in the run (the coordinator and every worker of the file).
    pub host_count: u16,
    /// The coordinator's id, as in its liveliness token: once the run is
    /// over (collected or refused) the worker outlives this coordinator.
    pub coordinator: String,
}

impl RunPlan {
    /// The key the coordinator sends run control on.
    pub fn control_key(&self) -> String {
        format!("{}/ctl", self.run)
    }

    /// The key workers report on.
    pub fn report_key(&self) -> String {
        format!("{}/up", self.run)
    }
}

/// What a task reports, as it crosses to the coordinator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum TaskEvent {
    /// A spout task is exhausted.
    SpoutDone,
    /// `finish`/`close` returned.
    Finished,
    /// The task failed for good.
    Failed(String),
    /// The task's thread ended.
    Exited,
}

/// The traffic a process sent on one edge.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct EdgeTraffic {
    /// The edge.
    pub edge: u32,
    /// Tuples sent.
    pub messages: u64,
    /// Frames they were sent in.
    pub frames: u64,
    /// Frame bytes sent.
    pub bytes: u64,
    /// Serializing, in nanoseconds.
    pub encode_ns: u64,
    /// Deserializing at the receivers of this process, in nanoseconds.
    pub decode_ns: u64,
    /// Tuples held for a task in another process and never sent: their
    /// producer task ended (failed, or the run aborted) first.
    pub undelivered: u64,
}

/// Run management between the coordinator and its workers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Control {
    /// Is the worker there? Answered by `Pong` with the same nonce.
    Ping {
        /// Matches the answer to the question.
        nonce: u64,
    },
    /// The worker's answer to `Ping`.
    Pong {
        /// The question's nonce.
        nonce: u64,
        /// The answering worker's name.
        worker: String,
    },
    /// End the worker process.
    Stop,
    /// The run is over: send `Outcomes` and let the run go.
    Collect,
    /// Host these tasks of this run: validate, wire, subscribe, then
    /// answer `Ready` (or `Refused`) and wait for `Go`.
    Start(Box<RunPlan>),
    /// The worker has wired the run and listens for its tuples.
    Ready {
        /// The run.
        run: String,
    },
    /// The worker cannot host the run.
    Refused {
        /// The run.
        run: String,
        /// Why.
        reason: String,
    },
    /// Every host is ready: start the tasks.
    Go,
    /// Move every task of a component forward to a stage.
    Advance {
        /// The component, by index.
        component: u32,
        /// The stage (drain 1, finish 2, exit 3, abort 4).
        stage: u8,
    },
    /// How far is the worker? Answered by `Totals`.
    Status {
        /// Matches the answer.
        nonce: u64,
    },
    /// A host's tuples accepted and resolved by its queues so far, the
    /// tuples it sent to and received from each host, and whether a tick
    /// is running.
    Totals {
        /// The question's nonce.
        nonce: u64,
        /// The answering host.
        host: u16,
        /// Accepted into queues.
        accepted: u64,
        /// Resolved by queues.
        resolved: u64,
        /// Tuples sent to each host.
        sent_to: Vec<u64>,
        /// Tuples received from each host.
        received_from: Vec<u64>,
        /// A task is inside `tick`.
        ticking: bool,
    },
    /// A host was lost: its tasks now run where `moves` says (component,
    /// task, host).
    Reassign {
        /// The lost host.
        lost: u16,
        /// Where each of its tasks runs now.
        moves: Vec<(u32, u32, u16)>,
    },
    /// A task on a worker reports.
    Event {
        /// The component.
        component: u32,
        /// The task.
        task: u32,
        /// What happened.
        event: TaskEvent,
    },
    /// A worker's last word on a run: its tasks' metrics and its traffic.
    Outcomes {
        /// The answering host.
        host: u16,
        /// (component, task, outcome).
        tasks: Vec<(u32, u32, crate::cluster::outcome::OutcomeWire)>,
        /// Traffic per edge.
        edges: Vec<EdgeTraffic>,
        /// Frames it refused: (too large, malformed).
        refused: (u64, u64),
    },
    /// A worker's tasks as they stand, each second while a run goes, for
    /// the coordinator's live view of it.
    Live {
        /// The reporting host.
        host: u16,
        /// (component, task, its counters now).
        tasks: Vec<(u32, u32, crate::live::RemoteTask)>,
        /// Traffic it sent to other processes so far, per edge.
        edges: Vec<EdgeTraffic>,
    },
}

/// Why an incoming frame was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// Over the size limit; not read.
    #[error("frame of {len} bytes exceeds the limit of {max}")]
    TooLarge {
        /// The frame's size.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// Not a squall frame (too short or wrong magic).
    #[error("not a squall frame")]
    NotAFrame,
    /// A squall frame of another format version.
    #[error("frame format {found}, expected {WIRE_VERSION}")]
    Version {
        /// The version the peer speaks.
        found: u8,
    },
    /// The body does not decode as a frame.
    #[error("malformed frame: {0}")]
    Malformed(String),
    /// A histogram of a task's metrics does not decode.
    #[error("bad histogram: {0}")]
    Histogram(String),
    /// A histogram of a task's metrics exceeds the bounds of squall's.
    #[error("histogram out of bounds: {0}")]
    HistogramBounds(String),
    /// The body decodes but bytes follow it.
    #[error("{0} bytes after the frame")]
    Trailing(usize),
}

/// Counts of frames refused, by reason: reported with the run's metrics.
#[derive(Debug, Default)]
pub struct Rejections {
    too_large: AtomicU64,
    malformed: AtomicU64,
}

impl Rejections {
    /// Counts `error`.
    pub fn count(&self, error: &WireError) {
        let counter = match error {
            WireError::TooLarge { .. } => &self.too_large,
            _ => &self.malformed,
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// (too large, malformed) so far.
    pub fn totals(&self) -> (u64, u64) {
        (self.too_large.load(Ordering::Relaxed), self.malformed.load(Ordering::Relaxed))
    }
}

impl Frame {
    /// The frame's bytes: header, then the postcard body.
    pub fn encode(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(64);
        bytes.extend_from_slice(&MAGIC);
        bytes.push(WIRE_VERSION);
        // Serializing into a Vec cannot fail for these types.
        postcard::to_io(self, &mut bytes).expect("a frame serializes");
        bytes
    }

    /// Checks and decodes an incoming frame of at most `max` bytes.
    pub fn decode(bytes: &[u8], max: usize) -> Result<Frame, WireError> {
        if bytes.len() > max {
            return Err(WireError::TooLarge { len: bytes.len(), max });
        }
        let body = match bytes {
            [m0, m1, version, body @ ..] if [*m0, *m1] == MAGIC => {
                if *version != WIRE_VERSION {
                    return Err(WireError::Version { found: *version });
                }
                body
            }
            _ => return Err(WireError::NotAFrame),
        };
        let (frame, rest) =
            postcard::take_from_bytes::<Frame>(body).map_err(|e| WireError::Malformed(e.to_string()))?;
        if !rest.is_empty() {
            return Err(WireError::Trailing(rest.len()));
        }
        Ok(frame)
    }
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    fn samples() -> Vec<Frame> {
        vec![
            Frame::Tuple { sender: 1, edge: 3, from: 0, to: 1, payload: vec![1, 2, 3] },
            Frame::Tuple { sender: 0, edge: 2, from: 0, to: 2, payload: vec![9; 1000] },
            Frame::Control(Control::Reassign { lost: 2, moves: vec![(3, 1, 1)] }),
            Frame::Credit { edge: 2, from: 1, to: 0, n: 3 },
            Frame::Control(Control::Advance { component: 2, stage: 3 }),
            Frame::Control(Control::Event { component: 1, task: 0, event: TaskEvent::Failed("x".into()) }),
            Frame::Control(Control::Ping { nonce: 77 }),
            Frame::Control(Control::Pong { nonce: 77, worker: "w1".into() }),
            Frame::Control(Control::Stop),
            Frame::Tuples {
                sender: 2,
                edge: 1,
                from: 1,
                to: 0,
                payloads: vec![vec![4; 30], vec![], vec![5; 200]],
            },
        ]
    }

    #[test]
    fn frames_round_trip() {
        for frame in samples() {
            assert_eq!(Frame::decode(&frame.encode(), DEFAULT_MAX_FRAME), Ok(frame));
        }
    }

    #[test]
    fn oversized_foreign_old_and_padded_frames_are_refused() {
        let bytes = Frame::Tuple { sender: 0, edge: 0, from: 0, to: 1, payload: vec![0; 5000] }.encode();
        assert_eq!(Frame::decode(&bytes, 4096), Err(WireError::TooLarge { len: bytes.len(), max: 4096 }));
        assert_eq!(Frame::decode(b"GET / HTTP/1.1", DEFAULT_MAX_FRAME), Err(WireError::NotAFrame));
        assert_eq!(Frame::decode(b"SQ", DEFAULT_MAX_FRAME), Err(WireError::NotAFrame));
        let mut old = Frame::Control(Control::Stop).encode();
        old[2] = 0;
        assert_eq!(Frame::decode(&old, DEFAULT_MAX_FRAME), Err(WireError::Version { found: 0 }));
        let mut padded = Frame::Control(Control::Stop).encode();
        padded.push(0);
        assert_eq!(Frame::decode(&padded, DEFAULT_MAX_FRAME), Err(WireError::Trailing(1)));
        let rejections = Rejections::default();
        rejections.count(&WireError::TooLarge { len: 2, max: 1 });
        rejections.count(&WireError::NotAFrame);
        rejections.count(&WireError::Trailing(1));
        assert_eq!(rejections.totals(), (1, 2));
    }

    #[test]
    fn corrupted_frames_are_errors_not_panics() {
        // Every frame cut short, and many with random bytes flipped or
        // random lengths claimed: each decodes to a frame or an error.
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut refused, mut total) = (0, 0);
        for frame in samples() {
            let bytes = frame.encode();
            for cut in 0..bytes.len() {
                assert!(Frame::decode(&bytes[..cut], DEFAULT_MAX_FRAME).is_err(), "{frame:?} cut at {cut}");
            }
            for _ in 0..2000 {
                let mut bad = bytes.clone();
                for _ in 0..rng.random_range(1..4) {
                    let i = rng.random_range(3..bad.len());
                    bad[i] = rng.random();
                }
                total += 1;
                refused += usize::from(Frame::decode(&bad, DEFAULT_MAX_FRAME).is_err());
            }
        }
        // Flipped bytes inside payloads still decode; headers and lengths
        // mostly do not.
        assert!(refused > total / 10, "{refused} of {total} refused");
    }
}
