//! The simulated world: line maps or a generated office, a robot exploring
//! it, a laser and wheel odometry, with ground truth.

pub mod campus;
pub mod office;
pub mod output;
pub mod people;
pub mod ring;
pub mod roadmap;
pub mod robot;
mod spout;

pub use robot::{Carry, Faults, Kidnap, OdometryQuality, SimConfig, SimEvent, Simulation, Start};
pub use spout::{OUTPUT_BYTES_PER_SCAN, SimSpout, outputs_fit};

use crate::{Error, Result};

/// Roadmap spacing for line-map worlds, metres.
pub const ROADMAP_SPACING: f64 = 0.5;
/// Clearance the robot keeps from walls in line-map worlds, metres.
pub const ROADMAP_MARGIN: f64 = 0.35;

/// The world of the simulating spouts (`sim`, `depth_sim`) when their
/// params name none: the generated office.
pub const DEFAULT_WORLD: &str = "office";

/// The generated open site ([`campus`]), a world name like `office`.
pub const CAMPUS_WORLD: &str = "campus";

/// The laser range a world is simulated with unless told otherwise,
/// metres: 80 on the open campus, 30 indoors.
pub fn laser_range_for(world: &str) -> f64 {
    if world == CAMPUS_WORLD { campus::CAMPUS_RANGE } else { SimConfig::default().range_max }
}

/// The robot's top speed in a world, m/s: 1.5 on the open campus (so
/// that ten minutes cross it and close loops), 0.6 indoors.
pub fn top_speed_for(world: &str) -> f64 {
    if world == CAMPUS_WORLD { campus::CAMPUS_SPEED } else { SimConfig::default().max_speed }
}

/// The line-map file a world name names (`None` for the generated
/// worlds, `office`, `campus` and `ring`): what a simulation reads.
pub fn world_file(world: &str) -> Option<&std::path::Path> {
    (world != "office" && world != CAMPUS_WORLD && world != ring::RING_WORLD)
        .then(|| std::path::Path::new(world))
}

/// The floor for a world name: `office`, `campus` or `ring` (generated from
/// `seed`) or the path of a line-map file (with a roadmap through it).
pub fn floor_for(world: &str, seed: u64) -> Result<office::Floor> {
    if world == "office" {
        return Ok(office::office(seed, 3, 2));
    }
    if world == ring::RING_WORLD {
        return Ok(ring::ring(seed));
    }
    if world == CAMPUS_WORLD {
        return campus::campus(seed).map_err(|source| Error::Roadmap { world: world.to_string(), source });
    }
    let file = std::path::Path::new(world);
    squall_topology::confine::check_read(file)?;
    let walls = squall_core::linemap::LineMap::load(file)?;
    roadmap::roadmap(walls, ROADMAP_SPACING, ROADMAP_MARGIN)
        .map_err(|source| Error::Roadmap { world: world.to_string(), source })
}
