//! `squall slam`: runs `examples/topologies/slam.toml` (embedded) with its
//! source pointed at a CARMEN log, a ROS 2 bag or the simulated office.

use std::path::PathBuf;
use std::process::ExitCode;

use squall_topology::{Override, Topology};

use super::{EXIT_INVALID, report_invalid, run, topology_path};

const SLAM_TOML: &str = include_str!("../../examples/topologies/slam.toml");

#[derive(Debug, Clone, clap::Args)]
pub(super) struct SlamArgs {
    /// A CARMEN log (.clf, .clf.gz) or a ROS 2 bag (folder, .mcap or .db3);
    /// without it, the simulated office.
    #[arg(long, value_name = "FILE")]
    pub(super) log: Option<PathBuf>,
    /// Particles.
    #[arg(long, value_parser = super::numbers::positive_count)]
    pub(super) particles: Option<u64>,
    /// Pose evaluations per particle per reading: a number or `none`.
    #[arg(long, value_name = "N|none", value_parser = crate::cli::numbers::cutoff)]
    pub(super) cutoff: Option<String>,
    /// Matcher tasks, each holding a share of the particles (the results
    /// do not depend on it).
    #[arg(long, default_value_t = 1, value_parser = super::numbers::tasks)]
    pub(super) matchers: usize,
    /// Stop after this many scans.
    #[arg(long, value_parser = super::numbers::positive_count)]
    pub(super) max_scans: Option<u64>,
    /// Run seed.
    #[arg(long, value_parser = super::numbers::seed)]
    pub(super) seed: Option<u64>,
    /// Another topology file instead of the built-in slam.toml.
    #[arg(long, value_name = "FILE")]
    pub(super) topology: Option<PathBuf>,
    /// Override any value (as in `squall run`).
    #[arg(long = "set", value_name = "PATH=VALUE", value_parser = super::parse_override)]
    pub(super) overrides: Vec<Override>,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    pub(super) out: PathBuf,
    /// Do not print the summary table.
    #[arg(long)]
    pub(super) quiet: bool,
    /// Run on the workers of this cluster file (cluster mode).
    #[arg(long, value_name = "CLUSTER.toml")]
    pub(super) cluster: Option<PathBuf>,
    #[command(flatten)]
    pub(super) watch: super::watch::WatchArgs,
}

fn quoted(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn overrides(args: &SlamArgs) -> Result<Vec<Override>, String> {
    let mut sets: Vec<String> = Vec::new();
    sets.push(format!("matcher.parallelism={}", args.matchers));
    let max_scans = args.max_scans.map_or(String::new(), |m| format!(", max_scans = {m}"));
    match &args.log {
        None => {
            if let Some(m) = args.max_scans {
                sets.push(format!("source.params.max_scans={m}"));
            }
        }
        Some(path) => {
            let name = topology_path("--log", path)?;
            let is_carmen = name.ends_with(".clf") || name.ends_with(".clf.gz") || name.ends_with(".gz");
            let (kind, key) = if is_carmen { ("carmen", "log") } else { ("rosbag2", "bag") };
            sets.push(format!("source.kind={kind}"));
            sets.push(format!("source.params={{ {key} = {}{max_scans} }}", quoted(name)));
        }
    }
    if let Some(p) = args.particles {
        sets.push(format!("matcher.params.particles={p}"));
    }
    if args.watch.viewed() && args.topology.is_none() {
        // The view shows the map as it grows: the best particle's every
        // tenth correction (the view publishes at most one a second of
        // the log's clock).
        sets.push("matcher.params.map_interval=10".into());
    }
    if let Some(c) = &args.cutoff {
        let value = if c == "none" { quoted("none") } else { c.clone() };
        sets.push(format!("matcher.params.cutoff={value}"));
    }
    if let Some(s) = args.seed {
        sets.push(format!("topology.seed={s}"));
    }
    let mut out: Vec<Override> = sets
        .iter()
        .map(|s| s.parse())
        .collect::<Result<_, squall_topology::OverrideError>>()
        .map_err(|e| e.to_string())?;
    out.extend(args.overrides.iter().cloned());
    Ok(out)
}

/// The validated SLAM topology for `args`; errors are reported and
/// turned into the exit code.
pub(super) fn topology(args: &SlamArgs) -> Result<Topology, ExitCode> {
    let overrides = overrides(args).map_err(|e| {
        eprintln!("error: {e}");
        ExitCode::from(EXIT_INVALID)
    })?;
    let spec = match &args.topology {
        Some(file) => Topology::load(file, &overrides, &crate::builtin::registry()),
        None => {
            let mut text = SLAM_TOML.to_string();
            if args.watch.viewed() {
                // The view: scans, the live estimate (placing map → odom),
                // the particles, the map and the corrected trajectory.
                let inputs = [
                    ("source", "scan"),
                    ("resampler", "pose"),
                    ("resampler", "particles"),
                    ("backend", "map"),
                    ("backend", "trajectory"),
                ];
                text.push_str(&super::watch::view_bolt(&inputs, ""));
            }
            Topology::from_text("slam.toml (built in)", &text, &overrides, &crate::builtin::registry())
        }
    };
    report_invalid(spec)
}

/// Runs `squall slam`.
pub(super) fn slam(args: &SlamArgs) -> ExitCode {
    // The log is read here, before the run, unless workers elsewhere read
    // it (`squall study` checks these settings before its logs exist).
    if let (Some(path), None) = (&args.log, &args.cluster) {
        let readable = match std::fs::metadata(path) {
            Ok(m) if m.is_dir() => std::fs::read_dir(path).map(drop),
            Ok(_) => std::fs::File::open(path).map(drop),
            Err(e) => Err(e),
        };
        if let Err(e) = readable {
            eprintln!("error: --log {}: cannot read: {e}", path.display());
            return ExitCode::from(EXIT_INVALID);
        }
    }
    match topology(args) {
        Ok(topology) => {
            run::run(&topology, Some(args.out.clone()), args.quiet, args.cluster.as_deref(), &args.watch)
        }
        Err(_) if super::signals::stopping() => run::stopped_before_start(Some(&args.out)),
        Err(code) => code,
    }
}
