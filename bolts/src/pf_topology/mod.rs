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
//! `model = "slam"`, `"parfil"` or `"cgr"` (the model the run uses).

pub mod dispatcher;
pub mod matcher;
pub mod messages;
pub mod resampler;
mod slam_transfer;

use squall_topology::{
    Bolt, BoxError, Declarer, Emitter, Message, MessageType, ParamError, Params, Registry, TaskContext, Tuple,
};

use crate::cgr::model::CgrModel;
use crate::cgr::observation::Observation2d;
use crate::parfil::{ParfilModel, ParfilOptions, ParfilReading};
use crate::pf::ParticleModel;
use crate::pf_topology::dispatcher::Dispatcher;
use crate::pf_topology::matcher::Matcher;
use crate::slam::grid::TiledGrid;
use crate::slam::model::{SlamModel, SlamParticle};
use crate::slam::options::SlamOptions;
use squall_core::geometry::Pose2;
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::LaserReading;

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

impl HostedModel for SlamModel {
    type Snapshot = OccupancyGrid;

    fn from_table(table: toml::Table) -> Result<Self, String> {
        SlamModel::new(from_table::<SlamOptions>(table)?)
    }

    fn snapshot(&self, state: &SlamParticle) -> OccupancyGrid {
        state.map.to_occupancy()
    }

    fn transfer_message() -> MessageType {
        MessageType::incremental::<messages::Transfer<SlamParticle, LaserReading>>()
    }

    fn memory<'a>(&self, states: impl Iterator<Item = &'a SlamParticle>) -> u64 {
        TiledGrid::distinct_tiles(states.flat_map(SlamParticle::grids)).1 as u64
    }
}

impl HostedModel for ParfilModel {
    type Snapshot = Pose2;

    fn from_table(table: toml::Table) -> Result<Self, String> {
        ParfilModel::new(from_table::<ParfilOptions>(table)?)
    }

    fn snapshot(&self, state: &Pose2) -> Pose2 {
        *state
    }
}

impl HostedModel for CgrModel {
    type Snapshot = Pose2;

    fn from_table(table: toml::Table) -> Result<Self, String> {
        crate::cgr_topology::cgr_model(table)
    }

    fn snapshot(&self, state: &Pose2) -> Pose2 {
        *state
    }
}

/// A settings struct from a component's params table; the error is the
/// TOML decoder's message (it names the key).
pub(crate) fn from_table<T: serde::de::DeserializeOwned>(table: toml::Table) -> Result<T, String> {
    toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| e.to_string().trim().to_string())
}

/// The models the kinds know, by their `model` name.
const MODELS: &[&str] = &["slam", "parfil", "cgr"];

fn model_of(p: &Params) -> Result<&str, ParamError> {
    let name = p
        .table()
        .get("model")
        .and_then(|v| v.as_str())
        .ok_or_else(|| ParamError::new(format!("`model` is required: one of {}", MODELS.join(", "))))?;
    MODELS
        .iter()
        .find(|&&m| m == name)
        .copied()
        .ok_or_else(|| ParamError::new(format!("unknown model \"{name}\": one of {}", MODELS.join(", "))))
}

/// One bolt type per kind whatever the model: each variant is the kind for
/// one model, chosen by the `model` param.
macro_rules! per_model {
    ($(#[$doc:meta])* $name:ident { $($variant:ident($inner:ty)),+ $(,)? }) => {
        $(#[$doc])*
        #[derive(Debug)]
        pub enum $name {
            $(
                #[allow(missing_docs)]
                $variant(Box<$inner>),
            )+
        }

        impl Bolt for $name {
            fn declare(&self, d: &mut Declarer) {
                match self { $($name::$variant(b) => b.declare(d),)+ }
            }

            async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
                match self { $($name::$variant(b) => b.prepare(ctx).await,)+ }
            }

            async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
                match self { $($name::$variant(b) => b.execute(input, out).await,)+ }
            }

            async fn tick(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
                match self { $($name::$variant(b) => b.tick(out).await,)+ }
            }

            async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
                match self { $($name::$variant(b) => b.finish(out).await,)+ }
            }
        }
    };
}

per_model!(
    /// `pf.dispatcher` for the run's model.
    AnyDispatcher {
        Slam(Dispatcher<LaserReading>),
        Parfil(Dispatcher<ParfilReading>),
        Cgr(Dispatcher<Observation2d>),
    }
);

per_model!(
    /// `pf.matcher` for the run's model.
    AnyMatcher { Slam(Matcher<SlamModel>), Parfil(Matcher<ParfilModel>), Cgr(Matcher<CgrModel>) }
);

/// Registers `pf.dispatcher`, `pf.matcher`, `pf.resampler` and `cgr.laser`.
pub fn register(r: &mut Registry) {
    r.register_bolt("pf.dispatcher", |p: &Params| {
        Ok(match model_of(p)? {
            "slam" => AnyDispatcher::Slam(Box::new(Dispatcher::from_params(p)?)),
            "parfil" => AnyDispatcher::Parfil(Box::new(Dispatcher::from_params(p)?)),
            _ => AnyDispatcher::Cgr(Box::new(Dispatcher::from_params(p)?)),
        })
    });
    r.register_bolt("pf.matcher", |p: &Params| {
        Ok(match model_of(p)? {
            "slam" => AnyMatcher::Slam(Box::new(Matcher::from_params(p)?)),
            "parfil" => AnyMatcher::Parfil(Box::new(Matcher::from_params(p)?)),
            _ => AnyMatcher::Cgr(Box::new(Matcher::from_params(p)?)),
        })
    });
    r.register_bolt("cgr.laser", crate::cgr_topology::LaserPoints::from_params);
    r.register_bolt("cgr.fspf", crate::cgr_topology::DepthPoints::from_params);
    r.register_bolt("pf.resampler", |p: &Params| {
        model_of(p)?;
        resampler::Resampler::from_params(p)
    });
}
