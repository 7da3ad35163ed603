//! `squall localize`: runs `examples/topologies/localize.toml` (embedded):
//! CGR localization on a line map, here on the simulator's laser.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use squall_bolts::cgr::fspf::FspfOptions;
use squall_core::eval::map_frame;
use squall_core::geometry::Pose2;
use squall_core::trajectory::Trajectory;

use squall_spouts::sim::{
    Carry, Kidnap, SimConfig, SimEvent, Simulation, Start, floor_for, outputs_fit, top_speed_for,
};
use squall_topology::bounds::MemoryBudget;
use squall_topology::spec::readable_number;
use squall_topology::{Override, Topology};

use super::eval::print_map_frame;
use super::{EXIT_INVALID, report_invalid, run, topology_path};

const LOCALIZE_TOML: &str = include_str!("../../examples/topologies/localize.toml");

#[derive(Debug, clap::Args)]
pub(super) struct LocalizeArgs {
    /// The line map (`x1,y1,x2,y2` per line).
    #[arg(long, value_name = "FILE")]
    map: PathBuf,
    /// Simulate a robot in the map (required: recorded input is not read
    /// yet).
    #[arg(long)]
    sim: bool,
    /// Simulated seconds.
    #[arg(long, default_value_t = 120.0, value_parser = super::numbers::sim_secs)]
    duration: f64,
    /// The simulated sensor: `laser`, or `depth` (a D435-like camera,
    /// plane filtered by FSPF).
    #[arg(long, value_name = "laser|depth", default_value = "laser")]
    input: String,
    /// The most particles. A global start begins with this many (default
    /// 2000) and keeps fewer as they gather (KLD-sampling), down to 50; a
    /// known start begins with 50 and grows towards 2000 only when the
    /// robot is lost. Given, a known start keeps exactly this many.
    #[arg(long, value_parser = super::numbers::positive_count)]
    particles: Option<u64>,
    /// Matcher tasks (the results do not depend on it).
    #[arg(long, default_value_t = 1, value_parser = super::numbers::tasks)]
    matchers: usize,
    /// How the new set is drawn.
    #[arg(long, value_name = "low-variance|sparse-ring|global", default_value = "low-variance")]
    resampling: String,
    /// `known` (start at the true pose) or `global` (poses the first
    /// reading supports, anywhere on the map).
    #[arg(long, value_name = "known|global", default_value = "known")]
    init: String,
    /// Where the simulated robot starts: `drawn` per seed anywhere on the
    /// map's roadmap, or `first-node` (the roadmap's first node, every
    /// seed's start).
    #[arg(long, value_name = "drawn|first-node", default_value = "drawn")]
    start: String,
    /// Kidnap the simulated robot this many seconds in: it is carried to
    /// a place of the map 5–20 m away (drawn per seed) without its
    /// odometry noticing. metrics.json then says how long the localizer
    /// took to find it again.
    #[arg(long, value_name = "SECS", value_parser = super::numbers::sim_instant)]
    kidnap_at: Option<f64>,
    /// Run seed (the simulated robot's start, route and noise, and the
    /// filter).
    #[arg(long, default_value_t = 42, value_parser = super::numbers::seed)]
    seed: u64,
    /// Override any value (as in `squall run`).
    #[arg(long = "set", value_name = "PATH=VALUE", value_parser = super::parse_override)]
    overrides: Vec<Override>,
    /// Output folder: trajectory.tum, ground_truth.tum, metrics.json.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Print neither the summary table nor the score (metrics.json has
    /// both).
    #[arg(long)]
    quiet: bool,
    #[command(flatten)]
    watch: super::watch::WatchArgs,
}

/// Particles a global start begins with: where the first reading fits
/// (see `CgrModel::propose`), enough that the robot's pose is among them
/// on the shared maps (docs/results/localization.md, decision 0018).
const GLOBAL_PARTICLES: u64 = 2000;

/// Particles that track a robot already found (and the fewest a global
/// start keeps).
const TRACKING_PARTICLES: u64 = 50;

/// Independent points a plane patch of the depth path's FSPF counts as:
/// its samples fix the wall's offset and direction there, and share the
/// patch's normal and the local error of wall and map. Decision 0029.
const PATCH_EVIDENCE: f64 = 4.0;

fn quoted(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// The built-in topology's overrides for `args`, and the simulated
/// route they drive.
fn overrides(args: &LocalizeArgs) -> Result<(Vec<Override>, Route), String> {
    if !args.sim {
        return Err("--sim is required: recorded depth and laser input come later".into());
    }
    if args.matchers == 0 || args.particles == Some(0) {
        return Err("--matchers and --particles must be at least 1".into());
    }
    if !(args.duration.is_finite() && args.duration > 0.0) {
        return Err(format!("--duration must be > 0 seconds, got {}", args.duration));
    }
    let scheme = match args.resampling.as_str() {
        "low-variance" => "low_variance",
        "sparse-ring" => "ring",
        "global" => "aggregation",
        other => {
            return Err(format!("--resampling must be low-variance, sparse-ring or global, got {other}"));
        }
    };
    let map = topology_path("--map", &args.map)?.to_string();
    let start = match args.start.as_str() {
        "drawn" => Start::Drawn,
        "first-node" => Start::FirstNode,
        other => return Err(format!("--start must be drawn or first-node, got {other}")),
    };
    let start_name = match start {
        Start::Drawn => "drawn",
        Start::FirstNode => "first_node",
    };
    let kidnap = match args.kidnap_at {
        Some(at) => format!(", kidnap = {{ at_secs = {at} }}"),
        None => String::new(),
    };
    let mut sets = vec![format!("topology.seed={}", args.seed)];
    match args.input.as_str() {
        "laser" => {
            sets.push(format!(
                "source.params={{ world = {}, duration_secs = {}, range_max = {}, start = \"{start_name}\"{kidnap} }}",
                quoted(&map),
                args.duration,
                RANGE_MAX
            ));
        }
        "depth" => {
            sets.push("source.kind=\"depth_sim\"".into());
            sets.push(format!(
                "source.params={{ world = {}, duration_secs = {}, start = \"{start_name}\"{kidnap} }}",
                quoted(&map),
                args.duration
            ));
            sets.push("points.kind=\"cgr.fspf\"".into());
            sets.push("points.params={}".into());
            sets.push("points.inputs.0.stream=\"frame\"".into());
        }
        other => return Err(format!("--input must be laser or depth, got {other}")),
    }
    sets.extend([
        format!("matcher.parallelism={}", args.matchers),
        format!("matcher.params.map={}", quoted(&map)),
        format!("matcher.params.resampling={}", quoted(scheme)),
    ]);
    let route = simulated_route(&map, start, args)?;
    // Augmented MCL (in localize.toml) redraws particles where the
    // reading fits once the fit drops: with either sensor, so that a
    // kidnapped robot, or a global start that settled on a look-alike, is
    // searched for. A person or a box can fill the depth camera's view:
    // what lies short of the map does not count against the fit there
    // (docs/decisions/0020-depth-recovery-and-occlusion.md).
    if args.input == "depth" {
        sets.push("matcher.params.occlusion_fits=true".into());
        // A depth frame's thousand points make the likelihood's peak a few
        // millimetres wide: refinement ends at it, and a corner seen does
        // not count against the true pose
        // (docs/decisions/0023-corners-and-the-peak-of-the-likelihood.md).
        sets.push("matcher.params.newton_step=true".into());
        sets.push("matcher.params.leave_out_corners=true".into());
        // The camera's noise grows with the square of depth: FSPF keeps far
        // walls by that law and refits their normals, and the matcher weighs
        // each point by it, both with the law of the camera `depth_sim`
        // renders with (docs/decisions/0025-far-walls-and-the-cameras-noise.md, 0026).
        let noise = squall_core::depth_render::DepthCamera::d435_on_robot().noise.sigma_per_z2;
        sets.push(format!("points.params.noise_per_z2={noise}"));
        sets.push(format!("matcher.params.noise_per_r2={noise}"));
        // FSPF's points come in plane patches of `local_samples` (80) that
        // share their normal and their wall's local error: a patch counts
        // as PATCH_EVIDENCE independent points, not as 80, so a frame's
        // evidence grows with the surfaces seen rather than with the
        // points asked for (docs/decisions/0029-a-plane-patch-as-evidence.md).
        let per_patch = FspfOptions::default().local_samples as f64 / PATCH_EVIDENCE;
        sets.push(format!("matcher.params.correlation={per_patch}"));
    }
    match args.init.as_str() {
        "global" => {
            let particles = args.particles.unwrap_or(GLOBAL_PARTICLES);
            sets.push("matcher.params.init=\"global\"".into());
            sets.push(format!("matcher.params.particles={particles}"));
            sets.push(format!("matcher.params.min_particles={}", particles.min(TRACKING_PARTICLES)));
        }
        "known" => {
            let at = (route.start.x, route.start.y, route.start.theta);
            // Tracking keeps 50; a lost (kidnapped) robot may grow its
            // set back to a global start's size to search, where
            // injection is on.
            let (most, fewest) = match args.particles {
                Some(n) => (n, n),
                None => (GLOBAL_PARTICLES, TRACKING_PARTICLES),
            };
            sets.push(format!("matcher.params.particles={most}"));
            sets.push(format!("matcher.params.min_particles={fewest}"));
            sets.push("matcher.params.init=\"known\"".into());
            sets.push(format!("matcher.params.start=[{}, {}, {}]", at.0, at.1, at.2));
        }
        other => return Err(format!("--init must be known or global, got {other}")),
    }
    let mut out: Vec<Override> = sets
        .iter()
        .map(|s| s.parse())
        .collect::<Result<_, squall_topology::OverrideError>>()
        .map_err(|e| e.to_string())?;
    out.extend(args.overrides.iter().cloned());
    Ok((out, route))
}

/// The simulated laser's range, metres (the topology's `points` bolt
/// reads as far).
pub(crate) const RANGE_MAX: f64 = 8.0;

/// What the run's simulated robot will do, known before it starts (the
/// simulator is deterministic per seed).
struct Route {
    /// The true pose of the first scan or frame.
    start: Pose2,
    /// The kidnapping, when one was asked for.
    carry: Option<Carry>,
    /// The raw odometry at every scan or frame, started at the true
    /// start: where dead reckoning alone would put the robot on the map.
    odometry: Trajectory,
}

/// Replays the run's simulated route (the robot's motion and odometry,
/// the sensor's rays left out) for its start, its kidnapping and its
/// odometry. An error if the settings are out of range or no place of the
/// map lies 5–20 m from where the robot is to be kidnapped.
fn simulated_route(map: &str, start: Start, args: &LocalizeArgs) -> Result<Route, String> {
    // The route's odometry, and the run's outputs, grow with its scans:
    // checked before the replay, as the source's factory checks it later.
    let budget = MemoryBudget::for_run(Override::memory_limit(&args.overrides));
    outputs_fit(budget, args.duration, SimConfig::default().scan_hz, "scans")
        .map_err(|e| format!("--duration {}: {e}", readable_number(args.duration)))?;
    let floor = floor_for(map, args.seed).map_err(|e| e.to_string())?;
    let kidnap = args.kidnap_at.map(|at_secs| Kidnap {
        at_secs,
        min_m: Kidnap::DEFAULT_MIN_M,
        max_m: Kidnap::DEFAULT_MAX_M,
    });
    // The laser's simulator drives at the world's top speed, the depth
    // camera's at the default one (the same indoors).
    let max_speed = match args.input.as_str() {
        "laser" => top_speed_for(map),
        _ => SimConfig::default().max_speed,
    };
    let config = SimConfig {
        seed: args.seed,
        duration_secs: args.duration,
        range_max: RANGE_MAX,
        beams: 2,
        max_speed,
        start,
        kidnap,
        ..SimConfig::default()
    };
    // `new` checks the config first.
    let mut sim = Simulation::new(floor, config).map_err(|e| e.to_string())?;
    let mut first: Option<(Pose2, Pose2)> = None;
    let mut odometry = Trajectory::default();
    let stop = squall_topology::runtime::process_stop();
    for event in sim.by_ref() {
        if stop.is_made() {
            return Err("stopped while the simulated route was replayed".into());
        }
        let SimEvent::Scan(scan, truth) = event else { continue };
        let (truth0, odometry0) = *first.get_or_insert((truth, scan.odometry));
        odometry.push(scan.stamp, truth0.compose(&scan.odometry.relative_to(&odometry0)));
    }
    let start = first
        .ok_or_else(|| {
            format!(
                "--duration {}: too short for one scan (the simulated sensor gives one each {} s)",
                readable_number(args.duration),
                1.0 / SimConfig::default().scan_hz
            )
        })?
        .0;
    let carry = sim.carried();
    if let (Some(k), Some(c)) = (kidnap, carry)
        && !(k.min_m..=k.max_m).contains(&c.distance())
    {
        return Err(format!(
            "{map}: no place of the roadmap lies {}–{} m from where the robot is at {} s (the nearest draw was {:.1} m away)",
            k.min_m,
            k.max_m,
            k.at_secs,
            c.distance()
        ));
    }
    Ok(Route { start, carry, odometry })
}

/// Runs `squall localize`.
pub(super) fn localize(args: &LocalizeArgs) -> ExitCode {
    let (overrides, route) = match overrides(args) {
        Ok(o) => o,
        Err(_) if super::signals::stopping() => return run::stopped_before_start(Some(&args.out)),
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    let mut text = LOCALIZE_TOML.to_string();
    if args.watch.viewed() {
        // The view: the line map, what the sensor saw (the scan, and the
        // points matched), the estimate (placing map → odom), the
        // particles, the hypotheses and the simulator's truth.
        let mut inputs = vec![
            ("points", "default"),
            ("resampler", "pose"),
            ("resampler", "particles"),
            ("resampler", "hypotheses"),
            ("source", "truth"),
        ];
        if args.input == "laser" {
            inputs.push(("source", "scan"));
        }
        let map = args.map.to_string_lossy();
        text.push_str(&super::watch::view_bolt(&inputs, &format!("line_map = {}", quoted(&map))));
    }
    let spec =
        Topology::from_text("localize.toml (built in)", &text, &overrides, &crate::builtin::registry());
    let scorer = |dir: &Path| score(dir, &route, args.quiet);
    match report_invalid(spec) {
        Ok(topology) => {
            run::run_scored(&topology, Some(args.out.clone()), args.quiet, None, &args.watch, Some(&scorer))
        }
        Err(_) if super::signals::stopping() => run::stopped_before_start(Some(&args.out)),
        Err(code) => code,
    }
}

/// The run's trajectory against the simulator's ground truth, in the map
/// frame (a localizer's poses are in the map's frame: no alignment),
/// printed and returned for metrics.json under `localization`; beside
/// it the raw odometry's (`odometry`) and how far the estimate ever was
/// worse than it (`worst_over_odometry_m`: the largest of the estimate's
/// error less the odometry's, over the poses); with a kidnapping, also
/// how long the robot was lost after it (`kidnap`).
fn score(dir: &Path, route: &Route, quiet: bool) -> Result<(&'static str, serde_json::Value), String> {
    let read = |name: &str| Trajectory::read_tum(&dir.join(name)).map_err(|e| e.to_string());
    let (estimate, truth) = (read("trajectory.tum")?, read("ground_truth.tum")?);
    let score = map_frame::score(&estimate, &truth)
        .ok_or("no pose of trajectory.tum shares a stamp with ground_truth.tum")?;
    if !quiet {
        print_map_frame(&score, false);
    }
    let mut value = serde_json::to_value(score).map_err(|e| e.to_string())?;
    if let (Some(odometry), Some(worst)) = (
        map_frame::score(&route.odometry, &truth),
        map_frame::worst_excess(&estimate, &route.odometry, &truth),
    ) {
        if !quiet {
            outln!(
                "  raw odometry: {:.4} m mean, {:.4} m max; the estimate at most {worst:.4} m worse than it",
                odometry.map_mean_m,
                odometry.map_max_m
            );
        }
        value["odometry"] =
            serde_json::json!({ "map_mean_m": odometry.map_mean_m, "map_max_m": odometry.map_max_m });
        value["worst_over_odometry_m"] = serde_json::json!(worst);
    }
    if let Some(c) = route.carry {
        let recovered = map_frame::recovered_after(&estimate, &truth, c.stamp);
        match recovered {
            _ if quiet => {}
            Some(t) => outln!(
                "  kidnapped at {:.1} s, carried {:.1} m: found again {t:.2} s later",
                c.stamp,
                c.distance()
            ),
            None => {
                outln!("  kidnapped at {:.1} s, carried {:.1} m: not found again", c.stamp, c.distance())
            }
        }
        value["kidnap"] = serde_json::json!({
            "at_s": c.stamp,
            "carry_m": c.distance(),
            "recovered_after_s": recovered,
        });
    }
    Ok(("localization", value))
}
