//! Simulated worlds as logs: each `--sim-worlds` world with each
//! `--odometry` quality becomes a CARMEN log with its relations and ground
//! truth, written once per study under `DIR/worlds/<world>-<quality>/`,
//! and is then studied like any log.

use std::path::{Path, PathBuf};

use squall_spouts::sim::office::Floor;
use squall_spouts::sim::output::write_run;
use squall_spouts::sim::{OdometryQuality, SimConfig, Simulation, floor_for, laser_range_for, top_speed_for};

/// The simulator's seed for every world: the route and the sensor noise
/// stay the same from one study to the next; the study's seeds are
/// SLAM's.
pub(super) const WORLD_SEED: u64 = 1;

/// One simulated world at one odometry quality.
#[derive(Debug, Clone)]
pub(super) struct World {
    /// The floor of `office` or of a line-map file, built once.
    floor: Floor,
    odometry: OdometryQuality,
    /// `<world>-<quality>`: its folder and its log's name.
    pub(super) name: String,
    /// The laser's range in this world, metres.
    range_max: f64,
    /// The robot's top speed, m/s.
    max_speed: f64,
}

/// Every (world, quality), each world checked (it exists and a robot can
/// drive it) before anything is written.
pub(super) fn plan(
    worlds: &[String],
    qualities: &[OdometryQuality],
    duration: f64,
) -> Result<Vec<World>, String> {
    let positive = duration.is_finite() && duration > 0.0;
    if !worlds.is_empty() && !positive {
        return Err(format!("--sim-duration must be > 0 s, got {duration}"));
    }
    let mut plan = Vec::new();
    for world in worlds {
        let floor = floor_for(world, WORLD_SEED).map_err(|e| format!("--sim-worlds {world}: {e}"))?;
        let stem =
            Path::new(world).file_stem().map_or_else(|| world.clone(), |s| s.to_string_lossy().into_owned());
        for &odometry in qualities {
            let name = format!("{stem}-{}", odometry.name());
            plan.push(World {
                floor: floor.clone(),
                odometry,
                name,
                range_max: laser_range_for(world),
                max_speed: top_speed_for(world),
            });
        }
    }
    Ok(plan)
}

/// Simulates `world` for `duration` seconds into `out/worlds/<name>/` and
/// returns its log, `<name>.clf`, beside `<name>.relations` and
/// `ground_truth.tum`.
pub(super) fn write(world: &World, duration: f64, out: &Path) -> Result<PathBuf, String> {
    let dir = out.join("worlds").join(&world.name);
    let fail = |e: &dyn std::fmt::Display| format!("simulating {}: {e}", world.name);
    let config = SimConfig {
        seed: WORLD_SEED,
        duration_secs: duration,
        odometry: world.odometry,
        range_max: world.range_max,
        max_speed: world.max_speed,
        ..SimConfig::default()
    };
    let sim = Simulation::new(world.floor.clone(), config).map_err(|e| fail(&e))?;
    write_run(sim, &dir).map_err(|e| fail(&e))?;
    let log = dir.join(format!("{}.clf", world.name));
    std::fs::rename(dir.join("sim.clf"), &log).map_err(|e| fail(&e))?;
    std::fs::rename(dir.join("sim.relations"), dir.join(format!("{}.relations", world.name)))
        .map_err(|e| fail(&e))?;
    Ok(log)
}
