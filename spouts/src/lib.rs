//! squall-spouts: sources — log readers (CARMEN, ROS 2 bags), simulators and
//! network ingest.

pub mod carmen;
mod clocked;
pub mod depth;
mod error;
#[cfg(feature = "cluster")]
pub mod live;
pub mod pace;
pub mod rmw_zenoh;
pub mod rosbag2;
pub mod sim;

pub use error::{Error, Result};

use squall_topology::Registry;

/// Registers every source kind (`sim`, `carmen`, `rosbag2`,
/// `depth_sim`; with the `cluster` feature the live link, `live.ingest` and
/// `live.publish`; without it those two are recorded as compiled out).
pub fn register(r: &mut Registry) {
    r.register_spout("sim", sim::SimSpout::from_params);
    r.register_spout("carmen", carmen::CarmenSpout::from_params);
    r.register_spout("rosbag2", rosbag2::Rosbag2Spout::from_params);
    r.register_spout("depth_sim", depth::DepthSimSpout::from_params);
    #[cfg(feature = "cluster")]
    {
        r.register_spout("live.ingest", live::LiveIngest::from_params);
        r.register_bolt("live.publish", live::LivePublish::from_params);
    }
    #[cfg(not(feature = "cluster"))]
    {
        r.compiled_out("live.ingest", "cluster");
        r.compiled_out("live.publish", "cluster");
    }
}
