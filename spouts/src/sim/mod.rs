//! The simulated world: line maps or a generated office, a robot exploring
//! it, a laser and wheel odometry, with ground truth.

pub mod office;
pub mod output;
mod rng;
pub mod robot;
mod spout;
pub mod world;

pub use robot::{SimConfig, SimEvent, Simulation};
pub use spout::SimSpout;
