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
//! the resampler owns the weights and the lineage. Every kind takes
//! `model = "slam"` (the model the run uses).

pub mod dispatcher;
pub mod matcher;
pub mod messages;
pub mod resampler;

use squall_topology::{Message, ParamError, Params, Registry};

use crate::map::OccupancyGrid;
use crate::pf::ParticleModel;
use crate::sensor::LaserReading;
use crate::slam::model::{SlamModel, SlamParticle};
use crate::slam::options::SlamOptions;

/// A [`ParticleModel`] the topology can host: built from a component's
/// params, its readings and states able to travel, and a snapshot of the
/// best particle to emit (the map, for SLAM).
pub trait HostedModel: ParticleModel<Input: Message, State: Message> + Sized {
    /// What the task holding the best particle emits on `map`.
    type Snapshot: Message;

    /// The model from a component's params (without `model` and
    /// `map_interval`); errors name the wrong setting.
    fn from_table(table: toml::Table) -> Result<Self, String>;

    /// The snapshot of a particle.
    fn snapshot(&self, state: &Self::State) -> Self::Snapshot;
}

impl HostedModel for SlamModel {
    type Snapshot = OccupancyGrid;

    fn from_table(table: toml::Table) -> Result<Self, String> {
        let options: SlamOptions = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| e.to_string().trim().to_string())?;
        SlamModel::new(options)
    }

    fn snapshot(&self, state: &SlamParticle) -> OccupancyGrid {
        state.map.to_occupancy()
    }
}

/// The models the kinds know, by their `model` name.
const MODELS: &[&str] = &["slam"];

fn model_of(p: &Params) -> Result<String, ParamError> {
    let name = p
        .table()
        .get("model")
        .and_then(|v| v.as_str())
        .ok_or_else(|| ParamError::new(format!("`model` is required: one of {}", MODELS.join(", "))))?;
    if !MODELS.contains(&name) {
        return Err(ParamError::new(format!("unknown model \"{name}\": one of {}", MODELS.join(", "))));
    }
    Ok(name.to_string())
}

/// Registers `pf.dispatcher`, `pf.matcher` and `pf.resampler`.
pub fn register(r: &mut Registry) {
    r.register_bolt("pf.dispatcher", |p: &Params| {
        model_of(p)?;
        dispatcher::Dispatcher::<LaserReading>::from_params(p)
    });
    r.register_bolt("pf.matcher", |p: &Params| {
        model_of(p)?;
        matcher::Matcher::<SlamModel>::from_params(p)
    });
    r.register_bolt("pf.resampler", |p: &Params| {
        model_of(p)?;
        resampler::Resampler::from_params(p)
    });
}
