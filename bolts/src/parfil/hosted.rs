//! parfil on the particle filter kinds (`model = "parfil"`): the state is
//! a pose and so is the snapshot.

use squall_core::geometry::Pose2;
use squall_topology::bounds::MemoryBudget;

use crate::parfil::{ParfilModel, ParfilOptions};
use crate::pf::kinds::{HostedModel, from_table};

impl HostedModel for ParfilModel {
    type Snapshot = Pose2;

    fn from_table(table: toml::Table, budget: MemoryBudget) -> crate::Result<Self> {
        let options = from_table::<ParfilOptions>(table)?;
        let bytes = options.particles as f64 * std::mem::size_of::<(usize, Pose2)>() as f64;
        budget.check(format!("{} particles", options.particles), bytes)?;
        ParfilModel::new(options)
    }

    fn snapshot(&self, state: &Pose2) -> Pose2 {
        *state
    }
}
