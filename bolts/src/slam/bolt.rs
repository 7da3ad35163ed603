//! `slam.rbpf`: the serial RBPF as a bolt. Takes `LaserReading`s; emits the
//! best estimate for every scan on `pose`, the best particle's map on `map`
//! (every `map_interval` processed scans, and at the end), and at the end,
//! on `trajectory`, a pose for every scan read from the final best
//! particle's lineage (processed scans) composed with odometry in between.
//! Metrics: pose evaluations per particle, Neff, resamplings, tiles cloned,
//! map memory, milliseconds per processed scan.

use std::time::Instant;

use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, TaskContext, Tuple};

use crate::geometry::Pose2;
use crate::map::OccupancyGrid;
use crate::sensor::{LaserReading, PoseStamped};
use crate::slam::filter::Rbpf;
use crate::slam::options::SlamOptions;

/// The SLAM bolt.
#[derive(Debug)]
pub struct SlamBolt {
    options: SlamOptions,
    map_interval: u64,
    filter: Option<Rbpf>,
    /// (stamp, odometry) of every scan, for the final trajectory.
    scans: Vec<(f64, Pose2)>,
    processed: u64,
}

impl SlamBolt {
    /// Builds the bolt: every [`SlamOptions`] key, plus `map_interval`
    /// (processed scans between map emits; 0, the default, emits only at
    /// the end).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let mut table = p.table().clone();
        let map_interval = match table.remove("map_interval") {
            None => 0,
            Some(v) => v
                .as_integer()
                .and_then(|i| u64::try_from(i).ok())
                .ok_or_else(|| ParamError::new(format!("map_interval must be a count ≥ 0, got {v}")))?,
        };
        let options: SlamOptions = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| ParamError::new(e.to_string().trim()))?;
        options.check().map_err(ParamError::new)?;
        if p.parallelism() != 1 {
            return Err(ParamError::new(
                "slam.rbpf runs as one task; parallel matchers come with the particle filter topology",
            ));
        }
        Ok(SlamBolt { options, map_interval, filter: None, scans: Vec::new(), processed: 0 })
    }

    fn best_map(&self) -> Option<OccupancyGrid> {
        self.filter.as_ref()?.best().map(|p| p.map.to_occupancy())
    }
}

impl Bolt for SlamBolt {
    fn declare(&self, d: &mut Declarer) {
        d.input::<LaserReading>()
            .output::<PoseStamped>("pose")
            .output::<OccupancyGrid>("map")
            .output::<PoseStamped>("trajectory");
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.filter = Some(Rbpf::new(self.options.clone(), ctx.seed())?);
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let scan = input.get::<LaserReading>().ok_or("slam.rbpf takes LaserReading")?;
        let filter = self.filter.as_mut().ok_or("slam.rbpf was not prepared")?;
        let started = Instant::now();
        let report = filter.process(scan);
        let elapsed = started.elapsed();
        let pose = filter.estimate(&scan.odometry).ok_or("no particles")?;
        if let Some(report) = &report {
            self.processed += 1;
            out.record("processed_scan_us", elapsed.as_micros() as u64);
            for e in &report.evaluations {
                out.record("evaluations_per_particle", u64::from(*e));
            }
            out.record("neff_x100", (report.neff * 100.0) as u64);
            out.count("resamplings", u64::from(report.resampled));
            out.count("tiles_cloned", report.update_work);
        }
        self.scans.push((scan.stamp, scan.odometry));
        out.emit("pose", PoseStamped { stamp: scan.stamp, pose }).await?;
        // Once per `map_interval` processed scans, at the scan that made the
        // count.
        if report.is_some() && self.map_interval > 0 && self.processed % self.map_interval == 0 {
            if let Some(map) = self.best_map() {
                out.emit("map", map).await?;
            }
        }
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let Some(filter) = &self.filter else { return Ok(()) };
        let (_, bytes) = filter.map_memory();
        out.count("map_bytes", bytes as u64);
        out.count("processed_scans", self.processed);
        for (stamp, pose) in filter.lineage_poses(self.scans.iter().copied()) {
            out.emit("trajectory", PoseStamped { stamp, pose }).await?;
        }
        if let Some(map) = self.best_map() {
            out.emit("map", map).await?;
        }
        Ok(())
    }
}
