//! Metrics of a run while it runs: what a live page, a Prometheus scrape,
//! a periodic `metrics.json` and the run log read before the run ends.
//!
//! Each task keeps its counters on its own thread (`TaskStats`, plain
//! integers) and publishes them to its `TaskLive` after every batch a
//! bolt executes and every `next` of a spout: relaxed stores of single
//! words, no lock and no read-modify-write, so that watching costs the
//! hot path next to nothing. What costs more (latency percentiles, which
//! walk a histogram, and the component's own metrics, behind a lock) is
//! published at most every `DETAIL_PERIOD` (0.5 s). Queue depths and drops are
//! read from the queues themselves. A reader takes a [`LiveSnapshot`] at
//! any time; a [`Sampler`] turns two snapshots into rates.
//!
//! A run is watched only when its [`RunOptions`](crate::RunOptions) carry
//! a [`LiveRun`]; otherwise tasks publish nothing.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::metrics::{
    ComponentReport, CustomMetric, Latency, RunReport, TaskReport, TaskStats, summarize_custom,
    summed_component,
};
use crate::plan::Topology;
use crate::runtime::queue::EdgeQueue;
use crate::spec::Role;

/// How often a task publishes its latency percentiles and its own
/// metrics.
pub(crate) const DETAIL_PERIOD: Duration = Duration::from_millis(500);

/// One task's published counters.
#[derive(Debug, Default)]
pub(crate) struct TaskLive {
    received: AtomicU64,
    emitted: AtomicU64,
    busy_ns: AtomicU64,
    blocked_ns: AtomicU64,
    restarts: AtomicU32,
    acked: AtomicU64,
    failed: AtomicU64,
    replayed: AtomicU64,
    abandoned: AtomicU64,
    exited: AtomicBool,
    detail: Mutex<Detail>,
}

/// What a task publishes under a lock, at most every [`DETAIL_PERIOD`].
#[derive(Debug, Default, Clone)]
struct Detail {
    execute: Latency,
    custom: BTreeMap<String, CustomMetric>,
    last_error: Option<String>,
}

impl TaskLive {
    /// Publishes the counters (cheap: a store per counter).
    pub(crate) fn publish(&self, s: &TaskStats) {
        let r = Ordering::Relaxed;
        self.received.store(s.received, r);
        self.emitted.store(s.emitted, r);
        self.busy_ns.store(s.busy.as_nanos() as u64, r);
        self.blocked_ns.store(s.blocked.as_nanos() as u64, r);
        self.restarts.store(s.restarts, r);
        self.acked.store(s.acked, r);
        self.failed.store(s.failed, r);
        self.replayed.store(s.replayed, r);
        self.abandoned.store(s.abandoned, r);
    }

    /// Publishes the counters, the latency percentiles and the
    /// component's own metrics.
    pub(crate) fn publish_detail(&self, s: &TaskStats) {
        self.publish(s);
        let execute = Latency::of(&s.latency);
        let custom = summarize_custom(&s.custom);
        let mut d = self.detail.lock().unwrap_or_else(|e| e.into_inner());
        d.execute = execute;
        d.custom = custom;
    }

    /// Records why the task's last incarnation ended.
    pub(crate) fn failed_with(&self, message: &str) {
        self.detail.lock().unwrap_or_else(|e| e.into_inner()).last_error = Some(message.to_string());
    }

    /// Marks the task's thread as ended.
    pub(crate) fn exit(&self) {
        self.exited.store(true, Ordering::Relaxed);
    }
}

/// A run being watched: made by the caller, handed to the runtime in
/// [`RunOptions::live`](crate::RunOptions::live), read from any thread.
#[derive(Debug)]
pub struct LiveRun {
    started: Instant,
    layout: OnceLock<Layout>,
    outcome: Mutex<Option<RunReport>>,
    /// Cluster runs: each worker host as last heard from.
    hosts: Mutex<BTreeMap<u16, HostHeard>>,
}

#[derive(Debug)]
struct Layout {
    topology: String,
    seed: u64,
    execute_sample: usize,
    components: Vec<LiveComponent>,
}

#[derive(Debug)]
struct LiveComponent {
    name: String,
    kind: String,
    role: Role,
    inputs: Vec<GraphEdge>,
    tasks: Vec<LiveTask>,
}

#[derive(Debug)]
struct LiveTask {
    published: Arc<TaskLive>,
    inbox: Vec<Arc<EdgeQueue>>,
    /// What the task's host last reported, when it runs in another
    /// process (cluster mode): (host, report).
    remote: Mutex<Option<(u16, RemoteTask)>>,
}

/// One task as its process reports it to the coordinator each second in
/// a cluster run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct RemoteTask {
    /// Its counters, as metrics.json has them.
    pub received: u64,
    /// Emit calls.
    pub emitted: u64,
    /// Drops at its inputs.
    pub dropped: u64,
    /// Undelivered at its inputs.
    pub undelivered: u64,
    /// Execute latency p50, µs.
    pub p50_us: f64,
    /// Execute latency p99, µs.
    pub p99_us: f64,
    /// Time in its code, ns.
    pub busy_ns: u64,
    /// Time its emits waited, ns.
    pub blocked_ns: u64,
    /// Restarts.
    pub restarts: u32,
    /// Tuples in its input queues now.
    pub queue_depth: u64,
    /// Their bounds, summed.
    pub queue_bound: u64,
    /// Deepest its queues have been.
    pub queue_depth_max: u64,
    /// Whether its thread runs.
    pub running: bool,
    /// Why its last incarnation failed.
    pub last_error: Option<String>,
    /// Its own counters.
    pub counters: Vec<(String, u64)>,
    /// Its own gauges.
    pub gauges: Vec<(String, u64)>,
    /// Its own measured quantities.
    pub measured: Vec<(String, f64)>,
}

/// A host of a cluster run as the coordinator last heard from it.
#[derive(Debug, Clone)]
struct HostHeard {
    tasks: usize,
    at: Instant,
    edges: Vec<crate::metrics::EdgeReport>,
}

impl Default for LiveRun {
    fn default() -> Self {
        LiveRun {
            started: Instant::now(),
            layout: OnceLock::new(),
            outcome: Mutex::new(None),
            hosts: Mutex::new(BTreeMap::new()),
        }
    }
}

impl LiveRun {
    /// A run to watch; its clock starts now.
    pub fn new() -> Arc<Self> {
        Arc::new(LiveRun::default())
    }

    /// Registers the run's tasks when the runtime has built its queues
    /// (the first call; a host starting tasks again, as a cluster's
    /// coordinator replacing a lost worker's, gets the same slots);
    /// returns each task's slot, `[component][task]`.
    pub(crate) fn attach(
        &self,
        topology: &Topology,
        inboxes: &[Vec<Vec<Arc<EdgeQueue>>>],
    ) -> Vec<Vec<Arc<TaskLive>>> {
        let layout = self.layout.get_or_init(|| Self::layout_of(topology, inboxes));
        layout.components.iter().map(|c| c.tasks.iter().map(|t| t.published.clone()).collect()).collect()
    }

    fn layout_of(topology: &Topology, inboxes: &[Vec<Vec<Arc<EdgeQueue>>>]) -> Layout {
        let components: Vec<LiveComponent> = topology
            .components
            .iter()
            .zip(inboxes)
            .map(|(p, inboxes)| LiveComponent {
                name: p.spec.name.clone(),
                kind: p.spec.kind.clone(),
                role: p.spec.role,
                inputs: p
                    .spec
                    .inputs
                    .iter()
                    .map(|i| GraphEdge {
                        from: i.from.clone(),
                        stream: i.stream.clone(),
                        to: p.spec.name.clone(),
                        grouping: i.grouping.to_string(),
                        feedback: i.feedback,
                    })
                    .collect(),
                tasks: inboxes
                    .iter()
                    .map(|inbox| LiveTask {
                        published: Arc::default(),
                        inbox: inbox.clone(),
                        remote: Mutex::new(None),
                    })
                    .collect(),
            })
            .collect();
        Layout {
            topology: topology.spec.name.clone(),
            seed: topology.spec.seed,
            execute_sample: topology.spec.execute_sample,
            components,
        }
    }

    /// The tasks for which `here(component, task)` holds, as this process
    /// reports them to a cluster's coordinator (empty before the run has
    /// started).
    pub fn report_tasks(&self, here: impl Fn(usize, usize) -> bool) -> Vec<(u32, u32, RemoteTask)> {
        let Some(layout) = self.layout.get() else { return Vec::new() };
        let elapsed = self.started.elapsed();
        let mut out = Vec::new();
        for (c, lc) in layout.components.iter().enumerate() {
            for (t, task) in lc.tasks.iter().enumerate().filter(|(t, _)| here(c, *t)) {
                let (r, s) = task_now(t, task, elapsed);
                let own = |gauges: bool| {
                    r.custom
                        .iter()
                        .filter_map(|(k, v)| match v {
                            CustomMetric::Counter(n) if !gauges => Some((k.clone(), *n)),
                            CustomMetric::Gauge(gauge) if gauges => Some((k.clone(), *gauge)),
                            _ => None,
                        })
                        .collect()
                };
                let (counters, gauges) = (own(false), own(true));
                let measured = r
                    .custom
                    .iter()
                    .filter_map(|(k, v)| match v {
                        CustomMetric::Measured(m) => Some((k.clone(), *m)),
                        _ => None,
                    })
                    .collect();
                let remote = RemoteTask {
                    received: r.received,
                    emitted: r.emitted,
                    dropped: r.dropped,
                    undelivered: r.undelivered,
                    p50_us: r.execute.p50_us,
                    p99_us: r.execute.p99_us,
                    busy_ns: s.busy_ns,
                    blocked_ns: s.blocked_ns,
                    restarts: r.restarts,
                    queue_depth: s.queue_depth as u64,
                    queue_bound: s.queue_bound as u64,
                    queue_depth_max: r.queue_depth_max as u64,
                    running: s.running,
                    last_error: s.last_error,
                    counters,
                    gauges,
                    measured,
                };
                out.push((c as u32, t as u32, remote));
            }
        }
        out
    }

    /// Takes in what worker `host` reported of its tasks, and the traffic
    /// it sent to other processes so far (cluster mode, on the
    /// coordinator). Tasks that are not in the run are left out.
    pub fn absorb(
        &self,
        host: u16,
        tasks: Vec<(u32, u32, RemoteTask)>,
        edges: Vec<crate::metrics::EdgeReport>,
    ) {
        let Some(layout) = self.layout.get() else { return };
        let count = tasks.len();
        for (c, t, report) in tasks {
            if let Some(task) = layout.components.get(c as usize).and_then(|lc| lc.tasks.get(t as usize)) {
                *task.remote.lock().unwrap_or_else(|e| e.into_inner()) = Some((host, report));
            }
        }
        let heard = HostHeard { tasks: count, at: Instant::now(), edges };
        self.hosts.lock().unwrap_or_else(|e| e.into_inner()).insert(host, heard);
    }

    /// Takes in the traffic this process (host `host`, a cluster's
    /// coordinator) has sent to others so far.
    pub fn absorb_traffic(&self, host: u16, tasks: usize, edges: Vec<crate::metrics::EdgeReport>) {
        let heard = HostHeard { tasks, at: Instant::now(), edges };
        self.hosts.lock().unwrap_or_else(|e| e.into_inner()).insert(host, heard);
    }

    /// Records the run's final report: snapshots show it from now on.
    pub fn finish(&self, report: &RunReport) {
        *self.outcome.lock().unwrap_or_else(|e| e.into_inner()) = Some(report.clone());
    }

    /// Everything published so far; `None` before the run has started.
    pub fn snapshot(&self) -> Option<LiveSnapshot> {
        let layout = self.layout.get()?;
        let elapsed = self.started.elapsed();
        let final_report = self.outcome.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let mut components = Vec::with_capacity(layout.components.len());
        let mut queues = Vec::with_capacity(layout.components.len());
        for lc in &layout.components {
            let mut per_task = Vec::with_capacity(lc.tasks.len());
            let mut now = Vec::with_capacity(lc.tasks.len());
            for (t, task) in lc.tasks.iter().enumerate() {
                let (report, state) = task_now(t, task, elapsed);
                per_task.push(report);
                now.push(state);
            }
            components.push(component_of(lc, per_task));
            queues.push(now);
        }
        // Once the run has ended its own report stands (it holds what the
        // last publication missed).
        let ended = final_report.is_some();
        let report = match final_report {
            Some(done) => done,
            None => RunReport {
                topology: layout.topology.clone(),
                seed: layout.seed,
                execute_sample: layout.execute_sample,
                wall_secs: elapsed.as_secs_f64(),
                peak_rss_mb: crate::metrics::peak_rss_mb(),
                components,
                warnings: Vec::new(),
                edges: Vec::new(),
            },
        };
        let heard = self.hosts.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let hosts = heard
            .iter()
            .map(|(&host, h)| HostNow { host, tasks: h.tasks, heard_secs_ago: h.at.elapsed().as_secs_f64() })
            .collect();
        let mut edges: BTreeMap<(String, String, String), crate::metrics::EdgeReport> = BTreeMap::new();
        for e in heard.values().flat_map(|h| &h.edges) {
            let sum = edges.entry((e.from.clone(), e.stream.clone(), e.to.clone())).or_insert_with(|| {
                crate::metrics::EdgeReport {
                    from: e.from.clone(),
                    stream: e.stream.clone(),
                    to: e.to.clone(),
                    ..Default::default()
                }
            });
            sum.messages += e.messages;
            sum.frames += e.frames;
            sum.bytes += e.bytes;
            sum.encode_ms += e.encode_ms;
            sum.decode_ms += e.decode_ms;
            sum.undelivered += e.undelivered;
        }
        Some(LiveSnapshot {
            elapsed_secs: elapsed.as_secs_f64(),
            ended,
            graph: layout.components.iter().flat_map(|c| c.inputs.iter().cloned()).collect(),
            tasks: queues,
            hosts,
            edges: edges.into_values().collect(),
            report,
        })
    }
}

fn task_now(t: usize, task: &LiveTask, elapsed: Duration) -> (TaskReport, TaskState) {
    if let Some((host, r)) = task.remote.lock().unwrap_or_else(|e| e.into_inner()).clone() {
        return remote_now(t, host, r, elapsed);
    }
    let p = &task.published;
    let r = Ordering::Relaxed;
    let detail = p.detail.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let wall = elapsed.as_nanos().max(1) as f64;
    let inbox = &task.inbox;
    let report = TaskReport {
        task: t,
        received: p.received.load(r),
        emitted: p.emitted.load(r),
        dropped: inbox.iter().map(|q| q.counters.dropped.load(r)).sum(),
        undelivered: inbox.iter().map(|q| q.counters.undelivered.load(r)).sum(),
        execute: detail.execute,
        busy_pct: 100.0 * p.busy_ns.load(r) as f64 / wall,
        backpressure_pct: 100.0 * p.blocked_ns.load(r) as f64 / wall,
        queue_depth_max: inbox.iter().map(|q| q.max_depth()).max().unwrap_or(0),
        restarts: p.restarts.load(r),
        acked: p.acked.load(r),
        failed: p.failed.load(r),
        replayed: p.replayed.load(r),
        abandoned: p.abandoned.load(r),
        custom: detail.custom,
        lost: false,
    };
    let state = TaskState {
        queue_depth: inbox.iter().map(|q| q.depth()).sum(),
        queue_bound: inbox.iter().map(|q| q.capacity()).sum(),
        busy_ns: p.busy_ns.load(r),
        blocked_ns: p.blocked_ns.load(r),
        running: !p.exited.load(r),
        last_error: detail.last_error,
        host: None,
    };
    (report, state)
}

/// A task of another process as its host last reported it.
fn remote_now(t: usize, host: u16, r: RemoteTask, elapsed: Duration) -> (TaskReport, TaskState) {
    let wall = elapsed.as_nanos().max(1) as f64;
    let report = TaskReport {
        task: t,
        received: r.received,
        emitted: r.emitted,
        dropped: r.dropped,
        undelivered: r.undelivered,
        execute: Latency { p50_us: r.p50_us, p99_us: r.p99_us, ..Latency::default() },
        busy_pct: 100.0 * r.busy_ns as f64 / wall,
        backpressure_pct: 100.0 * r.blocked_ns as f64 / wall,
        queue_depth_max: r.queue_depth_max as usize,
        restarts: r.restarts,
        acked: 0,
        failed: 0,
        replayed: 0,
        abandoned: 0,
        custom: (r.counters.into_iter().map(|(k, v)| (k, CustomMetric::Counter(v))))
            .chain(r.gauges.into_iter().map(|(k, gauge)| (k, CustomMetric::Gauge(gauge))))
            .chain(r.measured.into_iter().map(|(k, m)| (k, CustomMetric::Measured(m))))
            .collect(),
        lost: false,
    };
    let state = TaskState {
        queue_depth: r.queue_depth as usize,
        queue_bound: r.queue_bound as usize,
        busy_ns: r.busy_ns,
        blocked_ns: r.blocked_ns,
        running: r.running,
        last_error: r.last_error,
        host: Some(host),
    };
    (report, state)
}

fn component_of(lc: &LiveComponent, per_task: Vec<TaskReport>) -> ComponentReport {
    // Percentiles do not add up over tasks; the component shows its
    // slowest task's (what a capacity question asks about). Of its own
    // metrics, the counters and gauges add up.
    let execute =
        per_task.iter().map(|t| t.execute).max_by(|a, b| a.p99_us.total_cmp(&b.p99_us)).unwrap_or_default();
    let mut custom: BTreeMap<String, CustomMetric> = BTreeMap::new();
    for t in &per_task {
        for (k, v) in &t.custom {
            match (custom.get_mut(k), v) {
                (Some(CustomMetric::Counter(a)), CustomMetric::Counter(b))
                | (Some(CustomMetric::Gauge(a)), CustomMetric::Gauge(b)) => *a += b,
                (None, CustomMetric::Counter(_) | CustomMetric::Gauge(_) | CustomMetric::Measured(_)) => {
                    custom.insert(k.clone(), v.clone());
                }
                _ => {}
            }
        }
    }
    summed_component(&lc.name, &lc.kind, lc.role, per_task, execute, custom)
}

/// One subscription of the topology's graph.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct GraphEdge {
    /// The producing component.
    pub from: String,
    /// Its stream.
    pub stream: String,
    /// The consuming component.
    pub to: String,
    /// How tuples are spread over the consumer's tasks.
    pub grouping: String,
    /// Whether the edge closes a cycle on purpose.
    pub feedback: bool,
}

/// What a task is doing now (beyond its counters).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TaskState {
    /// Tuples in its input queues now.
    pub queue_depth: usize,
    /// Its input queues' bounds, summed.
    pub queue_bound: usize,
    /// Time in the component's code so far, ns.
    pub busy_ns: u64,
    /// Time its emits waited on full queues so far, ns.
    pub blocked_ns: u64,
    /// Whether its thread is still running.
    pub running: bool,
    /// Why its last incarnation failed, if one did.
    pub last_error: Option<String>,
    /// The worker host it runs on, in a cluster run (`None`: this
    /// process).
    pub host: Option<u16>,
}

/// A worker of a cluster run, as the coordinator last heard from it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct HostNow {
    /// Its index in the cluster file (0 is the coordinator).
    pub host: u16,
    /// The tasks it reported.
    pub tasks: usize,
    /// Since its last report.
    pub heard_secs_ago: f64,
}

/// A run as it stands.
#[derive(Debug, Clone, Serialize)]
pub struct LiveSnapshot {
    /// Since the run was started.
    pub elapsed_secs: f64,
    /// Whether the run has ended (its final report is shown).
    pub ended: bool,
    /// Every subscription.
    pub graph: Vec<GraphEdge>,
    /// `[component][task]`: queues and state now.
    pub tasks: Vec<Vec<TaskState>>,
    /// Cluster runs: the workers heard from.
    pub hosts: Vec<HostNow>,
    /// Cluster runs: traffic between processes so far, per edge.
    pub edges: Vec<crate::metrics::EdgeReport>,
    /// The counters as `metrics.json` has them (cumulative).
    pub report: RunReport,
}

/// Rates of one task over the last interval between two snapshots.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct TaskRates {
    /// Tuples executed per second.
    pub in_per_s: f64,
    /// Tuples emitted per second.
    pub out_per_s: f64,
    /// Time in the component's code, percent of the interval.
    pub busy_pct: f64,
    /// Time emits waited on full queues, percent of the interval.
    pub backpressure_pct: f64,
    /// Tuples dropped per second.
    pub dropped_per_s: f64,
}

/// `s` with every count and time at 0: the run as it started.
fn at_start(s: &LiveSnapshot) -> LiveSnapshot {
    let mut start = s.clone();
    start.elapsed_secs = 0.0;
    for c in &mut start.report.components {
        for t in &mut c.per_task {
            (t.received, t.emitted, t.dropped) = (0, 0, 0);
        }
    }
    for t in start.tasks.iter_mut().flatten() {
        (t.busy_ns, t.blocked_ns) = (0, 0);
    }
    start
}

/// A snapshot with the rates since the one before.
#[derive(Debug, Clone, Serialize)]
pub struct LiveSample {
    /// The run as it stands.
    #[serde(flatten)]
    pub snapshot: LiveSnapshot,
    /// `[component][task]`.
    pub rates: Vec<Vec<TaskRates>>,
}

/// Takes snapshots of one run and the rates between them.
#[derive(Debug)]
pub struct Sampler {
    run: Arc<LiveRun>,
    last: Option<LiveSnapshot>,
}

impl Sampler {
    /// A sampler of `run`.
    pub fn new(run: Arc<LiveRun>) -> Self {
        Sampler { run, last: None }
    }

    /// A snapshot now, with rates since the last sample (since the run
    /// started, for the first); `None` before the run has started.
    pub fn sample(&mut self) -> Option<LiveSample> {
        let now = self.run.snapshot()?;
        let rates = rates(self.last.as_ref(), &now);
        self.last = Some(now.clone());
        Some(LiveSample { snapshot: now, rates })
    }
}

/// Per-task rates from `before` to `now` (from the run's start, where
/// every count was 0, without `before`).
pub fn rates(before: Option<&LiveSnapshot>, now: &LiveSnapshot) -> Vec<Vec<TaskRates>> {
    let shape = |s: &LiveSnapshot| s.tasks.iter().map(Vec::len).collect::<Vec<_>>();
    let start;
    let before = match before.filter(|b| shape(b) == shape(now)) {
        Some(b) => b,
        None => {
            start = at_start(now);
            &start
        }
    };
    let dt = (now.elapsed_secs - before.elapsed_secs).max(1e-9);
    let per_s = |a: u64, b: u64| a.saturating_sub(b) as f64 / dt;
    let pct = |a: u64, b: u64| (100.0 * a.saturating_sub(b) as f64 / (dt * 1e9)).min(100.0);
    now.report
        .components
        .iter()
        .zip(&before.report.components)
        .zip(now.tasks.iter().zip(&before.tasks))
        .map(|((c, cb), (s, sb))| {
            c.per_task
                .iter()
                .zip(&cb.per_task)
                .zip(s.iter().zip(sb))
                .map(|((t, tb), (st, stb))| TaskRates {
                    in_per_s: per_s(t.received, tb.received),
                    out_per_s: per_s(t.emitted, tb.emitted),
                    busy_pct: pct(st.busy_ns, stb.busy_ns),
                    backpressure_pct: pct(st.blocked_ns, stb.blocked_ns),
                    dropped_per_s: per_s(t.dropped, tb.dropped),
                })
                .collect()
        })
        .collect()
}
