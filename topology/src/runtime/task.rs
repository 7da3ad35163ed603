//! The loop of one task, on its own thread.
//!
//! A bolt task takes a batch from one of its input queues (round-robin over
//! its inputs), executes it, hands over what it emitted (its held batches),
//! gives the room back, and sleeps when every queue is empty. A spout task
//! calls `next` until the source is exhausted, handing over its batches
//! after each call, settling acks and replaying failures in between. Both obey the coordinator's stage
//! (finish, exit, abort). A panic or error is caught here: the task restarts
//! with a fresh instance if its policy allows, else the run fails.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::Sender;
use std::time::{Duration, Instant};

use tokio::runtime::Handle;
use tracing::warn;

use crate::component::{Bolt, MessageId, Spout, SpoutStatus};
use crate::context::TaskContext;
use crate::error::BoxError;
use crate::live::{DETAIL_PERIOD, TaskLive};
use crate::metrics::TaskOutcome;
use crate::params::Params;
use crate::registry::{BoltFactory, SpoutFactory};
use crate::runtime::acker::{AckTracker, Outcome, Replay};
use crate::runtime::control::{Control, Event, EventKind, Stage};
use crate::runtime::emitter::Emitter;
use crate::runtime::queue::EdgeQueue;
use crate::runtime::{Progress, StopRequest};
use crate::spec::AckPolicy;
use crate::tuple::Tuple;

/// Most tuples taken from a queue at once: a busy consumer takes what
/// its producers handed over (a batch of up to 256 by default) in one go.
const MAX_BATCH: usize = 256;
/// A tuple whose execute took this long has the next one timed too: a
/// clock read (a vDSO call of tens of nanoseconds) is then small beside
/// the work, and a slow bolt's ticks and stall watchdog see every tuple.
const TIME_EACH_ABOVE: Duration = Duration::from_micros(2);
/// Polls of the input queues before an idle bolt task parks.
const SPINS: usize = 8;
/// How often a waiting spout checks for timed-out tuple trees.
const ACK_POLL: Duration = Duration::from_millis(20);

/// What every task has.
#[derive(Debug)]
pub(crate) struct TaskCommon {
    pub(crate) ctx: TaskContext,
    pub(crate) component: usize,
    pub(crate) control: Arc<Control>,
    pub(crate) emitter: Emitter,
    pub(crate) events: Sender<Event>,
    pub(crate) finished: bool,
    /// Where the task publishes its counters while it runs, when the run
    /// is watched.
    pub(crate) live: Option<Arc<TaskLive>>,
    /// When the task next publishes its percentiles and own metrics.
    pub(crate) next_detail: Instant,
    /// Whether counters changed since they were last published in detail.
    pub(crate) detail_stale: bool,
}

impl TaskCommon {
    /// Publishes the counters to a watched run: a store per counter, and
    /// every [`DETAIL_PERIOD`] the percentiles and the component's own
    /// metrics.
    fn publish(&mut self, now: Instant) {
        let Some(live) = &self.live else { return };
        if now >= self.next_detail {
            live.publish_detail(&self.emitter.stats);
            self.next_detail = now + DETAIL_PERIOD;
            self.detail_stale = false;
        } else {
            live.publish(&self.emitter.stats);
            self.detail_stale = true;
        }
    }

    /// When a task about to wait should wake to publish what it has not
    /// yet published in detail (`None` when nothing waits).
    fn detail_due(&self) -> Option<Instant> {
        (self.live.is_some() && self.detail_stale).then_some(self.next_detail)
    }

    fn report(&self, kind: EventKind) {
        // The coordinator outlives every task; a closed channel means it is
        // gone and there is nobody left to tell.
        let _ = self.events.send(Event { component: self.component, task: self.ctx.task_index, kind });
    }
}

/// A bolt task's state, kept across restarts.
#[derive(Debug)]
pub(crate) struct BoltTask {
    pub(crate) common: TaskCommon,
    pub(crate) inbox: Vec<Arc<EdgeQueue>>,
    /// Per inbox queue: whether `Emitter::hold_inputs` holds it back
    /// (every input but feedback edges and the peer queue).
    holdable: Vec<bool>,
    pub(crate) tick: Option<Duration>,
    batch: VecDeque<Tuple>,
    batch_from: usize,
    batch_taken: usize,
    /// The rest of a batch from a held queue, taken but not yet executed
    /// (and not released: its queue still counts it).
    parked: VecDeque<Tuple>,
    parked_from: usize,
    parked_taken: usize,
    next_queue: usize,
    /// One tuple in this many (and the first of each batch) is timed.
    pub(crate) execute_sample: usize,
}

impl BoltTask {
    pub(crate) fn new(
        mut common: TaskCommon,
        inbox: Vec<Arc<EdgeQueue>>,
        holdable: Vec<bool>,
        tick: Option<Duration>,
    ) -> Self {
        common.emitter.watch = Some(common.control.clone());
        BoltTask {
            common,
            inbox,
            holdable,
            tick,
            batch: VecDeque::with_capacity(MAX_BATCH),
            batch_from: 0,
            batch_taken: 0,
            parked: VecDeque::new(),
            parked_from: 0,
            parked_taken: 0,
            next_queue: 0,
            execute_sample: crate::spec::DEFAULT_EXECUTE_SAMPLE,
        }
    }

    fn holding(&self) -> bool {
        self.common.emitter.holding
    }

    fn take_batch(&mut self) -> bool {
        if !self.holding() && !self.parked.is_empty() {
            std::mem::swap(&mut self.batch, &mut self.parked);
            self.batch_from = self.parked_from;
            self.batch_taken = std::mem::take(&mut self.parked_taken);
            return true;
        }
        let n = self.inbox.len();
        for k in 0..n {
            let q = (self.next_queue + k) % n;
            if self.holdable[q] && self.holding() {
                continue;
            }
            let taken = self.inbox[q].take(&mut self.batch, MAX_BATCH);
            if taken > 0 {
                self.batch_from = q;
                self.batch_taken = taken;
                self.next_queue = (q + 1) % n;
                return true;
            }
        }
        false
    }

    /// Polls the queues briefly before the task parks: a wake-up costs a
    /// system call on both sides, while input usually arrives within
    /// microseconds on a busy pipeline.
    fn spin_for_input(&mut self) -> bool {
        for _ in 0..SPINS {
            std::hint::spin_loop();
            std::thread::yield_now();
            if self.take_batch() {
                return true;
            }
        }
        false
    }

    /// Keeps the rest of the current batch aside while its queue is held.
    fn park_batch(&mut self) {
        debug_assert!(self.parked.is_empty(), "a held queue is not taken from");
        std::mem::swap(&mut self.batch, &mut self.parked);
        self.parked_from = self.batch_from;
        self.parked_taken = std::mem::take(&mut self.batch_taken);
    }

    /// Discards the tuples taken from the queues but not executed (the
    /// rest of a batch when the task failed or the run aborted, a parked
    /// batch): each counts as undelivered on its queue, its anchor failed.
    fn discard_taken(&mut self) {
        for (queue, from) in [(&mut self.batch, self.batch_from), (&mut self.parked, self.parked_from)] {
            if queue.is_empty() {
                continue;
            }
            self.inbox[from].counters.undelivered.fetch_add(queue.len() as u64, Ordering::Relaxed);
            queue.drain(..).for_each(Tuple::lost);
        }
    }

    fn release_batch(&mut self) {
        if self.batch_taken > 0 {
            self.inbox[self.batch_from].release(self.batch_taken);
            self.batch_taken = 0;
        }
    }

    /// Executes one tuple (no clock read: the loop times batches, and
    /// sampled tuples alone).
    async fn execute<B: Bolt>(&mut self, bolt: &mut B, mut tuple: Tuple) -> Result<(), BoxError> {
        let out = &mut self.common.emitter;
        out.anchor = tuple.anchor.take();
        out.input_failed = false;
        // Counted before it runs: a tuple whose execution panics or fails
        // was received all the same.
        out.stats.received += 1;
        let result = bolt.execute(tuple, out).await;
        if let Some(anchor) = out.anchor.take() {
            if out.input_failed || result.is_err() { anchor.fail() } else { anchor.complete() }
        }
        result
    }

    /// Ends a stretch of executing that began at `start` with `blocked`
    /// time waited so far: its time, waits for queue space aside, is busy.
    fn busy_until(&mut self, start: Instant, blocked: Duration, end: Instant) {
        let stats = &mut self.common.emitter.stats;
        stats.busy += (end - start).saturating_sub(stats.blocked - blocked);
    }
}

/// Calls the bolt's `tick` and schedules the next one. While the task is
/// processing a batch (`busy`) it ticks in every stage: unreleased input
/// keeps the run from looking quiescent anyway. An idle task stops ticking
/// once the sources are exhausted, so that ticks cannot hold off shutdown.
async fn tick<B: Bolt>(
    bolt: &mut B,
    t: &mut BoltTask,
    next_tick: &mut Option<Instant>,
    now: Instant,
    busy: bool,
) -> Result<(), BoxError> {
    let Some(period) = t.tick else { return Ok(()) };
    *next_tick = Some(now + period);
    let control = t.common.control.clone();
    control.ticking.store(true, Ordering::SeqCst);
    let result = if busy || control.stage() < Stage::Drain {
        let blocked_before = t.common.emitter.stats.blocked;
        let start = Instant::now();
        control.call_progressed(start);
        t.common.emitter.clock = start;
        let result = bolt.tick(&mut t.common.emitter).await;
        control.call_ended();
        // What the tick emitted (a failed one too: its emits stand, as
        // they would unbatched), and whatever was held, is handed over
        // before the tick is over.
        let flushed = t.common.emitter.flush(None).await;
        t.busy_until(start, blocked_before, Instant::now());
        result.and(flushed.map_err(BoxError::from))
    } else {
        Ok(())
    };
    control.ticking.store(false, Ordering::SeqCst);
    result
}

/// Runs a bolt task until it is told to exit or abort.
pub(crate) async fn run_bolt<B: Bolt>(bolt: &mut B, t: &mut BoltTask) -> Result<(), BoxError> {
    bolt.prepare(&t.common.ctx).await?;
    let mut next_tick = t.tick.map(|p| Instant::now() + p);
    let sample = t.execute_sample.max(1);
    loop {
        // One clock read starts the batch; the first tuple and one in
        // `sample` of the rest are timed alone (two more reads each); the
        // batch's busy time is measured whole.
        let mut start = Instant::now();
        let mut clock = start;
        let mut blocked = t.common.emitter.stats.blocked;
        t.common.emitter.clock = start;
        let control = t.common.control.clone();
        let mut executed = 0usize;
        // Whether the last tuple timed took long enough that timing each
        // one costs nothing that matters (and ticks are checked between
        // every two of them).
        let mut slow = false;
        let mut timed = false;
        while let Some(tuple) = t.batch.pop_front() {
            timed = slow || executed.is_multiple_of(sample);
            if timed {
                if executed > 0 {
                    clock = Instant::now();
                }
                // The stall watchdog counts from here: an untimed tuple
                // follows a timed one that took under 2 µs, at most
                // `sample` tuples back.
                control.call_progressed(clock);
            }
            t.execute(bolt, tuple).await?;
            executed += 1;
            if timed {
                let now = Instant::now();
                let took = now - clock;
                slow = took >= TIME_EACH_ABOVE;
                t.common.emitter.stats.latency.saturating_record((took.as_nanos() as u64).max(1));
                clock = now;
                if clock >= t.common.next_detail {
                    // A batch of slow tuples still shows its progress.
                    t.busy_until(start, blocked, clock);
                    (start, blocked) = (clock, t.common.emitter.stats.blocked);
                    t.common.publish(clock);
                }
                if next_tick.is_some_and(|due| clock >= due) {
                    // A busy task still ticks, between tuples.
                    control.call_ended();
                    t.busy_until(start, blocked, clock);
                    tick(bolt, t, &mut next_tick, clock, true).await?;
                    clock = Instant::now();
                    (start, blocked) = (clock, t.common.emitter.stats.blocked);
                    t.common.emitter.clock = clock;
                }
            }
            if t.holding() && t.holdable[t.batch_from] && !t.batch.is_empty() {
                t.park_batch();
            }
        }
        control.call_ended();
        let end = if timed || executed == 0 { clock } else { Instant::now() };
        t.busy_until(start, blocked, end);
        // Held tuples due by now are handed over before the input they
        // came from is released.
        let flush_blocked = t.common.emitter.stats.blocked;
        t.common.emitter.flush(Some(end)).await?;
        if t.common.emitter.stats.blocked != flush_blocked {
            t.busy_until(end, flush_blocked, Instant::now());
        }
        t.common.publish(end);
        // The flush published what is still held (what lingers): the
        // input it came from can be given back.
        t.release_batch();
        let stage = t.common.control.stage();
        if stage >= Stage::Abort {
            return Ok(());
        }
        if stage >= Stage::Finish && !t.common.finished {
            t.common.emitter.clock = Instant::now();
            bolt.finish(&mut t.common.emitter).await?;
            t.common.emitter.flush(None).await?;
            t.common.finished = true;
            t.common.report(EventKind::Finished);
        }
        if stage >= Stage::Exit {
            return Ok(());
        }
        if next_tick.is_some_and(|due| Instant::now() >= due) {
            tick(bolt, t, &mut next_tick, Instant::now(), false).await?;
            continue;
        }
        if t.take_batch() {
            continue;
        }
        // No input waiting: nothing is held while this task waits.
        t.common.emitter.flush(None).await?;
        if t.take_batch() || t.spin_for_input() {
            continue;
        }
        let signal = t.common.control.signal.clone();
        signal.announce_park();
        if t.take_batch() {
            signal.unpark();
            continue;
        }
        let due =
            [next_tick.filter(|_| stage < Stage::Drain), t.common.detail_due()].into_iter().flatten().min();
        match due {
            Some(due) => {
                tokio::select! {
                    () = signal.wait() => {}
                    () = tokio::time::sleep_until(due.into()) => {}
                }
            }
            None => signal.wait().await,
        }
        signal.unpark();
    }
}

/// A spout task's state, kept across restarts.
#[derive(Debug)]
pub(crate) struct SpoutTask {
    pub(crate) common: TaskCommon,
    pub(crate) acking: Option<(Arc<AckTracker>, AckPolicy)>,
    pub(crate) progress: Option<Arc<Progress>>,
    stop: Arc<StopRequest>,
    exhausted: bool,
    reported_done: bool,
    settled: Vec<(u64, Outcome, Option<Replay>)>,
    last_expiry: Instant,
}

impl SpoutTask {
    pub(crate) fn new(
        common: TaskCommon,
        acking: Option<(Arc<AckTracker>, AckPolicy)>,
        progress: Option<Arc<Progress>>,
        stop: Arc<StopRequest>,
    ) -> Self {
        SpoutTask {
            common,
            acking,
            progress,
            stop,
            exhausted: false,
            reported_done: false,
            settled: Vec::new(),
            last_expiry: Instant::now(),
        }
    }

    /// Acks, fails and replays what settled; returns the roots still open.
    async fn settle<S: Spout>(&mut self, spout: &mut S) -> Result<usize, BoxError> {
        let Some((tracker, policy)) = self.acking.clone() else {
            return Ok(0);
        };
        let now = Instant::now();
        if now.duration_since(self.last_expiry) >= ACK_POLL {
            tracker.expire(now);
            self.last_expiry = now;
        }
        tracker.take_finished(&mut self.settled);
        for (seq, outcome, replay) in std::mem::take(&mut self.settled) {
            let stats = &mut self.common.emitter.stats;
            match outcome {
                Outcome::Acked => {
                    stats.acked += 1;
                    spout.ack(MessageId(seq));
                }
                Outcome::Failed => {
                    stats.failed += 1;
                    spout.fail(MessageId(seq));
                    match replay {
                        Some(r) if r.attempt < policy.max_retries => {
                            self.common.emitter.stats.replayed += 1;
                            self.common.emitter.replay(r).await?;
                        }
                        _ => stats.abandoned += 1,
                    }
                }
            }
        }
        Ok(tracker.pending())
    }
}

/// Runs a spout task until it is told to exit or abort.
pub(crate) async fn run_spout<S: Spout>(spout: &mut S, t: &mut SpoutTask) -> Result<(), BoxError> {
    spout.open(&t.common.ctx).await?;
    loop {
        let stage = t.common.control.stage();
        if stage >= Stage::Abort {
            return Ok(());
        }
        if stage >= Stage::Finish && !t.common.finished {
            spout.close().await?;
            t.common.emitter.flush(None).await?;
            t.common.finished = true;
            t.common.report(EventKind::Finished);
        }
        if stage >= Stage::Exit {
            return Ok(());
        }
        let pending = t.settle(spout).await?;
        if t.stop.is_made() {
            t.exhausted = true;
        }
        let max_pending = t.acking.as_ref().map_or(usize::MAX, |(_, p)| p.max_pending);
        let signal = t.common.control.signal.clone();
        let calling = !t.exhausted && pending < max_pending;
        if !calling {
            // About to wait (for acks, or for the end): nothing is held.
            t.common.emitter.flush(None).await?;
        }
        if calling {
            let before = t.common.emitter.stats.emitted;
            let blocked_before = t.common.emitter.stats.blocked;
            let start = Instant::now();
            t.common.emitter.clock = start;
            let status = spout.next(&mut t.common.emitter).await?;
            let mut end = Instant::now();
            let emitted = t.common.emitter.stats.emitted - before;
            // A call that emitted nothing, or the last, hands over all that
            // is held: the source is about to wait or end. Otherwise what
            // has lingered long enough goes.
            let idle = emitted == 0 || status == SpoutStatus::Done;
            t.common.emitter.flush(if idle { None } else { Some(end) }).await?;
            if t.common.emitter.holds_tuples() || t.common.emitter.stats.blocked != blocked_before {
                end = Instant::now();
            }
            let stats = &mut t.common.emitter.stats;
            stats.busy += (end - start).saturating_sub(stats.blocked - blocked_before);
            t.common.publish(end);
            if let Some(p) = &t.progress {
                p.emitted.fetch_add(emitted, Ordering::Relaxed);
            }
            if status == SpoutStatus::Done {
                t.exhausted = true;
            } else if emitted == 0 {
                tokio::task::yield_now().await;
            }
        } else if t.exhausted && pending == 0 && !t.reported_done {
            t.reported_done = true;
            t.common.report(EventKind::SpoutDone);
        } else if pending > 0 {
            let _ = tokio::time::timeout(ACK_POLL, signal.wait()).await;
        } else if let Some(due) = t.common.detail_due() {
            let _ = tokio::time::timeout_at(due.into(), signal.wait()).await;
            t.common.publish(Instant::now());
        } else {
            signal.wait().await;
        }
    }
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic with a non-string payload".to_string())
}

/// How one incarnation of a task ended.
enum Incarnation {
    /// It ran to its end.
    Done,
    /// Its code returned an error.
    Failed(BoxError),
    /// It panicked, with this message.
    Panicked(String),
}

impl Incarnation {
    /// One run of a task's code, caught if it panics.
    fn of(run: impl FnOnce() -> Result<(), BoxError>) -> Self {
        match catch_unwind(AssertUnwindSafe(run)) {
            Ok(Ok(())) => Incarnation::Done,
            Ok(Err(e)) => Incarnation::Failed(e),
            Err(panic) => Incarnation::Panicked(panic_message(&*panic)),
        }
    }
}

/// Access to the state every task kind has.
pub(crate) trait HasCommon {
    fn common(&mut self) -> &mut TaskCommon;
}

impl HasCommon for BoltTask {
    fn common(&mut self) -> &mut TaskCommon {
        &mut self.common
    }
}

impl HasCommon for SpoutTask {
    fn common(&mut self) -> &mut TaskCommon {
        &mut self.common
    }
}

/// Runs one incarnation after another until the task ends, restarting after
/// a panic or error while the policy allows. Returns the final failure.
fn supervise<T: HasCommon>(
    task: &mut T,
    max_restarts: u32,
    mut run_once: impl FnMut(&mut T) -> Incarnation,
) -> Option<String> {
    loop {
        let failure = match run_once(task) {
            Incarnation::Done => return None,
            Incarnation::Failed(e) => format!("failed: {e}"),
            Incarnation::Panicked(panic) => format!("panicked: {panic}"),
        };
        let common = task.common();
        if let Some(live) = &common.live {
            live.failed_with(&failure);
        }
        if common.control.stage() >= Stage::Abort {
            return None;
        }
        if let Some(anchor) = common.emitter.anchor.take() {
            anchor.fail();
        }
        if common.emitter.stats.restarts >= max_restarts {
            return Some(failure);
        }
        common.emitter.stats.restarts += 1;
        warn!(
            component = common.ctx.component(),
            task = common.ctx.task_index(),
            restart = common.emitter.stats.restarts,
            "task {failure}; restarting it"
        );
    }
}

/// The body of a bolt task's thread.
pub(crate) fn bolt_thread(
    factory: BoltFactory,
    params: Params,
    mut task: BoltTask,
    runtime: Handle,
    max_restarts: u32,
) -> TaskOutcome {
    let started = Instant::now();
    let failure = supervise(&mut task, max_restarts, |task| {
        // A call that panicked never said it ended: the new incarnation
        // starts outside any call, or the stall watchdog would count the
        // idle time after a restart.
        task.common.control.call_ended();
        match factory(&params) {
            Ok(mut bolt) => Incarnation::of(|| bolt.run(task, &runtime)),
            Err(e) => Incarnation::Failed(format!("could not be created: {e}").into()),
        }
    });
    // Whatever is still queued, or taken in a batch and not yet executed,
    // can no longer be executed: counted as undelivered on its queue; so
    // are the tuples it still holds for others.
    task.common.emitter.abandon_held();
    task.discard_taken();
    task.release_batch();
    for q in &task.inbox {
        q.close().into_iter().for_each(Tuple::lost);
    }
    finish_thread(&mut task.common, failure, started, &task.inbox)
}

/// The body of a spout task's thread.
pub(crate) fn spout_thread(
    factory: SpoutFactory,
    params: Params,
    mut task: SpoutTask,
    runtime: Handle,
    max_restarts: u32,
) -> TaskOutcome {
    let started = Instant::now();
    let failure = supervise(&mut task, max_restarts, |task| match factory(&params) {
        Ok(mut spout) => Incarnation::of(|| spout.run(task, &runtime)),
        Err(e) => Incarnation::Failed(format!("could not be created: {e}").into()),
    });
    task.common.emitter.abandon_held();
    finish_thread(&mut task.common, failure, started, &[])
}

fn finish_thread(
    common: &mut TaskCommon,
    failure: Option<String>,
    started: Instant,
    inbox: &[Arc<EdgeQueue>],
) -> TaskOutcome {
    if let Some(message) = failure {
        common.report(EventKind::Failed(message));
    }
    common.emitter.stats.wall = started.elapsed();
    if let Some(live) = &common.live {
        live.publish_detail(&common.emitter.stats);
        live.exit();
    }
    let outcome = TaskOutcome {
        stats: std::mem::take(&mut common.emitter.stats),
        // The host reads its queues' losses once every thread has ended
        // (`Wiring::queue_losses`): a producer may add to them after this.
        dropped: 0,
        undelivered: 0,
        queue_depth_max: inbox.iter().map(|q| q.max_depth()).max().unwrap_or(0),
        lost: false,
    };
    common.report(EventKind::Exited);
    outcome
}
