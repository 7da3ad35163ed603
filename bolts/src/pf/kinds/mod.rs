//! The particle filter as a topology (seed 003's Storm topology):
//!
//! ```text
//! source → pf.dispatcher → pf.matcher × K → pf.resampler → sinks
//!               ↑ ready         ↑ decision  │
//!               └───────────────┴───────────┘   (feedback edges)
//! ```
//!
//! Thin adapters over [`crate::pf`]: the dispatcher numbers readings and
//! holds the source back while the matchers work, the matcher tasks each
//! hold a share of the particles and exchange parents' states as peers,
//! the resampler owns the weights and the lineage. The kinds are generic
//! over a [`HostedModel`] and name none: each model registers itself with
//! [`register_model`] under the name a topology gives as `model = "..."`.

pub mod dispatcher;
pub mod matcher;
pub mod messages;
pub mod resampler;

use squall_topology::bounds::MemoryBudget;
use squall_topology::{Message, MessageType, Registry};

use crate::pf::ParticleModel;
use crate::pf::kinds::dispatcher::Dispatcher;
use crate::pf::kinds::matcher::Matcher;
use crate::pf::kinds::resampler::Resampler;

/// A [`ParticleModel`] the topology can host: built from a component's
/// params, its readings and states able to travel, and a snapshot of the
/// best particle to emit (the map, for SLAM).
pub trait HostedModel: ParticleModel<Input: Message, State: Message> + Sized {
    /// What the task holding the best particle emits on `map`.
    type Snapshot: Message;

    /// The model from a component's params (without `model` and
    /// `map_interval`); errors name the wrong setting. What its particles
    /// and structures would take before the first reading is checked
    /// against `budget` (the run's memory limit).
    fn from_table(table: toml::Table, budget: MemoryBudget) -> crate::Result<Self>;

    /// The snapshot of a particle.
    fn snapshot(&self, state: &Self::State) -> Self::Snapshot;

    /// How transfers of states between matcher tasks are described; a
    /// model whose states are large makes them cross processes
    /// incrementally.
    fn transfer_message() -> MessageType {
        MessageType::of::<messages::Transfer<Self::State, Self::Input>>()
    }

    /// Bytes the states take together (shared parts counted once).
    fn memory<'a>(&self, states: impl Iterator<Item = &'a Self::State>) -> u64
    where
        Self::State: 'a,
    {
        states.map(|s| self.state_bytes(s)).sum()
    }
}

/// A settings struct from a component's params table; the error is the
/// TOML decoder's message (it names the key).
pub(crate) fn from_table<T: serde::de::DeserializeOwned>(table: toml::Table) -> crate::Result<T> {
    toml::Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| crate::Error::Params(e.to_string().trim().to_string()))
}

/// Registers `model` under `name`: a component of kind `pf.dispatcher`,
/// `pf.matcher` or `pf.resampler` with `model = "<name>"` runs on it.
pub fn register_model<M: HostedModel>(r: &mut Registry, name: &str) {
    r.register_bolt_variant("pf.dispatcher", "model", name, Dispatcher::<M::Input>::from_params);
    r.register_bolt_variant("pf.matcher", "model", name, Matcher::<M>::from_params);
    r.register_bolt_variant("pf.resampler", "model", name, Resampler::from_params);
}
