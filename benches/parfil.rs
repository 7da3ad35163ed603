//! parfil (the thesis's toy filter, §6.3.1) on the particle filter
//! topology: median time per iteration against the particle count with one
//! and two matcher tasks, and the three resampling schemes at 1000
//! particles. Each cell is one run of `examples/topologies/parfil.toml`
//! (200 iterations), timed per iteration by the dispatcher (hand-out to
//! every task done, `reading_us`).

use squall::builtin::registry;
use squall_topology::{CustomMetric, Override, RunOptions, Topology, TopologySpec};

const PARFIL_TOML: &str = include_str!("../examples/topologies/parfil.toml");

/// Median ms per iteration.
fn run(particles: usize, matchers: usize, scheme: &str) -> f64 {
    let sets = [
        "source.params.iterations=200".to_string(),
        format!("matcher.parallelism={matchers}"),
        format!("matcher.params.particles={particles}"),
        format!("matcher.params.resampling=\"{scheme}\""),
    ];
    let overrides: Vec<Override> = sets.iter().map(|s| s.parse().expect("valid override")).collect();
    let spec = TopologySpec::parse_with("parfil.toml", PARFIL_TOML, &overrides).expect("parfil.toml parses");
    let topology = Topology::validate(spec, &registry()).expect("parfil.toml is valid");
    let dir = tempfile::tempdir().expect("a temporary folder");
    let options = RunOptions { out_dir: Some(dir.path().to_path_buf()), ..RunOptions::default() };
    let report = squall_topology::run(&topology, &options).expect("the run succeeds");
    let dispatcher = report.components.iter().find(|c| c.name == "dispatcher").expect("a dispatcher");
    match dispatcher.custom.get("reading_us") {
        Some(CustomMetric::Values { p50, .. }) => *p50 as f64 / 1e3,
        other => panic!("no reading_us: {other:?}"),
    }
}

fn main() {
    // `cargo bench` passes `--bench`; nothing else is accepted.
    println!("parfil: median ms per iteration (200 iterations per cell)");
    println!("{:>10} {:>10} {:>10} {:>8}", "particles", "K = 1", "K = 2", "speedup");
    for particles in [1_000, 10_000, 100_000] {
        let (one, two) = (run(particles, 1, "aggregation"), run(particles, 2, "aggregation"));
        println!("{particles:>10} {one:>10.3} {two:>10.3} {:>8.2}", one / two);
    }
    println!("\nresampling schemes at 1000 particles, K = 1: median ms per iteration");
    for scheme in ["aggregation", "low_variance", "ring"] {
        println!("{scheme:>14} {:>8.3}", run(1_000, 1, scheme));
    }
}
