//! A run watched while it runs: the counters, queue depths and rates a
//! live page reads, checked at points the test itself holds the run at.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use squall_topology::live::{LiveSnapshot, Sampler};
use squall_topology::{
    Bolt, BoxError, Declarer, Emitter, LiveRun, Params, Registry, RunOptions, Spout, SpoutStatus, Topology,
    TopologySpec, Tuple,
};

/// Emits 0, 1, … while `allowed` lets it, up to `count`.
struct Paced {
    next: u64,
    count: u64,
    allowed: Arc<AtomicU64>,
}

impl Spout for Paced {
    fn declare(&self, d: &mut Declarer) {
        d.output::<u64>("default");
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        if self.next == self.count {
            return Ok(SpoutStatus::Done);
        }
        if self.next < self.allowed.load(Ordering::SeqCst) {
            out.emit("default", self.next).await?;
            self.next += 1;
        } else {
            std::thread::yield_now();
        }
        Ok(SpoutStatus::Continue)
    }
}

/// Holds every tuple until `open`, then counts it and sets its gauge
/// `next` to one past it.
struct Gate {
    open: Arc<AtomicBool>,
}

impl Bolt for Gate {
    fn declare(&self, d: &mut Declarer) {
        d.input::<u64>();
    }

    async fn execute(&mut self, t: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        while !self.open.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(1));
        }
        out.count("passed", 1);
        out.gauge("next", t.get::<u64>().ok_or("a u64")? + 1);
        Ok(())
    }
}

const TOPOLOGY: &str = r#"
[topology]
name = "watched"

[[spout]]
name = "src"
kind = "paced"

[[bolt]]
name = "gate"
kind = "gate"
inputs = [ { from = "src", queue = 16 } ]
"#;

struct Run {
    allowed: Arc<AtomicU64>,
    open: Arc<AtomicBool>,
    live: Arc<LiveRun>,
    thread: std::thread::JoinHandle<squall_topology::RunReport>,
}

fn start(count: u64) -> Run {
    let allowed = Arc::new(AtomicU64::new(0));
    let open = Arc::new(AtomicBool::new(false));
    let mut registry = Registry::new();
    let a = allowed.clone();
    registry.register_spout("paced", move |_: &Params| Ok(Paced { next: 0, count, allowed: a.clone() }));
    let o = open.clone();
    registry.register_bolt("gate", move |_: &Params| Ok(Gate { open: o.clone() }));
    let spec = TopologySpec::parse("watched.toml", TOPOLOGY).unwrap();
    let topology = Topology::validate(spec, &registry).unwrap();
    let live = LiveRun::new();
    let options = RunOptions { live: Some(live.clone()), ..RunOptions::default() };
    let thread = std::thread::spawn(move || squall_topology::run(&topology, &options).unwrap());
    Run { allowed, open, live, thread }
}

/// Snapshots until `done` holds of one, or fails after 20 s: the run
/// gets there by itself (the test holds it at that point), only how soon
/// depends on the machine.
fn until(live: &LiveRun, what: &str, done: impl Fn(&LiveSnapshot) -> bool) -> LiveSnapshot {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        if let Some(s) = live.snapshot().filter(|s| done(s)) {
            return s;
        }
        assert!(Instant::now() < deadline, "the run never showed {what}: {:#?}", live.snapshot());
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn counts(s: &LiveSnapshot) -> (u64, u64, usize) {
    let src = s.report.component("src").unwrap();
    let gate = s.report.component("gate").unwrap();
    (src.emitted, gate.received, s.tasks[1][0].queue_depth)
}

#[test]
fn counters_and_queues_show_while_the_run_goes() {
    let run = start(10);
    until(&run.live, "its tasks", |_| true);
    let mut sampler = Sampler::new(run.live.clone());
    let first = sampler.sample().expect("the run has started");
    assert!(!first.snapshot.ended);
    assert_eq!(first.snapshot.graph.len(), 1);
    assert_eq!((first.snapshot.graph[0].from.as_str(), first.snapshot.graph[0].to.as_str()), ("src", "gate"));
    assert_eq!(first.snapshot.tasks[1][0].queue_bound, 16);

    // Five tuples out, all waiting at the closed gate: one in its hands
    // (taken, not yet released: its count shows once it is executed) and
    // the rest queued.
    run.allowed.store(5, Ordering::SeqCst);
    let held = until(&run.live, "five tuples at the gate", |s| counts(s).0 == 5 && counts(s).2 == 5);
    assert_eq!(held.report.component("gate").unwrap().custom.get("passed"), None);
    assert!(held.tasks[1][0].running);

    // The gate opens: everything passes, the queue empties, rates show it.
    run.open.store(true, Ordering::SeqCst);
    until(&run.live, "the five through the gate", |s| counts(s) == (5, 5, 0));
    let moving = sampler.sample().unwrap();
    assert!(moving.rates[0][0].out_per_s > 0.0, "{:?}", moving.rates);
    assert!(moving.rates[1][0].in_per_s > 0.0, "{:?}", moving.rates);
    let passed = until(&run.live, "the gate's own counter", |s| {
        s.report.component("gate").unwrap().custom.get("passed")
            == Some(&squall_topology::CustomMetric::Counter(5))
    });
    assert!(!passed.ended);
    // A gauge shows its last value, not a total of what it was set to.
    let gate = passed.report.component("gate").unwrap();
    assert_eq!(gate.custom.get("next"), Some(&squall_topology::CustomMetric::Gauge(5)));

    run.allowed.store(10, Ordering::SeqCst);
    let report = run.thread.join().unwrap();
    let last = run.live.snapshot().unwrap();
    assert!(last.ended);
    assert_eq!(counts(&last), (10, 10, 0));
    let gate = report.component("gate").unwrap();
    assert_eq!(gate.custom.get("next"), Some(&squall_topology::CustomMetric::Gauge(10)));
    assert_eq!(gate.custom.get("passed"), Some(&squall_topology::CustomMetric::Counter(10)));
    assert_eq!(last.report.wall_secs, report.wall_secs, "the final report stands once the run ended");
    assert!(last.tasks.iter().flatten().all(|t| !t.running));
}

#[test]
fn a_run_not_yet_started_has_no_snapshot() {
    let live = LiveRun::new();
    assert!(live.snapshot().is_none());
    assert!(Sampler::new(live).sample().is_none());
}
