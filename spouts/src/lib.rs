//! squall-spouts: sources — log readers (CARMEN, ROS 2 bags), simulators and
//! network ingest.

pub mod carmen;
pub mod depth;
pub mod parfil;
pub mod rosbag2;
pub mod sim;

use squall_topology::Registry;

/// Registers every source kind: `carmen`, `rosbag2`, `sim`.
pub fn register(r: &mut Registry) {
    r.register_spout("sim", sim::SimSpout::from_params);
    r.register_spout("carmen", carmen::CarmenSpout::from_params);
    r.register_spout("rosbag2", rosbag2::Rosbag2Spout::from_params);
    r.register_spout("parfil", parfil::ParfilSpout::from_params);
    r.register_spout("depth_sim", depth::DepthSimSpout::from_params);
}
