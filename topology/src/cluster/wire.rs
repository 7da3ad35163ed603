//! What crosses between processes, and the checks every incoming message
//! passes before anything reads it: a size limit, a magic and version
//! header, a complete postcard body with nothing after it. A message that
//! fails is rejected with a reason and counted, never a panic: peers may
//! be buggy, old, or hostile.

use std::sync::atomic::{AtomicU64, Ordering};

use serde::{Deserialize, Serialize};

/// The first bytes of every frame.
const MAGIC: [u8; 2] = *b"SQ";
/// The frame format; a peer speaking another is refused.
pub const WIRE_VERSION: u8 = 1;
/// Frames larger than this are refused unread, unless the cluster sets
/// another limit: a map with its tiles fits many times over.
pub const DEFAULT_MAX_FRAME: usize = 64 << 20;

/// A message between the processes of a cluster.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Frame {
    /// A tuple on an edge of the topology, for one task of the consumer.
    Tuple {
        /// The edge, by its index in the plan all processes share.
        edge: u32,
        /// The receiving task.
        task: u32,
        /// The message, postcard-encoded as the stream's type.
        payload: Vec<u8>,
    },
    /// A message between two tasks of one component.
    Peer {
        /// The component, by its index in the plan.
        component: u32,
        /// The sending task.
        from: u32,
        /// The receiving task.
        to: u32,
        /// The message, postcard-encoded.
        payload: Vec<u8>,
    },
    /// Coordinator and workers managing a run.
    Control(Control),
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
    /// End the run: the worker stops its tasks.
    Stop,
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
            Frame::Tuple { edge: 3, task: 1, payload: vec![1, 2, 3] },
            Frame::Peer { component: 2, from: 0, to: 2, payload: vec![9; 1000] },
            Frame::Control(Control::Ping { nonce: 77 }),
            Frame::Control(Control::Pong { nonce: 77, worker: "w1".into() }),
            Frame::Control(Control::Stop),
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
        let bytes = Frame::Peer { component: 0, from: 0, to: 1, payload: vec![0; 5000] }.encode();
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
