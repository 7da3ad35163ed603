//! The simulated world: line maps or a generated office, a robot exploring
//! it, a laser and wheel odometry, with ground truth.

pub mod office;
pub mod output;
pub mod people;
pub mod roadmap;
pub mod robot;
mod spout;

pub use robot::{SimConfig, SimEvent, Simulation};
pub use spout::SimSpout;

/// Roadmap spacing for line-map worlds, metres.
pub const ROADMAP_SPACING: f64 = 0.5;
/// Clearance the robot keeps from walls in line-map worlds, metres.
pub const ROADMAP_MARGIN: f64 = 0.35;

/// The floor for a world name: `office` (generated from `seed`) or the path
/// of a line-map file (with a roadmap through it).
pub fn floor_for(world: &str, seed: u64) -> Result<office::Floor, String> {
    if world == "office" {
        return Ok(office::office(seed, 3, 2));
    }
    let walls =
        squall_core::linemap::LineMap::load(std::path::Path::new(world)).map_err(|e| e.to_string())?;
    roadmap::roadmap(walls, ROADMAP_SPACING, ROADMAP_MARGIN).map_err(|e| format!("{world}: {e}"))
}
