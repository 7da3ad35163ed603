//! `squall speedup`: runs the SLAM topology for every (particles, matcher
//! tasks) pair and reports how the time per processed scan scales with the
//! matcher count (seed 003 Table 2 / Fig. 5): a table on stdout,
//! `speedup.csv` and a plot `speedup.svg`. With `--cluster`, every
//! configuration also runs on the cluster's workers (matcher task i on
//! worker i mod n), and the table adds the bytes and serialization time
//! that crossed between processes.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use squall_topology::fsio::write_atomic;
use squall_topology::{ComponentReport, CustomMetric, RunOptions, RunReport};

use super::slam::SlamArgs;
use super::{EXIT_FAILED, EXIT_INVALID};

#[derive(Debug, clap::Args)]
pub(super) struct SpeedupArgs {
    /// A CARMEN log or ROS 2 bag; without it, the simulated office.
    #[arg(long, value_name = "FILE")]
    log: Option<PathBuf>,
    /// Particle counts to run.
    #[arg(long, value_delimiter = ',', default_value = "20,60,100", value_parser = super::numbers::positive_count)]
    particles: Vec<u64>,
    /// Matcher task counts to run (1 is the baseline).
    #[arg(long, value_delimiter = ',', default_value = "1,2", value_parser = super::numbers::tasks)]
    matchers: Vec<usize>,
    /// Pose evaluations per particle per reading: a number or `none`.
    #[arg(long, value_name = "N|none", value_parser = crate::cli::numbers::cutoff)]
    cutoff: Option<String>,
    /// Stop each run after this many scans.
    #[arg(long, value_parser = super::numbers::positive_count)]
    max_scans: Option<u64>,
    /// Run seed.
    #[arg(long, value_parser = super::numbers::seed)]
    seed: Option<u64>,
    /// Output folder: speedup.csv, speedup.svg and one folder per run.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Also run every configuration on the workers of this cluster file.
    #[arg(long, value_name = "CLUSTER.toml")]
    cluster: Option<PathBuf>,
}

/// One configuration's figures.
#[derive(Debug, Clone)]
struct Row {
    particles: u64,
    matchers: usize,
    /// Run on a cluster's workers (else in one process).
    on_cluster: bool,
    /// Median wall ms per processed scan.
    median_ms: f64,
    /// Mean of (slowest matcher task − mean task) per correction, ms.
    imbalance_ms: f64,
    /// Bytes of particle state moved per processed scan.
    bytes_per_scan: f64,
    /// What round-robin placement would have moved per processed scan.
    naive_bytes_per_scan: f64,
    /// Bytes that crossed between processes per processed scan.
    wire_bytes_per_scan: f64,
    /// Serialization (both ends) per processed scan, ms.
    serialize_ms_per_scan: f64,
    /// Whether trajectory.tum equals the one-matcher run's.
    identical: Option<bool>,
}

fn component<'a>(report: &'a RunReport, name: &str) -> Option<&'a ComponentReport> {
    report.components.iter().find(|c| c.name == name)
}

fn values(c: &ComponentReport, name: &str) -> Option<(u64, f64, u64)> {
    match c.custom.get(name)? {
        CustomMetric::Values { count, mean, p50, .. } => Some((*count, *mean, *p50)),
        CustomMetric::Counter(_) | CustomMetric::Gauge(_) | CustomMetric::Measured(_) => None,
    }
}

fn counter(c: &ComponentReport, name: &str) -> Option<u64> {
    match c.custom.get(name)? {
        CustomMetric::Counter(n) => Some(*n),
        CustomMetric::Values { .. } | CustomMetric::Gauge(_) | CustomMetric::Measured(_) => None,
    }
}

/// Total of a value metric (mean × count), 0 when never recorded.
fn total(c: &ComponentReport, name: &str) -> f64 {
    values(c, name).map_or(0.0, |(n, mean, _)| n as f64 * mean)
}

fn row_of(report: &RunReport, particles: u64, matchers: usize, on_cluster: bool) -> Result<Row, String> {
    let missing = |what: &str| format!("the run's metrics lack {what} (is this the SLAM topology?)");
    let dispatcher = component(report, "dispatcher").ok_or_else(|| missing("the dispatcher"))?;
    let resampler = component(report, "resampler").ok_or_else(|| missing("the resampler"))?;
    let (_, _, p50_us) =
        values(dispatcher, "processed_scan_us").ok_or_else(|| missing("processed_scan_us"))?;
    let processed = counter(resampler, "processed_scans").ok_or_else(|| missing("processed_scans"))?.max(1);
    let corrections = values(resampler, "imbalance_us").map_or(0, |v| v.0).max(1);
    let wire_bytes: u64 = report.edges.iter().map(|e| e.bytes).sum();
    let serialize_ms = report.edges.iter().fold(0.0, |sum, e| sum + e.encode_ms + e.decode_ms);
    Ok(Row {
        particles,
        matchers,
        on_cluster,
        wire_bytes_per_scan: wire_bytes as f64 / processed as f64,
        serialize_ms_per_scan: serialize_ms / processed as f64,
        median_ms: p50_us as f64 / 1e3,
        imbalance_ms: total(resampler, "imbalance_us") / corrections as f64 / 1e3,
        bytes_per_scan: total(resampler, "bytes_moved") / processed as f64,
        naive_bytes_per_scan: total(resampler, "bytes_moved_round_robin") / processed as f64,
        identical: None,
    })
}

/// Runs `squall speedup`.
pub(super) fn speedup(args: &SpeedupArgs) -> ExitCode {
    if args.particles.is_empty() || args.matchers.is_empty() || args.matchers.contains(&0) {
        eprintln!("error: --particles and --matchers need at least one value each, matchers ≥ 1");
        return ExitCode::from(EXIT_INVALID);
    }
    if let Err(code) = super::writable_out(&args.out) {
        return code;
    }
    let mut matchers = args.matchers.clone();
    matchers.sort_unstable();
    matchers.dedup();
    let mut rows = Vec::new();
    'configurations: for &particles in &args.particles {
        for &k in &matchers {
            let places: &[bool] = if args.cluster.is_some() { &[false, true] } else { &[false] };
            for &on_cluster in places {
                if super::signals::stopping() {
                    break 'configurations;
                }
                let name = format!("p{particles}-k{k}{}", if on_cluster { "-cluster" } else { "" });
                let dir = args.out.join(name);
                let mut row = match run_one(args, particles, k, on_cluster, &dir) {
                    // Stopped during the run: its figures cover part of
                    // the log, and are left out.
                    _ if super::signals::stopping() => break 'configurations,
                    Ok(row) => row,
                    Err((code, e)) => {
                        eprintln!("error: {particles} particles, {k} matchers: {e}");
                        return ExitCode::from(code);
                    }
                };
                let baseline = args.out.join(format!("p{particles}-k{}", matchers[0])).join("trajectory.tum");
                if k != matchers[0] || on_cluster {
                    row.identical = Some(same_file(&baseline, &dir.join("trajectory.tum")));
                }
                eprintln!(
                    "{particles} particles, {k} matchers{}: {:.2} ms per processed scan",
                    if on_cluster { " on the cluster" } else { "" },
                    row.median_ms
                );
                rows.push(row);
            }
        }
    }
    if rows.is_empty() {
        eprintln!("error: stopped (Ctrl-C or SIGTERM) before a configuration was measured in full");
        return ExitCode::from(EXIT_FAILED);
    }
    let table = table(&rows, matchers[0]);
    out!("{table}");
    let written = write_atomic(&args.out.join("speedup.csv"), csv(&rows, matchers[0]).as_bytes())
        .and_then(|()| write_atomic(&args.out.join("speedup.svg"), svg(&rows, matchers[0]).as_bytes()));
    if let Err(e) = written {
        eprintln!("error: cannot write to {}: {e}", args.out.display());
        return ExitCode::from(EXIT_FAILED);
    }
    if super::signals::stopping() {
        eprintln!(
            "error: stopped (Ctrl-C or SIGTERM): the table has the {} configurations measured in full",
            rows.len()
        );
        return ExitCode::from(EXIT_FAILED);
    }
    if rows.iter().any(|r| r.identical == Some(false)) {
        eprintln!("error: a run's trajectory differs from the baseline's: results must not depend on K");
        return ExitCode::from(EXIT_FAILED);
    }
    ExitCode::SUCCESS
}

/// Runs one configuration into `dir` and measures it.
fn run_one(
    args: &SpeedupArgs,
    particles: u64,
    k: usize,
    on_cluster: bool,
    dir: &Path,
) -> Result<Row, (u8, String)> {
    let failed = |e: String| (EXIT_FAILED, e);
    let slam = SlamArgs {
        cluster: None,
        log: args.log.clone(),
        particles: Some(particles),
        cutoff: args.cutoff.clone(),
        matchers: k,
        max_scans: args.max_scans,
        seed: args.seed,
        topology: None,
        overrides: Vec::new(),
        out: dir.to_path_buf(),
        quiet: true,
        watch: Default::default(),
    };
    let topology =
        super::slam::topology(&slam).map_err(|_| (EXIT_INVALID, "invalid configuration".to_string()))?;
    let options = RunOptions {
        out_dir: Some(dir.to_path_buf()),
        stop: squall_topology::runtime::process_stop(),
        ..RunOptions::default()
    };
    let report = match (&args.cluster, on_cluster) {
        (Some(file), true) => run_on_cluster(&topology, file, &options)?,
        _ => squall_topology::run(&topology, &options).map_err(|e| failed(e.to_string()))?,
    };
    write_atomic(&dir.join("metrics.json"), report.to_json().as_bytes())
        .map_err(|e| failed(format!("cannot write {}: {e}", dir.join("metrics.json").display())))?;
    row_of(&report, particles, k, on_cluster).map_err(failed)
}

#[cfg(feature = "cluster")]
fn run_on_cluster(
    topology: &squall_topology::Topology,
    file: &Path,
    options: &RunOptions,
) -> Result<RunReport, (u8, String)> {
    use squall_topology::cluster::config::{ClusterSpec, Host};
    let mut cluster = ClusterSpec::load(file).map_err(|e| (EXIT_INVALID, e.to_string()))?;
    // The matchers go to the workers even when there is one of them (the
    // default would keep a single task with the coordinator).
    if !cluster.placement.contains_key("matcher") {
        let k = topology.spec().component("matcher").map_or(1, |c| c.parallelism);
        let workers = (0..k).map(|i| Host::Worker(i % cluster.workers.len())).collect();
        cluster.placement.insert("matcher".into(), workers);
    }
    squall_topology::cluster::run::run_on_cluster(topology, &cluster, options)
        .map_err(|e| (EXIT_FAILED, e.to_string()))
}

#[cfg(not(feature = "cluster"))]
fn run_on_cluster(
    _: &squall_topology::Topology,
    _: &Path,
    _: &RunOptions,
) -> Result<RunReport, (u8, String)> {
    Err((
        EXIT_INVALID,
        "--cluster needs cluster mode: this squall was built without the `cluster` feature".into(),
    ))
}

fn same_file(a: &Path, b: &Path) -> bool {
    matches!((std::fs::read(a), std::fs::read(b)), (Ok(x), Ok(y)) if x == y)
}

/// The baseline row's time for `particles`.
fn baseline(rows: &[Row], particles: u64, base: usize) -> Option<f64> {
    rows.iter().find(|r| r.particles == particles && r.matchers == base && !r.on_cluster).map(|r| r.median_ms)
}

/// (speedup T_base / T_K, efficiency speedup × base / K).
fn scaling(rows: &[Row], r: &Row, base: usize) -> (f64, f64) {
    let s = baseline(rows, r.particles, base).map_or(f64::NAN, |t| t / r.median_ms);
    (s, s * base as f64 / r.matchers as f64)
}

fn table(rows: &[Row], base: usize) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "{:>9} {:>8} {:>8} {:>10} {:>8} {:>10} {:>13} {:>14} {:>15} {:>12} {:>11} {:>9}",
        "particles",
        "matchers",
        "where",
        "median ms",
        "speedup",
        "efficiency",
        "imbalance ms",
        "bytes/scan",
        "round-robin b/s",
        "wire b/scan",
        "serde ms/sc",
        "same"
    );
    for r in rows {
        let (s, e) = scaling(rows, r, base);
        let same = match r.identical {
            None => "-",
            Some(true) => "yes",
            Some(false) => "NO",
        };
        let _ = writeln!(
            t,
            "{:>9} {:>8} {:>8} {:>10.2} {:>8.2} {:>10.2} {:>13.3} {:>14.0} {:>15.0} {:>12.0} {:>11.3} {:>9}",
            r.particles,
            r.matchers,
            if r.on_cluster { "workers" } else { "process" },
            r.median_ms,
            s,
            e,
            r.imbalance_ms,
            r.bytes_per_scan,
            r.naive_bytes_per_scan,
            r.wire_bytes_per_scan,
            r.serialize_ms_per_scan,
            same
        );
    }
    t
}

fn csv(rows: &[Row], base: usize) -> String {
    let mut t = String::from(
        "particles,matchers,median_ms,speedup,efficiency,imbalance_ms,bytes_moved_per_scan,round_robin_bytes_per_scan,identical,where,wire_bytes_per_scan,serialize_ms_per_scan\n",
    );
    for r in rows {
        let (s, e) = scaling(rows, r, base);
        let same = r.identical.map_or(String::new(), |b| b.to_string());
        let _ = writeln!(
            t,
            "{},{},{:.4},{:.4},{:.4},{:.4},{:.1},{:.1},{same},{},{:.1},{:.4}",
            r.particles,
            r.matchers,
            r.median_ms,
            s,
            e,
            r.imbalance_ms,
            r.bytes_per_scan,
            r.naive_bytes_per_scan,
            if r.on_cluster { "workers" } else { "process" },
            r.wire_bytes_per_scan,
            r.serialize_ms_per_scan
        );
    }
    t
}

/// Speedup against matcher tasks, one line per particle count, the ideal
/// line dashed.
fn svg(rows: &[Row], base: usize) -> String {
    const COLOURS: [&str; 6] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"];
    let (w, h, margin) = (480.0, 360.0, 50.0);
    let k_max = rows.iter().map(|r| r.matchers).max().unwrap_or(1).max(2) as f64;
    let s_max =
        rows.iter().map(|r| scaling(rows, r, base).0).filter(|s| s.is_finite()).fold(k_max, f64::max).ceil();
    let x = |k: f64| margin + (k - 1.0) / (k_max - 1.0) * (w - 2.0 * margin);
    let y = |s: f64| h - margin - s / s_max * (h - 2.0 * margin);
    let mut t = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    );
    let _ = writeln!(
        t,
        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{2}\" y2=\"{1}\" stroke=\"black\"/><line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{3}\" stroke=\"black\"/>",
        x(1.0),
        y(0.0),
        x(k_max),
        y(s_max)
    );
    for k in 1..=k_max as usize {
        let _ = writeln!(
            t,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{k}</text>",
            x(k as f64),
            y(0.0) + 16.0
        );
    }
    for s in 0..=s_max as usize {
        let _ = writeln!(
            t,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{s}</text>",
            x(1.0) - 6.0,
            y(s as f64) + 4.0
        );
    }
    let _ = writeln!(
        t,
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">matcher tasks</text>\n<text x=\"14\" y=\"{}\" transform=\"rotate(-90 14 {})\" text-anchor=\"middle\">speedup</text>",
        w / 2.0,
        h - 10.0,
        h / 2.0,
        h / 2.0
    );
    let _ = writeln!(
        t,
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"grey\" stroke-dasharray=\"6 4\"/>",
        x(1.0),
        y(1.0),
        x(k_max),
        y(k_max)
    );
    let mut particle_counts: Vec<(u64, bool)> = rows.iter().map(|r| (r.particles, r.on_cluster)).collect();
    particle_counts.sort_unstable();
    particle_counts.dedup();
    for (i, (p, on_cluster)) in particle_counts.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let points: Vec<String> = rows
            .iter()
            .filter(|r| r.particles == *p && r.on_cluster == *on_cluster)
            .map(|r| (r.matchers as f64, scaling(rows, r, base).0))
            .filter(|(_, s)| s.is_finite())
            .map(|(k, s)| format!("{:.1},{:.1}", x(k), y(s)))
            .collect();
        let _ = writeln!(
            t,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\"/>",
            points.join(" ")
        );
        let _ = writeln!(
            t,
            "<text x=\"{}\" y=\"{}\" fill=\"{colour}\">{p} particles{}</text>",
            margin + 10.0,
            margin + 16.0 * i as f64,
            if *on_cluster { ", workers" } else { "" },
        );
    }
    let _ = writeln!(
        t,
        "<text x=\"{}\" y=\"{}\" fill=\"grey\">ideal</text>",
        margin + 10.0,
        margin + 16.0 * particle_counts.len() as f64
    );
    t.push_str("</svg>\n");
    t
}
