//! The `sim` spout: the simulator as a source. Streams `scan`
//! (`LaserReading`), `odom` (`Odometry`) and `truth` (`PoseStamped`, the
//! true pose at each scan).

use std::collections::VecDeque;

use serde::Deserialize;
use squall_core::clock::{ClockMode, ScanClock};
use squall_core::no_return::NoReturnMode;
use squall_core::sensor::{LaserReading, Odometry, PoseStamped};
use squall_topology::bounds::{MemoryBudget, OverBudget};
use squall_topology::spec::readable_number;
use squall_topology::{
    BoxError, Declarer, Emitter, ParamError, Params, ReadingCounter, Spout, SpoutStatus, TaskContext,
};

use crate::clocked::ScanConditioner;

use super::robot::{Faults, Kidnap, OdometryQuality, SimConfig, SimEvent, Simulation, Start};
use super::{DEFAULT_WORLD, laser_range_for, top_speed_for};

/// The `sim` spout's params; a param left out takes its value from
/// [`P::default`].
#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct P {
    /// `"office"` (generated from the seed) or a line-map file. The default
    /// is [`DEFAULT_WORLD`], `"office"`.
    world: String,
    /// Simulated seconds. The default is 600.
    duration_secs: f64,
    /// Beams over the field of view. The default is 180.
    beams: usize,
    /// Field of view, degrees. The default is 180.
    fov_deg: f64,
    /// Laser range, metres. The default is 80 on the campus, 30
    /// elsewhere ([`laser_range_for`]).
    range_max: Option<f64>,
    /// Seed; the default (`None`) is the topology's seed.
    seed: Option<u64>,
    /// Stop after this many scans; the default (`None`) is no limit.
    max_scans: Option<u64>,
    /// The wheel odometry: `"good"`, `"poor"` or `"bad"`
    /// ([`OdometryQuality`]). The default is `"poor"`.
    odometry: OdometryQuality,
    /// Where the robot starts: `"first_node"` (the default) or `"drawn"`
    /// per seed ([`Start`]).
    start: Start,
    /// A kidnapping, e.g. `{ at_secs = 10 }` (carried 5–20 m, drawn per
    /// seed; [`Kidnap`]). The default is none.
    kidnap: Option<Kidnap>,
    /// Faults of real sensors, e.g. `{ scan_latency_secs = 0.1, odom_hz = 50 }`
    /// ([`Faults`]). The default is none.
    faults: Faults,
    /// How scans are timed against the odometry: `"auto"` (the default),
    /// `"log"` or seconds, as the log sources ([`ClockMode`]).
    clock_offset: ClockMode,
    /// Mend steps where the wheels slipped, as the log sources (off by
    /// default).
    mend_slips: bool,
    /// The readings that mean no return, as the log sources
    /// ([`NoReturnMode`]; the default `"auto"`).
    no_return: NoReturnMode,
}

impl Default for P {
    fn default() -> Self {
        P {
            world: DEFAULT_WORLD.into(),
            duration_secs: 600.0,
            beams: 180,
            fov_deg: 180.0,
            range_max: None,
            seed: None,
            max_scans: None,
            odometry: OdometryQuality::default(),
            start: Start::default(),
            kidnap: None,
            faults: Faults::default(),
            clock_offset: ClockMode::default(),
            mend_slips: false,
            no_return: NoReturnMode::default(),
        }
    }
}

/// What one simulated scan leaves in memory downstream until the run
/// ends, bytes: its poses in the trajectories and ground truth, and its
/// hypotheses. Measured: the peak resident memory of `squall localize
/// --map EDSH120_vector.txt --sim` grows by 3.2 MB from 60 to 240
/// simulated seconds, 1800 scans.
pub const OUTPUT_BYTES_PER_SCAN: usize = 1800;

/// Checks that a simulated run of `secs` seconds, a reading (`unit`:
/// "scans", "frames") every 1/`hz` s, leaves outputs that fit `budget`
/// ([`OUTPUT_BYTES_PER_SCAN`] a reading): the sim spouts' factories and
/// `squall localize`, which replays the route before the topology is
/// built, ask the same.
pub fn outputs_fit(budget: MemoryBudget, secs: f64, hz: f64, unit: &str) -> Result<(), OverBudget> {
    let readings = secs * hz;
    budget.check(
        format!(
            "a simulated run of {} s ({} {unit} of about {OUTPUT_BYTES_PER_SCAN} bytes each in the run's outputs)",
            readable_number(secs),
            readable_number(readings.ceil())
        ),
        readings * OUTPUT_BYTES_PER_SCAN as f64,
    )
}

/// Emits a simulated run.
#[derive(Debug)]
pub struct SimSpout {
    world: String,
    max_scans: Option<u64>,
    scans: u64,
    config: SimConfig,
    sim: Option<Simulation>,
    /// The scans on their way out.
    front: ScanConditioner,
    /// The true poses of the scans the clock holds, in order.
    truths: VecDeque<PoseStamped>,
    /// Scans emitted, for the progress display.
    readings: ReadingCounter,
}

impl SimSpout {
    /// Builds the spout from its `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: P = p.parse()?;
        let config = SimConfig {
            seed: params.seed.unwrap_or(p.seed()),
            duration_secs: params.duration_secs,
            beams: params.beams,
            fov: params.fov_deg.to_radians(),
            range_max: params.range_max.unwrap_or_else(|| laser_range_for(&params.world)),
            max_speed: top_speed_for(&params.world),
            odometry: params.odometry,
            start: params.start,
            kidnap: params.kidnap,
            faults: params.faults,
            ..SimConfig::default()
        };
        config.check().map_err(ParamError::new)?;
        outputs_fit(p.budget(), config.duration_secs, config.scan_hz, "scans").map_err(ParamError::new)?;
        Ok(SimSpout {
            world: params.world,
            max_scans: params.max_scans,
            scans: 0,
            config,
            sim: None,
            // A simulated robot is live: its scans flow through the warm-up.
            front: ScanConditioner::new(
                &params.no_return,
                ScanClock::flowing(params.clock_offset),
                params.mend_slips,
            ),
            truths: VecDeque::new(),
            readings: ReadingCounter::default(),
        })
    }
}

impl Spout for SimSpout {
    fn declare(&self, d: &mut Declarer) {
        d.output::<LaserReading>("scan").output::<Odometry>("odom").output::<PoseStamped>("truth");
        if let Some(file) = super::world_file(&self.world) {
            d.reads(file);
        }
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        let floor = super::floor_for(&self.world, self.config.seed)?;
        let scans = (self.config.duration_secs * self.config.scan_hz) as u64;
        ctx.expect_emits(scans * 3);
        self.readings = ctx.readings("scans", || Some(self.max_scans.map_or(scans, |m| m.min(scans))));
        self.sim = Some(Simulation::new(floor, self.config.clone())?);
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        let sim = self.sim.as_mut().ok_or("the simulation was not opened")?;
        let event = if self.max_scans.is_some_and(|m| self.scans >= m) { None } else { sim.next() };
        match event {
            None => {
                self.front.finish();
                self.emit_ready(out).await?;
                self.front.report(out);
                return Ok(SpoutStatus::Done);
            }
            Some(SimEvent::Odom(o)) => {
                self.front.odometry(o.stamp, o.pose);
                out.emit("odom", o).await?;
            }
            Some(SimEvent::Scan(scan, truth)) => {
                self.scans += 1;
                self.truths.push_back(PoseStamped { stamp: scan.stamp, pose: truth });
                self.front.scan(scan);
            }
        }
        self.emit_ready(out).await?;
        Ok(SpoutStatus::Continue)
    }
}

impl SimSpout {
    /// Emits the scans whose pose the clock has decided, each with its
    /// true pose.
    async fn emit_ready(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        while let Some(scan) = self.front.next_ready() {
            let truth = self.truths.pop_front().ok_or("a scan without its true pose")?;
            self.readings.add(1);
            out.emit("scan", scan).await?;
            out.emit("truth", truth).await?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_left_out_take_the_documented_defaults() {
        let p: P = Params::new(toml::Table::new(), 7, 1).parse().unwrap();
        assert_eq!((p.world.as_str(), p.duration_secs, p.beams), ("office", 600.0, 180));
        assert_eq!((p.fov_deg, p.range_max, p.seed, p.max_scans), (180.0, None, None, None));
        let spout = SimSpout::from_params(&Params::new(toml::Table::new(), 7, 1)).unwrap();
        assert_eq!(spout.config, SimConfig { seed: 7, fov: 180f64.to_radians(), ..SimConfig::default() });
        let e =
            SimSpout::from_params(&Params::new(toml::from_str("fov_deg = 0").unwrap(), 7, 1)).unwrap_err();
        assert_eq!(e.to_string(), "field of view must be in (0°, 360°], got 0°");
    }
}
