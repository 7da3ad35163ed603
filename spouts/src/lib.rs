//! squall-spouts: sources — log readers (CARMEN, ROS 2 bags), simulators and
//! network ingest.

pub mod carmen;

use squall_topology::Registry;

/// Registers every source kind: `carmen`.
pub fn register(r: &mut Registry) {
    r.register_spout("carmen", carmen::CarmenSpout::from_params);
}
