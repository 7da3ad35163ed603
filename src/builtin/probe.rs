//! The throughput probe: `probe.source → probe.relay → probe.sink`, with a
//! configurable message size, count and rate. It measures the engine itself
//! (messages/s, end-to-end latency) and injects faults for tests (slow,
//! failing, panicking, hanging or leaking bolts; a source that errors).

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use smallvec::SmallVec;
use squall_topology::{
    Bolt, BoxError, Declarer, Emitter, ParamError, Params, Registry, Spout, SpoutStatus, TaskContext, Tuple,
};

/// Padding bytes kept inside the message (a 64-byte probe's); larger
/// messages put theirs on the heap.
const INLINE_PADDING: usize = 40;

/// A probe message: a sequence number, a key, the send time and padding.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Probe {
    /// Position in the source's sequence.
    pub seq: u64,
    /// `seq % keys`, for `fields` grouping.
    pub key: u64,
    /// Wall-clock send time, ns since the Unix epoch (read once per
    /// burst of messages a `next` call emits).
    pub sent_ns: u64,
    /// Padding up to the configured message size, inline up to 64 bytes.
    pub payload: SmallVec<[u8; INLINE_PADDING]>,
}

/// Bytes of a probe message besides its padding.
const HEADER_BYTES: usize = 24;
/// Most messages one `next` call emits.
const BURST: u64 = 256;
/// Waits shorter than this are done by yielding rather than a timer.
const FINE_PACING: Duration = Duration::from_micros(100);

fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// Registers `probe.source`, `probe.relay` and `probe.sink`.
pub fn register(r: &mut Registry) {
    r.register_spout("probe.source", ProbeSource::new);
    r.register_bolt("probe.relay", |p| Ok(ProbeRelay { fault: p.parse()?, seen: 0 }));
    r.register_bolt("probe.sink", |p| Ok(ProbeSink { fault: p.parse()?, seen: 0 }));
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SourceParams {
    /// Messages per task. The default is 1 000 000.
    #[serde(default = "default_count")]
    count: u64,
    /// Size of one message in bytes (at least 24). The default is 64.
    #[serde(default = "default_bytes")]
    message_bytes: usize,
    /// Messages per second per task; absent = as fast as possible.
    rate_hz: Option<f64>,
    /// Distinct keys. The default is 1024.
    #[serde(default = "default_keys")]
    keys: u64,
    /// Fail with an error (as a source whose input breaks) when about to
    /// emit the n-th message (1-based); absent = never.
    fail_at: Option<u64>,
}

fn default_count() -> u64 {
    1_000_000
}
fn default_bytes() -> usize {
    64
}
fn default_keys() -> u64 {
    1024
}

/// Emits `count` probes, optionally paced at `rate_hz`.
#[derive(Debug)]
pub struct ProbeSource {
    params: SourceParams,
    next_seq: u64,
    started: Option<Instant>,
}

impl ProbeSource {
    fn new(p: &Params) -> Result<Self, ParamError> {
        let params: SourceParams = p.parse()?;
        if params.message_bytes < HEADER_BYTES {
            return Err(ParamError::new(format!(
                "message_bytes must be at least {HEADER_BYTES}, got {}",
                params.message_bytes
            )));
        }
        if params.keys == 0 {
            return Err(ParamError::new("keys must be at least 1"));
        }
        if params.rate_hz.is_some_and(|r| !(r.is_finite() && r > 0.0)) {
            return Err(ParamError::new("rate_hz must be a positive number"));
        }
        Ok(ProbeSource { params, next_seq: 0, started: None })
    }
}

impl Spout for ProbeSource {
    fn declare(&self, d: &mut Declarer) {
        d.output::<Probe>("default");
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        ctx.expect_emits(self.params.count);
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        let started = *self.started.get_or_insert_with(Instant::now);
        let remaining = self.params.count - self.next_seq;
        let mut burst = remaining.min(BURST);
        if let Some(rate) = self.params.rate_hz {
            let due = (started.elapsed().as_secs_f64() * rate) as u64;
            burst = burst.min(due.saturating_sub(self.next_seq));
            if burst == 0 {
                let next_due = started + Duration::from_secs_f64((self.next_seq + 1) as f64 / rate);
                let wait = next_due.saturating_duration_since(Instant::now());
                if wait < FINE_PACING {
                    // Timers are coarse (about 1 ms); short waits yield the
                    // core instead, so that paced messages leave one by one
                    // rather than in bursts.
                    std::thread::yield_now();
                } else {
                    tokio::time::sleep_until(next_due.into()).await;
                }
                return Ok(SpoutStatus::Continue);
            }
        }
        let padding = self.params.message_bytes - HEADER_BYTES;
        // One clock read per burst: the burst leaves at once (a message
        // emitted later in it shows a little more latency, never less).
        let sent_ns = now_ns();
        for _ in 0..burst {
            let seq = self.next_seq;
            if self.params.fail_at == Some(seq + 1) {
                return Err(format!("injected source error at message {}", seq + 1).into());
            }
            self.next_seq += 1;
            let payload = SmallVec::from_elem(0, padding);
            out.emit("default", Probe { seq, key: seq % self.params.keys, sent_ns, payload }).await?;
        }
        Ok(if self.next_seq == self.params.count { SpoutStatus::Done } else { SpoutStatus::Continue })
    }
}

/// Fault injection shared by relay and sink.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Fault {
    /// What `leak_kib` has kept.
    #[serde(skip)]
    leaked: Vec<Vec<u8>>,
    /// Sleep this long per message (a slow bolt).
    #[serde(default)]
    delay_us: u64,
    /// Panic on the n-th message (1-based).
    panic_at: Option<u64>,
    /// Fail (for replay) the first n messages it sees.
    #[serde(default)]
    fail_first: u64,
    /// Stop making progress on the n-th message: never return from it.
    hang_at: Option<u64>,
    /// Keep this many KiB allocated for every message seen (a leak).
    #[serde(default)]
    leak_kib: u64,
}

impl Fault {
    fn apply(&mut self, seen: u64, out: &mut Emitter) {
        if self.delay_us > 0 {
            // Blocking is fine: every task has its own thread.
            std::thread::sleep(Duration::from_micros(self.delay_us));
        }
        if self.panic_at == Some(seen) {
            panic!("injected panic at message {seen}");
        }
        if self.hang_at == Some(seen) {
            loop {
                std::thread::park();
            }
        }
        if self.leak_kib > 0 {
            // Touched, so that it is resident, not only reserved.
            self.leaked.push(vec![1u8; (self.leak_kib as usize) << 10]);
        }
        if seen <= self.fail_first {
            out.fail();
        }
    }
}

/// Forwards every probe unchanged (no copy).
#[derive(Debug)]
pub struct ProbeRelay {
    fault: Fault,
    seen: u64,
}

impl Bolt for ProbeRelay {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Probe>().output::<Probe>("default");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        self.seen += 1;
        self.fault.apply(self.seen, out);
        let probe = input.into_arc::<Probe>().map_err(|_| "probe.relay expects Probe")?;
        out.emit_shared("default", probe).await?;
        Ok(())
    }
}

/// The sink times one message in this many (by sequence number): a clock
/// read and a histogram update per message were a tenth of the
/// pipeline's time.
const LATENCY_SAMPLE: u64 = 16;

/// Counts probes and records the end-to-end latency (`latency_ns`) of one
/// in [`LATENCY_SAMPLE`].
#[derive(Debug)]
pub struct ProbeSink {
    fault: Fault,
    seen: u64,
}

impl Bolt for ProbeSink {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Probe>();
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        self.seen += 1;
        self.fault.apply(self.seen, out);
        let probe = input.get::<Probe>().ok_or("probe.sink expects Probe")?;
        if probe.seq % LATENCY_SAMPLE == 0 {
            out.record("latency_ns", now_ns().saturating_sub(probe.sent_ns));
        }
        Ok(())
    }
}
