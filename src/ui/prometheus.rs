//! The run's metrics in the Prometheus (OpenMetrics) text format, encoded
//! from a fresh snapshot at every scrape.

use std::sync::Arc;

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::registry::{Registry, Unit};
use squall_topology::live::LiveSnapshot;
use squall_topology::{CustomMetric, EdgeReport, LiveRun, TaskReport};

/// A counter of every cross-process edge: name, help, unit, value.
type EdgeCounter = (&'static str, &'static str, Option<&'static Unit>, fn(&EdgeReport) -> u64);

/// What a scrape of `/metrics` returns, as its content type says.
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// Encodes `run` as it stands (an empty exposition before it starts).
pub fn encode(run: &Arc<LiveRun>) -> String {
    let mut registry = Registry::with_prefix("squall");
    registry.register_collector(Box::new(RunCollector(run.clone())));
    let mut text = String::new();
    // Writing into a String cannot fail.
    let _ = prometheus_client::encoding::text::encode(&mut text, &registry);
    text
}

#[derive(Debug)]
struct RunCollector(Arc<LiveRun>);

/// One metric per task: its name, help, unit and value.
type PerTask =
    (&'static str, &'static str, Option<Unit>, fn(&TaskReport, &squall_topology::live::TaskState) -> f64);

impl Collector for RunCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        let Some(s) = self.0.snapshot() else { return Ok(()) };
        run_gauges(&s, &mut encoder)?;
        let counters: [PerTask; 11] = [
            ("tuples_received", "Tuples handed to execute", None, |t, _| t.received as f64),
            ("tuples_emitted", "Emit calls", None, |t, _| t.emitted as f64),
            ("tuples_dropped", "Tuples lost to a drop policy at the task's inputs", None, |t, _| {
                t.dropped as f64
            }),
            ("tuples_undelivered", "Tuples that arrived after the task exited", None, |t, _| {
                t.undelivered as f64
            }),
            ("busy", "Time in the component's code", Some(Unit::Seconds), |_, s| s.busy_ns as f64 / 1e9),
            ("backpressure", "Time emits waited on full queues", Some(Unit::Seconds), |_, s| {
                s.blocked_ns as f64 / 1e9
            }),
            ("restarts", "Restarts after a panic or error", None, |t, _| f64::from(t.restarts)),
            ("trees_acked", "Acked tuple trees", None, |t, _| t.acked as f64),
            ("trees_failed", "Failed tuple trees", None, |t, _| t.failed as f64),
            ("trees_replayed", "Replayed tuple trees", None, |t, _| t.replayed as f64),
            ("trees_abandoned", "Tuple trees given up after the retry limit", None, |t, _| {
                t.abandoned as f64
            }),
        ];
        for (name, help, unit, value) in &counters {
            let mut family = encoder.encode_descriptor(
                name,
                help,
                unit.as_ref(),
                ConstCounter::<f64>::new(0.0).metric_type(),
            )?;
            each_task(&s, |labels, t, st| {
                ConstCounter::new(value(t, st)).encode(family.encode_family(&labels)?)
            })?;
        }
        let gauges: [PerTask; 4] = [
            ("queue_depth", "Tuples in the task's input queues now", None, |_, s| s.queue_depth as f64),
            ("queue_bound", "The task's input queue bounds, summed", None, |_, s| s.queue_bound as f64),
            ("execute_p50", "Median execute latency so far", Some(Unit::Seconds), |t, _| {
                t.execute.p50_us / 1e6
            }),
            ("execute_p99", "99th percentile execute latency so far", Some(Unit::Seconds), |t, _| {
                t.execute.p99_us / 1e6
            }),
        ];
        for (name, help, unit, value) in &gauges {
            let mut family = encoder.encode_descriptor(
                name,
                help,
                unit.as_ref(),
                ConstGauge::<f64>::new(0.0).metric_type(),
            )?;
            each_task(&s, |labels, t, st| {
                ConstGauge::new(value(t, st)).encode(family.encode_family(&labels)?)
            })?;
        }
        // Traffic between processes, per edge (cluster runs).
        let edge_counters: [EdgeCounter; 4] = [
            ("edge_messages", "Tuples sent between processes on an edge (cluster runs)", None, |e| {
                e.messages
            }),
            (
                "edge_frames",
                "Frames the tuples of an edge travelled in between processes (a batch is one)",
                None,
                |e| e.frames,
            ),
            ("edge", "Bytes sent between processes on an edge (cluster runs)", Some(&Unit::Bytes), |e| {
                e.bytes
            }),
            (
                "edge_undelivered",
                "Tuples held for a task in another process and never sent: their producer ended first",
                None,
                |e| e.undelivered,
            ),
        ];
        for (name, help, unit, value) in edge_counters {
            let mut family =
                encoder.encode_descriptor(name, help, unit, ConstCounter::<u64>::new(0).metric_type())?;
            for e in &s.edges {
                let labels =
                    [("from", e.from.as_str()), ("stream", e.stream.as_str()), ("to", e.to.as_str())];
                ConstCounter::new(value(e)).encode(family.encode_family(&labels)?)?;
            }
        }
        let mut family = encoder.encode_descriptor(
            "component_counter",
            "A counter a component keeps itself (resamplings, loops, maps written), over its tasks",
            None,
            ConstCounter::<u64>::new(0).metric_type(),
        )?;
        for c in &s.report.components {
            for (metric, value) in &c.custom {
                if let CustomMetric::Counter(v) = value {
                    let labels = [("component", c.name.as_str()), ("metric", metric.as_str())];
                    ConstCounter::new(*v).encode(family.encode_family(&labels)?)?;
                }
            }
        }
        let mut family = encoder.encode_descriptor(
            "component_gauge",
            "A level a component reports itself (bytes of map held), over its tasks",
            None,
            ConstGauge::<i64>::new(0).metric_type(),
        )?;
        for c in &s.report.components {
            for (metric, value) in &c.custom {
                if let CustomMetric::Gauge(gauge) = value {
                    let labels = [("component", c.name.as_str()), ("metric", metric.as_str())];
                    ConstGauge::new(i64::try_from(*gauge).unwrap_or(i64::MAX))
                        .encode(family.encode_family(&labels)?)?;
                }
            }
        }
        Ok(())
    }
}

fn run_gauges(s: &LiveSnapshot, encoder: &mut DescriptorEncoder) -> Result<(), std::fmt::Error> {
    let labels = [("topology", s.report.topology.as_str())];
    let gauge = |v: f64| ConstGauge::new(v);
    let mut elapsed = encoder.encode_descriptor(
        "run_elapsed",
        "Time since the run started",
        Some(&Unit::Seconds),
        gauge(0.0).metric_type(),
    )?;
    gauge(s.elapsed_secs).encode(elapsed.encode_family(&labels)?)?;
    let mut ended =
        encoder.encode_descriptor("run_ended", "1 once the run has ended", None, gauge(0.0).metric_type())?;
    gauge(if s.ended { 1.0 } else { 0.0 }).encode(ended.encode_family(&labels)?)?;
    if let Some(mb) = s.report.peak_rss_mb {
        let mut rss = encoder.encode_descriptor(
            "peak_rss",
            "Peak resident memory of the process",
            Some(&Unit::Bytes),
            gauge(0.0).metric_type(),
        )?;
        gauge(mb * 1048576.0).encode(rss.encode_family(&labels)?)?;
    }
    Ok(())
}

/// Calls `f` with each task's labels, report and state.
fn each_task(
    s: &LiveSnapshot,
    mut f: impl FnMut(
        [(&str, &str); 2],
        &TaskReport,
        &squall_topology::live::TaskState,
    ) -> Result<(), std::fmt::Error>,
) -> Result<(), std::fmt::Error> {
    for (c, states) in s.report.components.iter().zip(&s.tasks) {
        for (t, st) in c.per_task.iter().zip(states) {
            let task = t.task.to_string();
            f([("component", c.name.as_str()), ("task", task.as_str())], t, st)?;
        }
    }
    Ok(())
}
