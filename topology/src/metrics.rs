//! Per-task and per-component run metrics, and the summary table.

use std::collections::BTreeMap;
use std::fmt;
use std::time::Duration;

use hdrhistogram::Histogram;
use serde::Serialize;

use crate::spec::Role;

/// The largest value a histogram tracks: 1 hour, in ns.
pub(crate) const HISTOGRAM_HIGHEST: u64 = 3_600_000_000_000;
/// The significant digits a histogram keeps.
pub(crate) const HISTOGRAM_DIGITS: u8 = 3;

/// Histogram bounds: 1 ns .. 1 hour, 3 significant digits.
pub(crate) fn new_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, HISTOGRAM_HIGHEST, HISTOGRAM_DIGITS).expect("valid histogram bounds")
}

/// What one task counts while it runs (owned by the task's thread).
#[derive(Debug, Clone)]
pub(crate) struct TaskStats {
    pub(crate) received: u64,
    pub(crate) emitted: u64,
    /// Time in the component's own code, excluding `blocked`.
    pub(crate) busy: Duration,
    /// Time emits waited for room in full `block` queues (backpressure).
    pub(crate) blocked: Duration,
    pub(crate) wall: Duration,
    pub(crate) latency: Histogram<u64>,
    pub(crate) restarts: u32,
    pub(crate) acked: u64,
    pub(crate) failed: u64,
    pub(crate) replayed: u64,
    pub(crate) abandoned: u64,
    pub(crate) custom: BTreeMap<String, Custom>,
}

/// A metric a component records itself (`Emitter::count`,
/// `Emitter::record`, `Emitter::gauge`).
#[derive(Debug, Clone)]
pub(crate) enum Custom {
    Counter(u64),
    Values(Box<Histogram<u64>>),
    /// The last value set: a level (bytes held, particles owned), not a
    /// total.
    Gauge(u64),
    /// A quantity measured or chosen once (a calibration), in the unit
    /// its name says.
    Measured(f64),
}

impl Default for TaskStats {
    fn default() -> Self {
        TaskStats {
            received: 0,
            emitted: 0,
            busy: Duration::ZERO,
            blocked: Duration::ZERO,
            wall: Duration::ZERO,
            latency: new_histogram(),
            restarts: 0,
            acked: 0,
            failed: 0,
            replayed: 0,
            abandoned: 0,
            custom: BTreeMap::new(),
        }
    }
}

impl TaskStats {
    pub(crate) fn count(&mut self, name: &str, delta: u64) {
        match self.custom.get_mut(name) {
            Some(Custom::Counter(c)) => *c += delta,
            Some(_) => {}
            None => {
                self.custom.insert(name.to_string(), Custom::Counter(delta));
            }
        }
    }

    pub(crate) fn record(&mut self, name: &str, value: u64) {
        match self.custom.get_mut(name) {
            Some(Custom::Values(h)) => h.saturating_record(value.max(1)),
            Some(_) => {}
            None => {
                let mut h = Box::new(new_histogram());
                h.saturating_record(value.max(1));
                self.custom.insert(name.to_string(), Custom::Values(h));
            }
        }
    }

    pub(crate) fn measured(&mut self, name: &str, value: f64) {
        match self.custom.get_mut(name) {
            Some(Custom::Measured(m)) => *m = value,
            Some(_) => {}
            None => {
                self.custom.insert(name.to_string(), Custom::Measured(value));
            }
        }
    }

    pub(crate) fn gauge(&mut self, name: &str, value: u64) {
        match self.custom.get_mut(name) {
            Some(Custom::Gauge(g)) => *g = value,
            Some(_) => {}
            None => {
                self.custom.insert(name.to_string(), Custom::Gauge(value));
            }
        }
    }
}

/// Percentiles of a latency histogram, in microseconds.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct Latency {
    /// Samples.
    pub count: u64,
    /// Mean.
    pub mean_us: f64,
    /// Median.
    pub p50_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// Maximum.
    pub max_us: f64,
}

impl Latency {
    pub(crate) fn of(h: &Histogram<u64>) -> Self {
        if h.is_empty() {
            return Latency::default();
        }
        let us = |ns: u64| ns as f64 / 1e3;
        Latency {
            count: h.len(),
            mean_us: h.mean() / 1e3,
            p50_us: us(h.value_at_quantile(0.5)),
            p99_us: us(h.value_at_quantile(0.99)),
            max_us: us(h.max()),
        }
    }
}

/// A summary of a recorded custom metric.
#[derive(Debug, Clone, Serialize, PartialEq)]
#[serde(untagged)]
pub enum CustomMetric {
    /// A counter's total.
    Counter(u64),
    /// Recorded values.
    Values {
        /// Samples.
        count: u64,
        /// Mean.
        mean: f64,
        /// Standard deviation.
        sd: f64,
        /// Median.
        p50: u64,
        /// 99th percentile.
        p99: u64,
        /// Maximum.
        max: u64,
    },
    /// A level's last value, summed over a component's tasks (a number in
    /// metrics.json, as a counter is; Prometheus types it as a gauge).
    Gauge(u64),
    /// A quantity the component measured or chose once (a calibration,
    /// such as the laser's clock offset), in the unit its name says; over
    /// tasks, the first task's.
    Measured(f64),
}

pub(crate) fn summarize_custom(custom: &BTreeMap<String, Custom>) -> BTreeMap<String, CustomMetric> {
    custom
        .iter()
        .map(|(k, v)| {
            let m = match v {
                Custom::Counter(c) => CustomMetric::Counter(*c),
                Custom::Gauge(g) => CustomMetric::Gauge(*g),
                Custom::Measured(m) => CustomMetric::Measured(*m),
                Custom::Values(h) => CustomMetric::Values {
                    count: h.len(),
                    mean: h.mean(),
                    sd: h.stdev(),
                    p50: h.value_at_quantile(0.5),
                    p99: h.value_at_quantile(0.99),
                    max: h.max(),
                },
            };
            (k.clone(), m)
        })
        .collect()
}

/// Metrics of one task.
#[derive(Debug, Clone, Serialize)]
pub struct TaskReport {
    /// Task index.
    pub task: usize,
    /// Tuples handed to `execute` (bolts), one that panicked or failed
    /// included.
    pub received: u64,
    /// Emit calls.
    pub emitted: u64,
    /// Tuples lost to drop policies at this task's inputs.
    pub dropped: u64,
    /// Tuples that reached this task after it exited (or at an abort).
    pub undelivered: u64,
    /// Execute latency.
    pub execute: Latency,
    /// Time spent in the component's code over wall time, percent
    /// (waiting on backpressure excluded).
    pub busy_pct: f64,
    /// Time emits waited on full downstream queues over wall time, percent.
    pub backpressure_pct: f64,
    /// Deepest input queue seen.
    pub queue_depth_max: usize,
    /// Restarts after panics.
    pub restarts: u32,
    /// Acked tuple trees (spouts with acking).
    pub acked: u64,
    /// Failed tuple trees.
    pub failed: u64,
    /// Replays.
    pub replayed: u64,
    /// Trees given up after the retry limit.
    pub abandoned: u64,
    /// The component's own metrics.
    pub custom: BTreeMap<String, CustomMetric>,
    /// The task's thread never returned (it was stuck when the run was
    /// abandoned): its counters could not be collected and read 0.
    /// Written only when true.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub lost: bool,
}

/// Metrics of one component (sums over tasks; latency over all tuples).
#[derive(Debug, Clone, Serialize)]
pub struct ComponentReport {
    /// Component name.
    pub name: String,
    /// Registry kind.
    pub kind: String,
    /// Spout or bolt.
    pub role: Role,
    /// Parallelism.
    pub tasks: usize,
    /// Tuples handed to `execute`, over its tasks.
    pub received: u64,
    /// Emit calls.
    pub emitted: u64,
    /// Tuples lost to drop policies.
    pub dropped: u64,
    /// Tuples that could not be delivered.
    pub undelivered: u64,
    /// Execute latency over all tasks.
    pub execute: Latency,
    /// Mean busy percent over tasks.
    pub busy_pct: f64,
    /// Mean backpressure percent over tasks.
    pub backpressure_pct: f64,
    /// Deepest input queue of any task.
    pub queue_depth_max: usize,
    /// Restarts after panics.
    pub restarts: u32,
    /// Acked trees.
    pub acked: u64,
    /// Failed trees.
    pub failed: u64,
    /// Replays.
    pub replayed: u64,
    /// Abandoned trees.
    pub abandoned: u64,
    /// Custom counters and gauges summed over tasks, value metrics
    /// merged.
    pub custom: BTreeMap<String, CustomMetric>,
    /// Each task.
    pub per_task: Vec<TaskReport>,
}

/// Everything measured in one run; `squall run` writes it as `metrics.json`.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Topology name.
    pub topology: String,
    /// Run seed.
    pub seed: u64,
    /// How execute latencies were sampled: the first tuple of each batch
    /// a task took, one in this many of the rest, and every tuple after
    /// one that took 2 µs or more were timed (`[topology]
    /// execute_sample`; 1: every tuple).
    pub execute_sample: usize,
    /// Wall time of the run.
    pub wall_secs: f64,
    /// Peak resident memory of this process when the report was made,
    /// MiB (Linux's `VmHWM`; absent where the system does not report it).
    /// In cluster mode, the coordinator's process only. A parent's own
    /// memory does not count here, unlike in the `ru_maxrss` a parent
    /// reads when it reaps the process.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_rss_mb: Option<f64>,
    /// Components in file order.
    pub components: Vec<ComponentReport>,
    /// Things the user should know (undelivered tuples, abandoned trees).
    pub warnings: Vec<String>,
    /// Traffic between processes, per edge (cluster runs only).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub edges: Vec<EdgeReport>,
}

/// The traffic of one edge between processes: every tuple that crossed
/// from a task of `from` to a task of `to` in another process.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct EdgeReport {
    /// The producing component.
    pub from: String,
    /// The stream (`peer` for messages between tasks of one component).
    pub stream: String,
    /// The consuming component.
    pub to: String,
    /// Tuples sent.
    pub messages: u64,
    /// Frames they travelled in (a producer's batch is one frame).
    pub frames: u64,
    /// Their encoded bytes (frame headers included).
    pub bytes: u64,
    /// Time spent serializing them, in total.
    pub encode_ms: f64,
    /// Time spent deserializing them, in total.
    pub decode_ms: f64,
    /// Tuples a producer task held for a task in another process and
    /// never sent, because it ended first (a failure, an abort); also
    /// counted in the consumer's `undelivered`.
    pub undelivered: u64,
}

/// What the runtime collected for one task.
#[derive(Debug, Clone)]
pub(crate) struct TaskOutcome {
    pub(crate) stats: TaskStats,
    pub(crate) dropped: u64,
    pub(crate) undelivered: u64,
    pub(crate) queue_depth_max: usize,
    /// The task's thread never returned (stuck when the run was
    /// abandoned): its counters could not be collected and read 0.
    pub(crate) lost: bool,
}

pub(crate) fn task_report(task: usize, o: &TaskOutcome) -> TaskReport {
    let s = &o.stats;
    TaskReport {
        task,
        received: s.received,
        emitted: s.emitted,
        dropped: o.dropped,
        undelivered: o.undelivered,
        execute: Latency::of(&s.latency),
        busy_pct: percent(s.busy, s.wall),
        backpressure_pct: percent(s.blocked, s.wall),
        queue_depth_max: o.queue_depth_max,
        restarts: s.restarts,
        acked: s.acked,
        failed: s.failed,
        replayed: s.replayed,
        abandoned: s.abandoned,
        custom: summarize_custom(&s.custom),
        lost: o.lost,
    }
}

fn percent(part: Duration, whole: Duration) -> f64 {
    if whole.is_zero() { 0.0 } else { 100.0 * part.as_secs_f64() / whole.as_secs_f64() }
}

pub(crate) fn component_report(
    name: &str,
    kind: &str,
    role: Role,
    outcomes: &[TaskOutcome],
) -> ComponentReport {
    let mut latency = new_histogram();
    let mut custom: BTreeMap<String, Custom> = BTreeMap::new();
    for o in outcomes {
        latency.add(&o.stats.latency).expect("same bounds");
        for (k, v) in &o.stats.custom {
            match (custom.get_mut(k), v) {
                (Some(Custom::Counter(a)), Custom::Counter(b))
                | (Some(Custom::Gauge(a)), Custom::Gauge(b)) => *a += b,
                (Some(Custom::Values(a)), Custom::Values(b)) => a.add(&**b).expect("same bounds"),
                (None, v) => {
                    custom.insert(k.clone(), v.clone());
                }
                _ => {}
            }
        }
    }
    let per_task: Vec<TaskReport> = outcomes.iter().enumerate().map(|(i, o)| task_report(i, o)).collect();
    let latency = Latency::of(&latency);
    summed_component(name, kind, role, per_task, latency, summarize_custom(&custom))
}

/// A component's report from its tasks' reports: counts summed, busy and
/// backpressure averaged over tasks, with the given latency and own
/// metrics (which do not add up task by task).
pub(crate) fn summed_component(
    name: &str,
    kind: &str,
    role: Role,
    per_task: Vec<TaskReport>,
    execute: Latency,
    custom: BTreeMap<String, CustomMetric>,
) -> ComponentReport {
    let n = per_task.len().max(1) as f64;
    let sum = |f: fn(&TaskReport) -> u64| per_task.iter().map(f).sum::<u64>();
    ComponentReport {
        name: name.to_string(),
        kind: kind.to_string(),
        role,
        tasks: per_task.len(),
        received: sum(|t| t.received),
        emitted: sum(|t| t.emitted),
        dropped: sum(|t| t.dropped),
        undelivered: sum(|t| t.undelivered),
        execute,
        busy_pct: per_task.iter().map(|t| t.busy_pct).sum::<f64>() / n,
        backpressure_pct: per_task.iter().map(|t| t.backpressure_pct).sum::<f64>() / n,
        queue_depth_max: per_task.iter().map(|t| t.queue_depth_max).max().unwrap_or(0),
        restarts: per_task.iter().map(|t| t.restarts).sum(),
        acked: sum(|t| t.acked),
        failed: sum(|t| t.failed),
        replayed: sum(|t| t.replayed),
        abandoned: sum(|t| t.abandoned),
        custom,
        per_task,
    }
}

/// This process's peak resident memory, MiB, from `/proc/self/status`
/// (`None` where there is no such file or line).
pub fn peak_rss_mb() -> Option<f64> {
    crate::runtime::memory::status_kib("VmHWM:").map(|kib| kib as f64 / 1024.0)
}

impl RunReport {
    /// The component called `name`.
    pub fn component(&self, name: &str) -> Option<&ComponentReport> {
        self.components.iter().find(|c| c.name == name)
    }

    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("reports serialize")
    }
}

/// The per-component summary table printed at the end of a run.
impl fmt::Display for RunReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "topology \"{}\" (seed {}) ran {:.3} s", self.topology, self.seed, self.wall_secs)?;
        writeln!(
            f,
            "{:<18} {:>5} {:>12} {:>12} {:>9} {:>11} {:>11} {:>7}",
            "component", "tasks", "received", "emitted", "dropped", "p50 exec", "p99 exec", "busy"
        )?;
        for c in &self.components {
            let (p50, p99) = if c.role == Role::Bolt {
                (format_us(c.execute.p50_us), format_us(c.execute.p99_us))
            } else {
                ("-".to_string(), "-".to_string())
            };
            writeln!(
                f,
                "{:<18} {:>5} {:>12} {:>12} {:>9} {:>11} {:>11} {:>6.1}%",
                c.name, c.tasks, c.received, c.emitted, c.dropped, p50, p99, c.busy_pct
            )?;
        }
        for w in &self.warnings {
            writeln!(f, "warning: {w}")?;
        }
        Ok(())
    }
}

fn format_us(us: f64) -> String {
    if us >= 1e6 {
        format!("{:.2} s", us / 1e6)
    } else if us >= 1e3 {
        format!("{:.2} ms", us / 1e3)
    } else {
        format!("{us:.1} µs")
    }
}
