//! SLAM on the particle filter kinds (`model = "slam"`): the model built
//! from a matcher's params, the best particle's map as its snapshot, its
//! memory counted by distinct tiles, and transfers that cross processes
//! incrementally ([`crate::slam::transfer_message`]).

use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::LaserReading;
use squall_topology::bounds::MemoryBudget;
use squall_topology::{MessageType, Registry};

use crate::pf::kinds::messages::Transfer;
use crate::pf::kinds::{HostedModel, from_table, register_model};
use crate::slam::grid::{Tile, TiledGrid};
use crate::slam::model::{SlamModel, SlamParticle};
use crate::slam::options::SlamOptions;

impl HostedModel for SlamModel {
    type Snapshot = OccupancyGrid;

    fn from_table(table: toml::Table, budget: MemoryBudget) -> crate::Result<Self> {
        let options = from_table::<SlamOptions>(table)?;
        // Every particle holds its record and, from the first reading on,
        // at least one tile of its own map (the first scan written at its
        // own pose).
        let each = std::mem::size_of::<(usize, SlamParticle)>() + std::mem::size_of::<Tile>();
        budget.check(
            format!(
                "{} particles of at least {each} bytes (a record and a map tile each)",
                options.particles
            ),
            options.particles as f64 * each as f64,
        )?;
        SlamModel::new(options)
    }

    fn snapshot(&self, state: &SlamParticle) -> OccupancyGrid {
        state.map.to_occupancy()
    }

    fn transfer_message() -> MessageType {
        MessageType::incremental::<Transfer<SlamParticle, LaserReading>>()
    }

    fn memory<'a>(&self, states: impl Iterator<Item = &'a SlamParticle>) -> u64 {
        TiledGrid::distinct_tiles(states.flat_map(SlamParticle::grids)).1 as u64
    }
}

/// Registers SLAM as the particle filter kinds' `model = "slam"`.
pub fn register(r: &mut Registry) {
    register_model::<SlamModel>(r, "slam");
    r.register_bolt("slam.backend", crate::slam::backend::Backend::from_params);
}
