//! parfil on the particle filter kinds (`model = "parfil"`): the state is
//! a pose and so is the snapshot.

use squall_core::geometry::Pose2;

use crate::parfil::{ParfilModel, ParfilOptions};
use crate::pf::kinds::{HostedModel, from_table};

impl HostedModel for ParfilModel {
    type Snapshot = Pose2;

    fn from_table(table: toml::Table) -> crate::Result<Self> {
        ParfilModel::new(from_table::<ParfilOptions>(table)?)
    }

    fn snapshot(&self, state: &Pose2) -> Pose2 {
        *state
    }
}
