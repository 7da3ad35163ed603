//! ROS 2 bags: the `rosbag2` spout.
//!
//! Reads rosbag2's MCAP and sqlite3 (`.db3`) storage, chosen from the
//! bag's `metadata.yaml` or the file's bytes.
//! Emits scans (with odometry interpolated at their stamps) on `scan` and
//! the odometry stream on `odom`, merged in stamp order, as fast as possible
//! or at the recorded rate times a factor.

mod bag;
mod cdr;
pub mod messages;
mod record_check;

use std::collections::VecDeque;
use std::path::PathBuf;

use serde::Deserialize;
use squall_core::sensor::{LaserReading, Odometry};
use squall_topology::{
    BoxError, Declarer, Emitter, ParamError, Params, ReadingCounter, Spout, SpoutStatus, TaskContext,
};

pub use bag::{
    BagError, BagReadings, MAX_EXTRAPOLATION, Storage, Topics, bag_files, check_bag, interpolate, read_bag,
    read_mcap_bytes,
};
pub use cdr::CdrError;

use crate::pace::{Pacer, pace};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BagParams {
    /// The bag folder, or one .mcap or .db3 file.
    bag: PathBuf,
    #[serde(default = "scan_topic")]
    scan_topic: String,
    #[serde(default = "odom_topic")]
    odom_topic: String,
    #[serde(default = "tf_static_topic")]
    tf_static_topic: String,
    /// `"max"` (the default) or a factor of the recorded rate.
    #[serde(default)]
    rate: Option<toml::Value>,
    /// Stop after this many scans.
    max_scans: Option<u64>,
    /// Skip messages that do not decode (counted) instead of failing.
    #[serde(default)]
    skip_bad: bool,
}

fn scan_topic() -> String {
    Topics::default().scan
}
fn odom_topic() -> String {
    Topics::default().odom
}
fn tf_static_topic() -> String {
    Topics::default().tf_static
}

/// Replays a ROS 2 bag.
#[derive(Debug)]
pub struct Rosbag2Spout {
    bag: PathBuf,
    topics: Topics,
    pacer: Pacer,
    max_scans: Option<u64>,
    scans: VecDeque<LaserReading>,
    odometry: VecDeque<Odometry>,
    without_odometry: u64,
    skipped: u64,
    /// Scans emitted, for the progress display.
    readings: ReadingCounter,
}

impl Rosbag2Spout {
    /// Builds the spout from its `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: BagParams = p.parse()?;
        let topics = Topics {
            skip_bad: params.skip_bad,
            scan: params.scan_topic,
            odom: params.odom_topic,
            tf_static: params.tf_static_topic,
        };
        Ok(Rosbag2Spout {
            bag: params.bag,
            topics,
            pacer: Pacer::new(pace(params.rate.as_ref())?),
            max_scans: params.max_scans,
            scans: VecDeque::new(),
            odometry: VecDeque::new(),
            without_odometry: 0,
            skipped: 0,
            readings: ReadingCounter::default(),
        })
    }
}

impl Spout for Rosbag2Spout {
    fn declare(&self, d: &mut Declarer) {
        d.output::<LaserReading>("scan").output::<Odometry>("odom");
        d.reads(&self.bag);
        // Before the run, where the bag is: a bag squall cannot read, or one
        // without the topics asked for, is invalid input, not a failed run.
        let (bag, topics) = (self.bag.clone(), self.topics.clone());
        d.check_inputs(move || check_bag(&bag, &topics).map(drop).map_err(|e| e.to_string()));
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.pacer.watch(ctx.stop());
        let readings = read_bag(&self.bag, &self.topics)?;
        if readings.scans_without_odometry > 0 {
            tracing::warn!(
                bag = %self.bag.display(),
                "{} scans lie outside the odometry stream and are not emitted",
                readings.scans_without_odometry
            );
        }
        let mut scans = readings.scans;
        if let Some(m) = self.max_scans {
            scans.truncate(usize::try_from(m).unwrap_or(usize::MAX));
            // Odometry past the last emitted scan is not needed.
            let end = scans.last().map_or(f64::NEG_INFINITY, |s| s.stamp);
            self.odometry = readings.odometry.into_iter().filter(|o| o.stamp <= end).collect();
        } else {
            self.odometry = readings.odometry.into();
        }
        ctx.expect_emits((scans.len() + self.odometry.len()) as u64);
        self.readings = ctx.readings("scans", || Some(scans.len() as u64));
        self.scans = scans.into();
        self.without_odometry = readings.scans_without_odometry;
        self.skipped = readings.skipped;
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        let scan_first = match (self.scans.front(), self.odometry.front()) {
            (None, None) => {
                out.count("scans_without_odometry", self.without_odometry);
                out.count("records_skipped", self.skipped);
                return Ok(SpoutStatus::Done);
            }
            (Some(_), None) => true,
            (None, Some(_)) => false,
            (Some(s), Some(o)) => s.stamp <= o.stamp,
        };
        let stamp = if scan_first { self.scans[0].stamp } else { self.odometry[0].stamp };
        let waited = self.pacer.wait_for(stamp).await;
        if !waited.map_err(|e| format!("{}: {e}", self.bag.display()))? {
            return Ok(SpoutStatus::Continue);
        }
        // The match above set `scan_first` only with a scan queued, and
        // cleared it only with odometry queued: neither pop can fail.
        if scan_first {
            let scan = self.scans.pop_front().expect("checked above");
            out.emit("scan", scan).await?;
            self.readings.add(1);
        } else {
            let odom = self.odometry.pop_front().expect("checked above");
            out.emit("odom", odom).await?;
        }
        Ok(SpoutStatus::Continue)
    }
}
