//! The `parfil` spout: the thesis's toy world (a wrap-around room with a
//! landmark in each corner) driven in a loop. Streams `reading`
//! (`ParfilReading`: the control and four noisy bearings) and `truth`
//! (`PoseStamped`, stamped with the iteration). The first reading carries
//! no motion; it starts the filter.

use super::{ParfilOptions, ParfilReading, ParfilWorld};
use serde::Deserialize;
use squall_core::geometry::Pose2;
use squall_core::sensor::PoseStamped;
use squall_topology::{BoxError, Declarer, Emitter, ParamError, Params, Spout, SpoutStatus, TaskContext};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct P {
    /// Iterations after the first reading. The default is 1000.
    #[serde(default = "default_iterations")]
    iterations: u64,
    /// Forward distance per iteration, metres. The default is 1.5.
    #[serde(default = "default_forward")]
    forward: f64,
    /// Turn per iteration, radians. The default is 0.05.
    #[serde(default = "default_turn")]
    turn: f64,
    /// The world (room size, noise); what the matcher's model must assume.
    #[serde(default)]
    world: ParfilOptions,
    /// Seed; the default is the topology's seed.
    seed: Option<u64>,
}

fn default_iterations() -> u64 {
    1000
}
fn default_forward() -> f64 {
    1.5
}
fn default_turn() -> f64 {
    0.05
}

/// Emits a simulated parfil run.
#[derive(Debug)]
pub struct ParfilSpout {
    p: P,
    world: Option<ParfilWorld>,
    emitted: u64,
}

impl ParfilSpout {
    /// Builds the spout from its `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let mut params: P = p.parse()?;
        params.world.check().map_err(ParamError::new)?;
        params.seed.get_or_insert(p.seed());
        Ok(ParfilSpout { p: params, world: None, emitted: 0 })
    }
}

impl Spout for ParfilSpout {
    fn declare(&self, d: &mut Declarer) {
        d.output::<ParfilReading>("reading").output::<PoseStamped>("truth");
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        ctx.expect_emits(2 * (self.p.iterations + 1));
        let (w, h) = (self.p.world.width, self.p.world.height);
        let start = Pose2::new(0.3 * w, 0.5 * h, 0.5);
        self.world = Some(ParfilWorld::new(self.p.world.clone(), start, self.p.seed.unwrap_or(0)));
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        if self.emitted > self.p.iterations {
            return Ok(SpoutStatus::Done);
        }
        let world = self.world.as_mut().ok_or("the parfil world was not opened")?;
        let (forward, turn) = if self.emitted == 0 { (0.0, 0.0) } else { (self.p.forward, self.p.turn) };
        let mut reading = world.step(forward, turn);
        reading.iteration = self.emitted;
        let truth = PoseStamped { stamp: self.emitted as f64, pose: world.truth() };
        self.emitted += 1;
        out.emit("reading", reading).await?;
        out.emit("truth", truth).await?;
        Ok(SpoutStatus::Continue)
    }
}
