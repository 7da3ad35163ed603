//! Task metrics as they travel from a worker to the coordinator.

#[cfg(feature = "cluster")]
use std::collections::BTreeMap;
#[cfg(feature = "cluster")]
use std::time::Duration;

use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};

use crate::cluster::wire::WireError;
#[cfg(feature = "cluster")]
use crate::metrics::{Custom, TaskOutcome, TaskStats};
use crate::metrics::{HISTOGRAM_DIGITS, HISTOGRAM_HIGHEST, new_histogram};

/// A task's outcome as it travels from a worker to the coordinator:
/// histograms in HdrHistogram's portable V2 encoding.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutcomeWire {
    received: u64,
    emitted: u64,
    busy_ns: u64,
    blocked_ns: u64,
    wall_ns: u64,
    latency: Vec<u8>,
    restarts: u32,
    acked: u64,
    failed: u64,
    replayed: u64,
    abandoned: u64,
    custom: Vec<(String, CustomWire)>,
    dropped: u64,
    undelivered: u64,
    queue_depth_max: u64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
enum CustomWire {
    Counter(u64),
    Values(Vec<u8>),
    Gauge(u64),
    Measured(f64),
}

#[cfg(feature = "cluster")]
fn histogram_bytes(h: &Histogram<u64>) -> Vec<u8> {
    use hdrhistogram::serialization::Serializer;
    let mut bytes = Vec::new();
    hdrhistogram::serialization::V2Serializer::new()
        .serialize(h, &mut bytes)
        .expect("a histogram serializes into memory");
    bytes
}

/// The V2 encoding's cookie (uncompressed; squall never sends the
/// compressed form).
const V2_COOKIE: u32 = 0x1c84_9313;
/// The V2 header's size: cookie, payload length, normalizing offset,
/// significant digits, lowest, highest, conversion ratio.
const V2_HEADER: usize = 40;

/// A histogram from a peer, in HdrHistogram's portable V2 encoding,
/// decoded and checked to fit squall's bounds.
///
/// The header is checked first: the hdrhistogram crate allocates the
/// payload length and the counts its bounds imply before reading: a
/// 77-byte histogram claimed 1.3 GB (found by `fuzz/`'s `cluster_frames`
/// target).
pub fn decode_histogram(bytes: &[u8]) -> Result<Histogram<u64>, WireError> {
    let be32 = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_be_bytes(b.try_into().expect("4 bytes")));
    let be64 = |at: usize| bytes.get(at..at + 8).map(|b| u64::from_be_bytes(b.try_into().expect("8 bytes")));
    let (Some(cookie), Some(payload), Some(digits), Some(highest)) = (be32(0), be32(4), be32(12), be64(24))
    else {
        return Err(WireError::Histogram(format!("{} bytes, shorter than a V2 header", bytes.len())));
    };
    if cookie != V2_COOKIE {
        return Err(WireError::Histogram(format!("cookie {cookie:#x}, expected V2's {V2_COOKIE:#x}")));
    }
    let available = bytes.len() - V2_HEADER;
    if usize::try_from(payload).is_ok_and(|p| p > available) {
        return Err(WireError::Histogram(format!("payload of {payload} bytes claimed, {available} sent")));
    }
    if digits > u32::from(HISTOGRAM_DIGITS) || highest > HISTOGRAM_HIGHEST {
        return Err(WireError::HistogramBounds(format!(
            "{digits} digits up to {highest}, squall's histograms keep {HISTOGRAM_DIGITS} up to {HISTOGRAM_HIGHEST}"
        )));
    }
    let h: Histogram<u64> = hdrhistogram::serialization::Deserializer::new()
        .deserialize(&mut &bytes[..])
        .map_err(|e| WireError::Histogram(format!("{e:?}")))?;
    let mut bounded = new_histogram();
    bounded.add(&h).map_err(|e| WireError::HistogramBounds(format!("{e:?}")))?;
    Ok(bounded)
}

#[cfg(feature = "cluster")]
impl TaskOutcome {
    /// The outcome in its portable form.
    pub(crate) fn to_wire(&self) -> OutcomeWire {
        let s = &self.stats;
        let nanos = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        OutcomeWire {
            received: s.received,
            emitted: s.emitted,
            busy_ns: nanos(s.busy),
            blocked_ns: nanos(s.blocked),
            wall_ns: nanos(s.wall),
            latency: histogram_bytes(&s.latency),
            restarts: s.restarts,
            acked: s.acked,
            failed: s.failed,
            replayed: s.replayed,
            abandoned: s.abandoned,
            custom: s
                .custom
                .iter()
                .map(|(k, v)| {
                    let v = match v {
                        Custom::Counter(c) => CustomWire::Counter(*c),
                        Custom::Values(h) => CustomWire::Values(histogram_bytes(h)),
                        Custom::Gauge(g) => CustomWire::Gauge(*g),
                        Custom::Measured(m) => CustomWire::Measured(*m),
                    };
                    (k.clone(), v)
                })
                .collect(),
            dropped: self.dropped,
            undelivered: self.undelivered,
            queue_depth_max: self.queue_depth_max as u64,
        }
    }

    /// The outcome back from its portable form; an error if a histogram
    /// does not decode.
    pub(crate) fn from_wire(w: OutcomeWire) -> Result<Self, WireError> {
        let mut custom = BTreeMap::new();
        for (k, v) in w.custom {
            let v = match v {
                CustomWire::Counter(c) => Custom::Counter(c),
                CustomWire::Values(bytes) => Custom::Values(Box::new(decode_histogram(&bytes)?)),
                CustomWire::Gauge(g) => Custom::Gauge(g),
                CustomWire::Measured(m) => Custom::Measured(m),
            };
            custom.insert(k, v);
        }
        Ok(TaskOutcome {
            stats: TaskStats {
                received: w.received,
                emitted: w.emitted,
                busy: Duration::from_nanos(w.busy_ns),
                blocked: Duration::from_nanos(w.blocked_ns),
                wall: Duration::from_nanos(w.wall_ns),
                latency: decode_histogram(&w.latency)?,
                restarts: w.restarts,
                acked: w.acked,
                failed: w.failed,
                replayed: w.replayed,
                abandoned: w.abandoned,
                custom,
            },
            dropped: w.dropped,
            undelivered: w.undelivered,
            queue_depth_max: usize::try_from(w.queue_depth_max).unwrap_or(usize::MAX),
            lost: false,
        })
    }
}

#[cfg(all(test, feature = "cluster"))]
mod tests {
    use super::*;
    use crate::metrics::task_report;

    #[test]
    fn an_outcome_survives_its_portable_form() {
        let mut stats =
            TaskStats { received: 7, emitted: 3, busy: Duration::from_millis(5), ..Default::default() };
        stats.latency.record(1500).unwrap();
        stats.latency.record(90_000).unwrap();
        stats.count("scans", 4);
        stats.record("evaluations", 120);
        stats.record("evaluations", 40);
        let outcome = TaskOutcome { stats, dropped: 2, undelivered: 1, queue_depth_max: 9, lost: false };
        let bytes = postcard::to_stdvec(&outcome.to_wire()).unwrap();
        let back = TaskOutcome::from_wire(postcard::from_bytes(&bytes).unwrap()).unwrap();
        assert_eq!(task_report(0, &back).execute, task_report(0, &outcome).execute);
        assert_eq!(task_report(0, &back).custom, task_report(0, &outcome).custom);
        assert_eq!((back.dropped, back.undelivered, back.queue_depth_max), (2, 1, 9));
        assert_eq!(back.stats.busy, Duration::from_millis(5));
    }

    #[test]
    fn a_histogram_claiming_more_than_it_sends_is_refused_unread() {
        let mut latency = new_histogram();
        latency.record(1500).unwrap();
        let bytes = histogram_bytes(&latency);
        assert_eq!(decode_histogram(&bytes).unwrap().len(), 1);
        // The payload length raised to 1.3 GB: the fuzzer's case.
        let mut claims = bytes.clone();
        claims[4..8].copy_from_slice(&0x4e00_0000u32.to_be_bytes());
        let error = decode_histogram(&claims).unwrap_err().to_string();
        assert!(error.contains("payload of 1308622848 bytes claimed"), "{error}");
        // Bounds past squall's: 5 digits.
        let mut digits = bytes.clone();
        digits[12..16].copy_from_slice(&5u32.to_be_bytes());
        assert!(matches!(decode_histogram(&digits), Err(WireError::HistogramBounds(_))));
        assert!(decode_histogram(&bytes[..39]).is_err());
    }
}
