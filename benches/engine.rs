//! Engine throughput and latency: spout → relay → sink with 64-byte probe
//! messages.
//!
//!     cargo bench --bench engine
//!
//! `throughput/p{1,2}`: one million messages per iteration through the three
//! stages, with the relay and sink at parallelism 1 and 2. `latency`: the
//! source paced at half the measured maximum rate; end-to-end latency p50/p99
//! (sink receive time − emit time), median of five runs, printed as a table.

use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use squall::topology::metrics::CustomMetric;
use squall::topology::{RunOptions, RunReport, Topology, TopologySpec};

const MESSAGES: u64 = 1_000_000;

fn topology(parallelism: usize, count: u64, rate_hz: Option<f64>) -> Topology {
    let rate = rate_hz.map_or(String::new(), |r| format!(", rate_hz = {r}"));
    let toml = format!(
        r#"
[topology]
name = "bench"

[[spout]]
name = "source"
kind = "probe.source"
params = {{ count = {count}, message_bytes = 64 {rate} }}

[[bolt]]
name = "relay"
kind = "probe.relay"
parallelism = {parallelism}
inputs = [ {{ from = "source" }} ]

[[bolt]]
name = "sink"
kind = "probe.sink"
parallelism = {parallelism}
inputs = [ {{ from = "relay" }} ]
"#
    );
    let spec = TopologySpec::parse("bench.toml", &toml).expect("valid bench topology");
    Topology::validate(spec, &squall::builtin::registry()).expect("valid bench topology")
}

fn run(t: &Topology) -> RunReport {
    squall::topology::run(t, &RunOptions::default()).expect("bench run succeeds")
}

fn throughput(c: &mut Criterion) {
    let mut group = c.benchmark_group("throughput");
    group.sample_size(10).measurement_time(Duration::from_secs(8)).warm_up_time(Duration::from_secs(1));
    group.throughput(Throughput::Elements(MESSAGES));
    for parallelism in [1, 2] {
        let t = topology(parallelism, MESSAGES, None);
        group.bench_function(format!("p{parallelism}"), |b| b.iter(|| run(&t)));
    }
    group.finish();
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn latency(_c: &mut Criterion) {
    println!("\nlatency at half load (64-byte messages, median of 5 runs)");
    println!("{:<6} {:>14} {:>14} {:>10} {:>10}", "tasks", "max msg/s", "paced msg/s", "p50 µs", "p99 µs");
    for parallelism in [1, 2] {
        let max_rate = median(
            (0..3)
                .map(|_| {
                    let r = run(&topology(parallelism, MESSAGES, None));
                    MESSAGES as f64 / r.wall_secs
                })
                .collect(),
        );
        let rate = max_rate / 2.0;
        let count = (rate * 1.0) as u64; // about one second per run
        let (mut p50, mut p99) = (Vec::new(), Vec::new());
        for _ in 0..5 {
            let r = run(&topology(parallelism, count, Some(rate)));
            match r.component("sink").and_then(|s| s.custom.get("latency_ns")) {
                Some(CustomMetric::Values { p50: a, p99: b, .. }) => {
                    p50.push(*a as f64 / 1e3);
                    p99.push(*b as f64 / 1e3);
                }
                other => panic!("sink reported no latency: {other:?}"),
            }
        }
        println!(
            "{:<6} {:>14.0} {:>14.0} {:>10.1} {:>10.1}",
            parallelism,
            max_rate,
            rate,
            median(p50),
            median(p99)
        );
    }
}

// The macro generates an undocumented public function.
#[allow(missing_docs)]
mod group {
    use super::*;
    criterion_group!(benches, throughput, latency);
}
criterion_main!(group::benches);
