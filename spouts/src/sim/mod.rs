//! The simulated world: line maps or a generated office, a robot exploring
//! it, a laser and wheel odometry, with ground truth.

pub mod office;
pub mod output;
pub mod people;
pub mod roadmap;
pub mod robot;
mod spout;

pub use robot::{OdometryQuality, SimConfig, SimEvent, Simulation};
pub use spout::SimSpout;

use crate::{Error, Result};

/// Roadmap spacing for line-map worlds, metres.
pub const ROADMAP_SPACING: f64 = 0.5;
/// Clearance the robot keeps from walls in line-map worlds, metres.
pub const ROADMAP_MARGIN: f64 = 0.35;

/// The world of the simulating spouts (`sim`, `depth_sim`) when their
/// params name none: the generated office.
pub const DEFAULT_WORLD: &str = "office";

/// The floor for a world name: `office` (generated from `seed`) or the path
/// of a line-map file (with a roadmap through it).
pub fn floor_for(world: &str, seed: u64) -> Result<office::Floor> {
    if world == "office" {
        return Ok(office::office(seed, 3, 2));
    }
    let walls = squall_core::linemap::LineMap::load(std::path::Path::new(world))?;
    roadmap::roadmap(walls, ROADMAP_SPACING, ROADMAP_MARGIN)
        .map_err(|source| Error::Roadmap { world: world.to_string(), source })
}
