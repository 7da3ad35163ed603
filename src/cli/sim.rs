//! `squall sim`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use squall_spouts::sim::output::write_run;
use squall_spouts::sim::{
    Faults, OdometryQuality, SimConfig, Simulation, floor_for, laser_range_for, top_speed_for,
};

use squall_topology::bounds::MemoryBudget;
use squall_topology::spec::readable_number;

use super::{EXIT_FAILED, EXIT_INVALID};

#[derive(Debug, clap::Args)]
pub(super) struct SimArgs {
    /// The world: `office`, `campus` (a 320 × 220 m open site) or `ring`
    /// (one corridor, 230–300 m round, about a block of rooms: a loop
    /// that closes only after the odometry has drifted far), each
    /// generated from the seed, or a line-map file (`x1,y1,x2,y2` per line,
    /// metres).
    #[arg(long, default_value = "office")]
    world: String,
    /// Simulated seconds.
    #[arg(long, default_value_t = 600.0, value_parser = super::numbers::sim_secs)]
    duration: f64,
    /// Seed of the world, the route and every noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Laser beams over the field of view.
    #[arg(long, default_value_t = 180, value_parser = super::numbers::beams)]
    beams: usize,
    /// Laser field of view, degrees.
    #[arg(long, default_value_t = 180.0, value_parser = super::numbers::fov_deg)]
    fov_deg: f64,
    /// Laser range, metres (farther walls give no return). The default is
    /// 80 on the campus, 30 elsewhere.
    #[arg(long, value_parser = super::numbers::range_m)]
    range_max: Option<f64>,
    /// Wheel odometry: good (0.2–0.5% scale error, 0.02–0.05°/m heading
    /// drift), poor (1–2%, 0.15–0.35°/m) or bad (3–5%, 0.5–0.8°/m).
    #[arg(long, default_value = "poor", value_name = "good|poor|bad")]
    odometry: OdometryQuality,
    /// Stamp each scan this long after the laser measured it, seconds,
    /// with the odometry at its stamp: a driver that stamps on arrival.
    #[arg(long, default_value_t = 0.0, value_name = "SECS", value_parser = super::numbers::latency_secs)]
    scan_latency: f64,
    /// Odometry messages per second (`ODOM` lines); 0 writes one with
    /// each scan.
    #[arg(long, default_value_t = 0.0, value_name = "HZ", value_parser = super::numbers::odom_hz)]
    odom_hz: f64,
    /// Write no-return beams as this many metres (±4 cm) instead of the
    /// declared range: a no-return code below the declared maximum (needs
    /// --declared-range above it).
    #[arg(long, value_name = "M", value_parser = super::numbers::range_m)]
    no_return: Option<f64>,
    /// The maximum range the log declares, metres, when more than the
    /// laser reaches.
    #[arg(long, value_name = "M", value_parser = super::numbers::range_m)]
    declared_range: Option<f64>,
    /// The odometry misjudges every turn by this share (0.05: 5% too
    /// much).
    #[arg(long, default_value_t = 0.0, value_name = "SHARE", value_parser = super::numbers::error_share)]
    turn_scale_error: f64,
    /// A wheel slip every this many seconds on average: for 2–6 s the
    /// robot is held while its odometry drives on.
    #[arg(long, value_name = "SECS", value_parser = super::numbers::slip_every_secs)]
    slip_every: Option<f64>,
    /// The most memory the log may take while it is made (it is written
    /// whole when the run ends), MiB; the default is 90% of the
    /// machine's. A --duration whose log would not fit is refused before
    /// anything runs.
    #[arg(long, value_name = "MIB", value_parser = super::numbers::positive_count)]
    memory_limit_mb: Option<u64>,
    /// Output folder: sim.clf, ground_truth.tum, sim.relations, world.png.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

/// Runs `squall sim`.
pub(super) fn sim(args: &SimArgs) -> ExitCode {
    let config = SimConfig {
        seed: args.seed,
        duration_secs: args.duration,
        beams: args.beams,
        fov: args.fov_deg.to_radians(),
        range_max: args.range_max.unwrap_or_else(|| laser_range_for(&args.world)),
        max_speed: top_speed_for(&args.world),
        odometry: args.odometry,
        faults: Faults {
            scan_latency_secs: args.scan_latency,
            odom_hz: args.odom_hz,
            no_return_m: args.no_return,
            declared_range_m: args.declared_range,
            turn_scale_error: args.turn_scale_error,
            slip_every_secs: args.slip_every,
        },
        ..SimConfig::default()
    };
    // The log is held whole until written: a FLASER line of up to 7
    // characters a beam and its stamps and poses, an ODOM line per
    // physics step, a ground-truth pose a scan.
    let scans = args.duration * config.scan_hz;
    let per_scan = (args.beams * 7 + 400) as f64;
    let limit = args.memory_limit_mb.map(|mb| mb.saturating_mul(1 << 20));
    if let Err(e) = MemoryBudget::for_run(limit).raised_with("--memory-limit-mb").check(
        format!(
            "--duration {}: a log of {} scans of {} beams",
            readable_number(args.duration),
            readable_number(scans.ceil()),
            args.beams
        ),
        scans * per_scan,
    ) {
        eprintln!("error: {e}");
        return ExitCode::from(EXIT_INVALID);
    }
    let started = Instant::now();
    let floor = match floor_for(&args.world, args.seed) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    let sim = match Simulation::new(floor, config) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    if let Err(code) = super::writable_out(&args.out) {
        return code;
    }
    match write_run(sim, &args.out) {
        Ok(s) => {
            outln!(
                "simulated {:.0} s in {:.2} s: {} scans, {} local and {} loop relations in {}",
                args.duration,
                started.elapsed().as_secs_f64(),
                s.scans,
                s.local_relations,
                s.loop_relations,
                args.out.display()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: cannot write into {}: {e}", args.out.display());
            ExitCode::from(EXIT_FAILED)
        }
    }
}
