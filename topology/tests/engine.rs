//! Behaviour of whole topologies on the in-process runtime: groupings,
//! backpressure, drop policies, acking, shutdown, failures, peers, feedback
//! and ticks. Components here record what they see into shared logs.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use squall_topology::{
    Bolt, BoxError, Declarer, Emitter, MessageId, ParamError, Params, Registry, RunError, RunOptions,
    RunReport, Spout, SpoutStatus, TaskContext, Topology, TopologySpec, Tuple,
};

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Num {
    seq: u64,
    key: u64,
}

/// What every recorder saw: (component, task, seq).
type Log = Arc<Mutex<Vec<(String, usize, u64)>>>;

/// When something happened, in the order it happened.
type Times = Arc<Mutex<Vec<Instant>>>;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
struct SourceParams {
    count: u64,
    keys: u64,
    /// Send each number directly to task `seq % direct_tasks`.
    direct_tasks: u64,
}

struct Numbers {
    p: SourceParams,
    next: u64,
    emitted: Arc<AtomicU64>,
    /// When each emit returned.
    emitted_at: Times,
    acked: Log,
    failed: Log,
}

impl Spout for Numbers {
    fn declare(&self, d: &mut Declarer) {
        d.output::<Num>("default");
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        if self.next == self.p.count {
            return Ok(SpoutStatus::Done);
        }
        let n = Num { seq: self.next, key: self.next % self.p.keys.max(1) };
        if self.p.direct_tasks > 0 {
            out.emit_direct("default", (self.next % self.p.direct_tasks) as usize, n).await?;
        } else {
            out.emit("default", n).await?;
        }
        self.emitted_at.lock().unwrap().push(Instant::now());
        self.next += 1;
        self.emitted.fetch_add(1, Ordering::SeqCst);
        Ok(SpoutStatus::Continue)
    }

    fn ack(&mut self, id: MessageId) {
        self.acked.lock().unwrap().push(("ack".into(), 0, id.0));
    }

    fn fail(&mut self, id: MessageId) {
        self.failed.lock().unwrap().push(("fail".into(), 0, id.0));
    }
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
struct RecorderParams {
    delay_us: u64,
    /// Fail the first n tuples (once each, by seq).
    fail_first: u64,
    /// Sleep this long on the first tuple (to force an ack timeout).
    stall_first_ms: u64,
    panic_at_seq: Option<u64>,
    forward: bool,
}

struct Recorder {
    p: RecorderParams,
    name: String,
    task: usize,
    log: Log,
    /// Spout emits minus tuples executed, sampled at each execute.
    in_flight_max: Arc<AtomicU64>,
    emitted: Arc<AtomicU64>,
    /// When each execute ended (before the bolt gives its queue slot back).
    executed_at: Times,
    executed: u64,
    failed_once: BTreeSet<u64>,
}

impl Bolt for Recorder {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Num>().output::<Num>("default");
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.name = ctx.component().to_string();
        self.task = ctx.task_index();
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let n = input.get::<Num>().unwrap().clone();
        let in_flight = self.emitted.load(Ordering::SeqCst).saturating_sub(self.executed);
        self.in_flight_max.fetch_max(in_flight, Ordering::SeqCst);
        if self.p.panic_at_seq == Some(n.seq) {
            panic!("boom at {}", n.seq);
        }
        if self.p.stall_first_ms > 0 && self.executed == 0 {
            std::thread::sleep(Duration::from_millis(self.p.stall_first_ms));
        }
        if self.p.delay_us > 0 {
            std::thread::sleep(Duration::from_micros(self.p.delay_us));
        }
        self.executed += 1;
        self.executed_at.lock().unwrap().push(Instant::now());
        if n.seq < self.p.fail_first && self.failed_once.insert(n.seq) {
            out.fail();
            return Ok(());
        }
        self.log.lock().unwrap().push((self.name.clone(), self.task, n.seq));
        if self.p.forward {
            out.emit("default", n).await?;
        }
        Ok(())
    }
}

struct Harness {
    log: Log,
    acked: Log,
    failed: Log,
    emitted: Arc<AtomicU64>,
    emitted_at: Times,
    executed_at: Times,
    in_flight_max: Arc<AtomicU64>,
}

impl Harness {
    fn new() -> Self {
        Harness {
            log: Default::default(),
            acked: Default::default(),
            failed: Default::default(),
            emitted: Default::default(),
            emitted_at: Default::default(),
            executed_at: Default::default(),
            in_flight_max: Default::default(),
        }
    }

    fn registry(&self) -> Registry {
        let mut r = Registry::new();
        let (emitted, acked, failed) = (self.emitted.clone(), self.acked.clone(), self.failed.clone());
        let emitted_at = self.emitted_at.clone();
        r.register_spout("numbers", move |p: &Params| {
            Ok(Numbers {
                p: p.parse()?,
                next: 0,
                emitted: emitted.clone(),
                emitted_at: emitted_at.clone(),
                acked: acked.clone(),
                failed: failed.clone(),
            })
        });
        let (log, in_flight_max, emitted) =
            (self.log.clone(), self.in_flight_max.clone(), self.emitted.clone());
        let executed_at = self.executed_at.clone();
        r.register_bolt("recorder", move |p: &Params| {
            Ok(Recorder {
                p: p.parse()?,
                name: String::new(),
                task: 0,
                log: log.clone(),
                in_flight_max: in_flight_max.clone(),
                emitted: emitted.clone(),
                executed_at: executed_at.clone(),
                executed: 0,
                failed_once: BTreeSet::new(),
            })
        });
        r
    }

    fn run(&self, toml: &str) -> Result<RunReport, RunError> {
        let spec = TopologySpec::parse("test.toml", toml).expect("valid spec");
        let topology = Topology::validate(spec, &self.registry()).expect("valid topology");
        squall_topology::run(&topology, &RunOptions::default())
    }

    /// Seqs seen per task of `component`.
    fn per_task(&self, component: &str) -> BTreeMap<usize, Vec<u64>> {
        let mut m: BTreeMap<usize, Vec<u64>> = BTreeMap::new();
        for (c, t, s) in self.log.lock().unwrap().iter() {
            if c == component {
                m.entry(*t).or_default().push(*s);
            }
        }
        m
    }
}

fn two_stage(count: u64, grouping: &str, tasks: usize, extra: &str) -> String {
    format!(
        r#"
[topology]
name = "t"

[[spout]]
name = "src"
kind = "numbers"
params = {{ count = {count}, keys = 10 {extra} }}

[[bolt]]
name = "b"
kind = "recorder"
parallelism = {tasks}
inputs = [ {{ from = "src", {grouping} }} ]
"#
    )
}

#[test]
fn shuffle_spreads_evenly() {
    for grouping in [r#"grouping = "shuffle""#, r#"grouping = "local_or_shuffle""#] {
        let h = Harness::new();
        h.run(&two_stage(3001, grouping, 3, "")).unwrap();
        let per_task = h.per_task("b");
        let sizes: Vec<usize> = per_task.values().map(Vec::len).collect();
        assert_eq!(sizes.iter().sum::<usize>(), 3001);
        assert!(sizes.iter().all(|&s| s == 1000 || s == 1001), "{grouping}: {sizes:?}");
    }
}

#[test]
fn fields_sends_each_key_to_one_task() {
    let h = Harness::new();
    h.run(&two_stage(2000, r#"grouping = "fields", fields = ["key"]"#, 3, "")).unwrap();
    let mut task_of_key: BTreeMap<u64, BTreeSet<usize>> = BTreeMap::new();
    let per_task = h.per_task("b");
    for (task, seqs) in &per_task {
        for s in seqs {
            task_of_key.entry(s % 10).or_default().insert(*task);
        }
    }
    assert_eq!(task_of_key.len(), 10);
    assert!(task_of_key.values().all(|tasks| tasks.len() == 1), "{task_of_key:?}");
    assert!(per_task.len() > 1, "10 keys over 3 tasks should use more than one task");
}

#[test]
fn all_broadcasts_and_global_picks_task_zero() {
    let h = Harness::new();
    h.run(&two_stage(500, r#"grouping = "all""#, 3, "")).unwrap();
    let per_task = h.per_task("b");
    assert_eq!(per_task.len(), 3);
    for seqs in per_task.values() {
        assert_eq!(seqs, &(0..500).collect::<Vec<_>>());
    }

    let h = Harness::new();
    h.run(&two_stage(500, r#"grouping = "global""#, 3, "")).unwrap();
    let per_task = h.per_task("b");
    assert_eq!(per_task.keys().copied().collect::<Vec<_>>(), vec![0]);
    assert_eq!(per_task[&0].len(), 500);
}

#[test]
fn direct_reaches_the_named_task() {
    let h = Harness::new();
    h.run(&two_stage(300, r#"grouping = "direct""#, 3, ", direct_tasks = 3")).unwrap();
    for (task, seqs) in h.per_task("b") {
        assert_eq!(seqs.len(), 100);
        assert!(seqs.iter().all(|s| s % 3 == task as u64), "task {task}: {seqs:?}");
    }
}

#[test]
fn direct_subscriber_rejects_an_emit_without_task() {
    let h = Harness::new();
    let err = h.run(&two_stage(10, r#"grouping = "direct""#, 2, "")).unwrap_err();
    let message = err.to_string();
    assert!(message.starts_with("spout \"src\" task 0 failed"), "{message}");
    assert!(message.contains("direct subscriber"), "{message}");
}

/// A fast spout feeding one bolt that sleeps `delay_us` per tuple through a
/// `queue`-slot queue with `policy`.
fn slow_bolt(count: u64, queue: usize, policy: &str, delay_us: u64) -> String {
    slow_bolt_batched(count, queue, policy, delay_us, "")
}

/// As [`slow_bolt`], the edge batched as `batch` says (e.g.
/// `, batch = { max = 1 }`).
fn slow_bolt_batched(count: u64, queue: usize, policy: &str, delay_us: u64, batch: &str) -> String {
    two_stage(count, &format!(r#"grouping = "shuffle", queue = {queue}, policy = "{policy}"{batch}"#), 1, "")
        .replace("kind = \"recorder\"", &format!("kind = \"recorder\"\nparams = {{ delay_us = {delay_us} }}"))
}

#[test]
fn block_bounds_in_flight_and_slows_the_spout() {
    // Batched (the default), a tuple the spout has emitted may also wait
    // in its batch: this spout emits one per `next` call, and a call's
    // batch is handed over when it returns, so one more is in flight.
    let h = Harness::new();
    h.run(&slow_bolt(50, 4, "block", 1000)).unwrap();
    let in_flight = h.in_flight_max.load(Ordering::SeqCst);
    assert!(in_flight <= 4 + 1, "in flight {in_flight}");

    let h = Harness::new();
    let count = 200;
    let report = h.run(&slow_bolt_batched(count, 4, "block", 1000, ", batch = { max = 1 }")).unwrap();
    assert!(
        h.in_flight_max.load(Ordering::SeqCst) <= 4,
        "in flight {}",
        h.in_flight_max.load(Ordering::SeqCst)
    );
    assert!(report.component("b").unwrap().queue_depth_max <= 4);
    assert_eq!(report.component("b").unwrap().received, count);
    // The spout was slowed to the bolt's pace: when an emit returned, the
    // bolt had executed all but the queue's 4 slots' worth of what the
    // spout had sent (a `block` queue counts the tuples the bolt holds
    // until it has executed them). An emit that did not wait would be a
    // hundred tuples ahead of a bolt that takes 1 ms per tuple.
    let (emitted_at, executed_at) = (h.emitted_at.lock().unwrap(), h.executed_at.lock().unwrap());
    assert_eq!((emitted_at.len(), executed_at.len()), (count as usize, count as usize));
    for (i, sent) in emitted_at.iter().enumerate() {
        let executed = executed_at.iter().filter(|done| *done <= sent).count();
        let ahead = (i + 1).saturating_sub(executed);
        assert!(ahead <= 4, "when tuple {i} was emitted the spout was {ahead} tuples ahead of the bolt");
    }
    // That it waited rather than worked shows as back-pressure (time a
    // loaded machine takes from the spout only adds to it); its busy share
    // is not asserted: a preempted spout counts as busy.
    let spout = &report.component("src").unwrap().per_task[0];
    assert!(spout.backpressure_pct > 0.0, "a blocked spout waits: {spout:?}");
}

#[test]
fn drop_oldest_keeps_newest_and_counts_exactly() {
    let h = Harness::new();
    let count = 500;
    let report = h.run(&slow_bolt(count, 2, "drop_oldest", 200)).unwrap();
    let seen = &h.per_task("b")[&0];
    let b = report.component("b").unwrap();
    assert!(b.dropped > 0, "a slow bolt behind a 2-slot queue must drop");
    assert_eq!(b.received + b.dropped, count, "every tuple is either executed or counted as dropped");
    assert_eq!(seen.len() as u64, b.received);
    assert!(seen.windows(2).all(|w| w[0] < w[1]), "order is kept");
    assert_eq!(*seen.last().unwrap(), count - 1, "the newest tuple is never the one dropped");
}

#[test]
fn drop_newest_counts_exactly() {
    let h = Harness::new();
    let count = 500;
    let report = h.run(&slow_bolt(count, 2, "drop_newest", 200)).unwrap();
    let b = report.component("b").unwrap();
    assert!(b.dropped > 0);
    assert_eq!(b.received + b.dropped, count);
    assert_eq!(h.per_task("b")[&0][..2], [0, 1], "the oldest tuples are kept");
}

#[test]
fn batched_edges_account_for_every_tuple_and_keep_order_under_every_policy() {
    let count = 3000;
    for policy in ["block", "drop_oldest", "drop_newest"] {
        for batch in ["{ max = 1 }", "{ max = 7 }", "{ max = 64, linger_us = 300 }", "{}"] {
            let h = Harness::new();
            let toml = format!(
                r#"
[topology]
name = "chain"

[[spout]]
name = "src"
kind = "numbers"
params = {{ count = {count} }}

[[bolt]]
name = "a"
kind = "recorder"
params = {{ forward = true }}
inputs = [ {{ from = "src", queue = 8, batch = {batch} }} ]

[[bolt]]
name = "b"
kind = "recorder"
parallelism = 2
params = {{ delay_us = 20 }}
inputs = [ {{ from = "a", queue = 4, policy = "{policy}", batch = {batch} }} ]
"#
            );
            let report = h.run(&toml).unwrap();
            let what = format!("{policy}, batch = {batch}");
            let (src, a, b) = (
                report.component("src").unwrap(),
                report.component("a").unwrap(),
                report.component("b").unwrap(),
            );
            assert_eq!(src.emitted, count, "{what}");
            // Every tuple emitted on an edge is executed or counted lost.
            assert_eq!((a.received, a.dropped, a.undelivered), (count, 0, 0), "{what}");
            assert_eq!(a.emitted, count, "{what}");
            assert_eq!(b.received + b.dropped, a.emitted, "{what}");
            assert_eq!(b.undelivered, 0, "{what}");
            if policy == "block" {
                assert_eq!(b.dropped, 0, "{what}");
            }
            // One producer per edge: each consumer task sees its tuples in
            // the order they were emitted (the `block` source edge in
            // front of a fast relay, a policy's edge before a slow pair).
            for (task, seqs) in h.per_task("b").into_iter().chain(h.per_task("a")) {
                assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{what}: task {task} out of order");
            }
        }
    }
}

fn acked(count: u64, bolt_params: &str, ack: &str) -> String {
    format!(
        r#"
[topology]
name = "acked"

[[spout]]
name = "src"
kind = "numbers"
params = {{ count = {count} }}
ack = {ack}

[[bolt]]
name = "mid"
kind = "recorder"
parallelism = 2
params = {{ forward = true }}
inputs = [ {{ from = "src" }} ]

[[bolt]]
name = "b"
kind = "recorder"
params = {bolt_params}
inputs = [ {{ from = "mid" }} ]
"#
    )
}

#[test]
fn acking_replays_failed_tuples() {
    let h = Harness::new();
    let report = h.run(&acked(100, "{ fail_first = 5 }", "{ timeout_secs = 30 }")).unwrap();
    let src = report.component("src").unwrap();
    assert_eq!((src.acked, src.failed, src.replayed, src.abandoned), (100, 5, 5, 0));
    let acked: BTreeSet<u64> = h.acked.lock().unwrap().iter().map(|a| a.2).collect();
    assert_eq!(acked, (0..100).collect());
    let failed: Vec<u64> = h.failed.lock().unwrap().iter().map(|a| a.2).collect();
    assert_eq!(failed.len(), 5);
    // Each failed tuple reached the end once, on its replay.
    let mut seen = h.per_task("b")[&0].clone();
    seen.sort();
    assert_eq!(seen, (0..100).collect::<Vec<_>>());
}

#[test]
fn acking_replays_timed_out_tuples() {
    let h = Harness::new();
    // Retries enough that none is given up while the bolt stalls, however
    // late a loaded machine lets the pipeline answer.
    let report =
        h.run(&acked(20, "{ stall_first_ms = 300 }", "{ timeout_secs = 0.1, max_retries = 1000 }")).unwrap();
    let src = report.component("src").unwrap();
    assert_eq!(src.acked, 20);
    assert!(src.failed >= 1 && src.replayed >= 1, "failed {} replayed {}", src.failed, src.replayed);
    assert_eq!(src.abandoned, 0);
}

#[test]
fn acking_counts_abandoned_tuples() {
    let h = Harness::new();
    let report = h.run(&acked(10, "{ fail_first = 1 }", "{ timeout_secs = 30, max_retries = 0 }")).unwrap();
    let src = report.component("src").unwrap();
    assert_eq!((src.acked, src.failed, src.abandoned), (9, 1, 1));
    assert!(report.warnings.iter().any(|w| w.contains("abandoned")), "{:?}", report.warnings);
}

#[test]
fn nothing_is_lost_across_shutdown() {
    let h = Harness::new();
    let toml = r#"
[topology]
name = "chain"

[[spout]]
name = "src"
kind = "numbers"
parallelism = 2
params = { count = 20000 }

[[bolt]]
name = "a"
kind = "recorder"
parallelism = 3
params = { forward = true }
inputs = [ { from = "src", queue = 16 } ]

[[bolt]]
name = "b"
kind = "recorder"
parallelism = 2
params = { forward = true }
inputs = [ { from = "a", grouping = "fields", fields = ["key"], queue = 16 } ]

[[bolt]]
name = "c"
kind = "recorder"
inputs = [ { from = "b", queue = 16 } ]
"#;
    let report = h.run(toml).unwrap();
    for name in ["a", "b", "c"] {
        let c = report.component(name).unwrap();
        assert_eq!((c.received, c.dropped, c.undelivered), (40000, 0, 0), "{name}");
    }
    assert_eq!(report.component("src").unwrap().emitted, 40000);
}

#[test]
fn a_panicking_bolt_fails_the_run_with_its_name() {
    let h = Harness::new();
    let toml = two_stage(1000, r#"grouping = "shuffle""#, 2, "")
        .replace("kind = \"recorder\"", "kind = \"recorder\"\nparams = { panic_at_seq = 500 }");
    match h.run(&toml) {
        Err(RunError::TaskFailed { component, message, report, .. }) => {
            assert_eq!(component, "b");
            assert!(message.contains("panicked: boom at 500"), "{message}");
            assert!(report.component("b").is_some());
        }
        other => panic!("expected a task failure, got {other:?}"),
    }
}

#[test]
fn a_restart_policy_keeps_the_run_going() {
    let h = Harness::new();
    let toml = two_stage(1000, r#"grouping = "shuffle""#, 1, "").replace(
        "kind = \"recorder\"",
        "kind = \"recorder\"\nparams = { panic_at_seq = 500 }\nrestart = { max_restarts = 1 }",
    );
    let report = h.run(&toml).unwrap();
    let b = report.component("b").unwrap();
    assert_eq!(b.restarts, 1);
    // The tuple that caused the panic is the only one not recorded, but
    // it was received: every tuple emitted is received or counted lost.
    assert_eq!(h.per_task("b")[&0].len(), 999);
    assert_eq!(b.received, 1000, "the panicking execute counts as received");
    assert_eq!(report.component("src").unwrap().emitted, b.received + b.dropped + b.undelivered);
}

// ---- peers, feedback, ticks ----

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Greeting {
    from: usize,
    round: u64,
}

/// Each task, on every input number, greets every other task by index.
struct Greeter {
    task: usize,
    count: usize,
    log: Log,
}

impl Bolt for Greeter {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Num>().peer::<Greeting>();
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.task = ctx.task_index();
        self.count = ctx.task_count();
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        if let Some(n) = input.get::<Num>() {
            for peer in (0..self.count).filter(|&p| p != self.task) {
                out.send_peer(peer, Greeting { from: self.task, round: n.seq }).await?;
            }
        } else if let Some(g) = input.get::<Greeting>() {
            assert_eq!(input.source_task(), g.from);
            self.log.lock().unwrap().push((format!("from{}", g.from), self.task, g.round));
        }
        Ok(())
    }
}

#[test]
fn peers_exchange_by_index() {
    let h = Harness::new();
    let mut r = h.registry();
    let log = h.log.clone();
    r.register_bolt("greeter", move |_: &Params| Ok(Greeter { task: 0, count: 0, log: log.clone() }));
    let toml = two_stage(50, r#"grouping = "all""#, 3, "").replace("\"recorder\"", "\"greeter\"");
    let topology = Topology::validate(TopologySpec::parse("t.toml", &toml).unwrap(), &r).unwrap();
    squall_topology::run(&topology, &RunOptions::default()).unwrap();
    let log = h.log.lock().unwrap();
    assert_eq!(log.len(), 50 * 3 * 2, "each of 3 tasks greets 2 peers per number");
    for task in 0..3 {
        for from in (0..3).filter(|&f| f != task) {
            let n = log.iter().filter(|(c, t, _)| *c == format!("from{from}") && *t == task).count();
            assert_eq!(n, 50);
        }
    }
}

/// Forwards numbers while seq < limit, incrementing: with a feedback edge to
/// itself-through-a-relay this makes a bounded loop.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Hop {
    origin: u64,
    hops: u64,
}

struct Looper {
    limit: u64,
    log: Log,
}

impl Bolt for Looper {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Num>().input::<Hop>().output::<Hop>("default").output::<Hop>("done");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let hop = match input.get::<Num>() {
            Some(n) => Hop { origin: n.seq, hops: 0 },
            None => input.get::<Hop>().unwrap().clone(),
        };
        if hop.hops < self.limit {
            out.emit("default", Hop { origin: hop.origin, hops: hop.hops + 1 }).await?;
        } else {
            self.log.lock().unwrap().push(("done".into(), 0, hop.origin));
        }
        Ok(())
    }
}

struct Relay;

impl Bolt for Relay {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Hop>().output::<Hop>("default");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let hop = input.into_arc::<Hop>().unwrap();
        out.emit_shared("default", hop).await?;
        Ok(())
    }
}

#[test]
fn feedback_loops_finish() {
    let h = Harness::new();
    let mut r = h.registry();
    let log = h.log.clone();
    r.register_bolt("looper", move |_: &Params| Ok(Looper { limit: 5, log: log.clone() }));
    r.register_bolt("relay", |_: &Params| Ok::<_, ParamError>(Relay));
    let toml = r#"
[topology]
name = "loop"

[[spout]]
name = "src"
kind = "numbers"
params = { count = 200 }

[[bolt]]
name = "looper"
kind = "looper"
parallelism = 2
inputs = [ { from = "src" }, { from = "relay", feedback = true } ]

[[bolt]]
name = "relay"
kind = "relay"
inputs = [ { from = "looper" } ]
"#;
    let topology = Topology::validate(TopologySpec::parse("t.toml", toml).unwrap(), &r).unwrap();

    let report = squall_topology::run(&topology, &RunOptions::default()).unwrap();
    let mut done: Vec<u64> = h.log.lock().unwrap().iter().map(|e| e.2).collect();
    done.sort();
    assert_eq!(done, (0..200).collect::<Vec<_>>(), "every number made all its hops");
    assert_eq!(report.component("relay").unwrap().received, 200 * 5);
    assert_eq!(report.component("looper").unwrap().undelivered, 0);
}

/// Takes one number, sends it round the relay and holds its inputs until
/// it comes back: at most one number is ever outstanding.
struct Gatekeeper {
    outstanding: u64,
    most_outstanding: Arc<AtomicU64>,
    log: Log,
}

impl Bolt for Gatekeeper {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Num>().input::<Hop>().output::<Hop>("default");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        if let Some(n) = input.get::<Num>() {
            self.outstanding += 1;
            self.most_outstanding.fetch_max(self.outstanding, Ordering::SeqCst);
            out.emit("default", Hop { origin: n.seq, hops: 1 }).await?;
            out.hold_inputs(true);
        } else {
            let hop = input.get::<Hop>().unwrap();
            self.outstanding -= 1;
            self.log.lock().unwrap().push(("back".into(), 0, hop.origin));
            out.hold_inputs(false);
        }
        Ok(())
    }
}

#[test]
fn a_bolt_holding_its_inputs_takes_only_feedback_until_it_lets_go() {
    let h = Harness::new();
    let mut r = h.registry();
    let (log, most) = (h.log.clone(), Arc::new(AtomicU64::new(0)));
    let m = most.clone();
    r.register_bolt("gatekeeper", move |_: &Params| {
        Ok(Gatekeeper { outstanding: 0, most_outstanding: m.clone(), log: log.clone() })
    });
    r.register_bolt("relay", |_: &Params| Ok::<_, ParamError>(Relay));
    let toml = r#"
[topology]
name = "gate"

[[spout]]
name = "src"
kind = "numbers"
params = { count = 300 }

[[bolt]]
name = "gate"
kind = "gatekeeper"
inputs = [ { from = "src", queue = 8 }, { from = "relay", feedback = true } ]

[[bolt]]
name = "relay"
kind = "relay"
inputs = [ { from = "gate" } ]
"#;
    let topology = Topology::validate(TopologySpec::parse("t.toml", toml).unwrap(), &r).unwrap();
    let report = squall_topology::run(&topology, &RunOptions::default()).unwrap();
    let back: Vec<u64> = h.log.lock().unwrap().iter().map(|e| e.2).collect();
    assert_eq!(back, (0..300).collect::<Vec<_>>(), "every number, in order, nothing lost");
    assert_eq!(most.load(Ordering::SeqCst), 1, "a number arrived while the inputs were held");
    let gate = report.component("gate").unwrap();
    assert_eq!((gate.received, gate.dropped), (600, 0));
}

/// Sleeps 2 ms per tuple and counts its 1 ms ticks.
struct Ticker {
    ticks: Arc<AtomicU64>,
    ticks_after_finish: Arc<AtomicU64>,
    finished: bool,
}

impl Bolt for Ticker {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Num>().tick(Duration::from_millis(1));
    }

    async fn execute(&mut self, _input: Tuple, _out: &mut Emitter) -> Result<(), BoxError> {
        std::thread::sleep(Duration::from_millis(2));
        Ok(())
    }

    async fn tick(&mut self, _out: &mut Emitter) -> Result<(), BoxError> {
        let counter = if self.finished { &self.ticks_after_finish } else { &self.ticks };
        counter.fetch_add(1, Ordering::SeqCst);
        Ok(())
    }

    async fn finish(&mut self, _out: &mut Emitter) -> Result<(), BoxError> {
        self.finished = true;
        Ok(())
    }
}

#[test]
fn ticks_fire_while_the_run_lasts_and_stop_at_shutdown() {
    let h = Harness::new();
    let mut r = h.registry();
    let (ticks, late) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let (t, l) = (ticks.clone(), late.clone());
    r.register_bolt("ticker", move |_: &Params| {
        Ok(Ticker { ticks: t.clone(), ticks_after_finish: l.clone(), finished: false })
    });
    let toml = two_stage(30, r#"grouping = "shuffle""#, 1, "").replace("\"recorder\"", "\"ticker\"");
    let topology = Topology::validate(TopologySpec::parse("t.toml", &toml).unwrap(), &r).unwrap();
    squall_topology::run(&topology, &RunOptions::default()).unwrap();
    // 30 tuples × 2 ms: the run lasts 60 ms or more, ticks are due every 1 ms
    // and are checked between batches of tuples.
    assert!(ticks.load(Ordering::SeqCst) >= 3, "{} ticks", ticks.load(Ordering::SeqCst));
    assert_eq!(late.load(Ordering::SeqCst), 0, "no tick after finish");
}
