//! CARMEN logs: the `carmen` spout and its reader.
//!
//! The spout emits every front-laser scan on stream `scan`, rear-laser scans
//! on `rear_scan` and odometry on `odom`, as fast as possible or paced at the
//! recorded rate times a factor. Each front scan carries the odometry at the
//! instant it was measured, which [`ScanClock`] finds: the `ODOM` stream (or
//! the scans' own poses) interpolated at the scan's stamp plus the offset
//! between the laser's clock and the odometry's, learnt from the first
//! scans (`clock_offset = "auto"`, the default), given in seconds, or
//! `"log"` for the poses as recorded.

mod parse;
mod reader;

use std::path::PathBuf;

use serde::Deserialize;
use squall_core::clock::{ClockMode, ScanClock};
use squall_core::no_return::NoReturnMode;
use squall_core::sensor::{LaserReading, Odometry};
use squall_topology::{
    BoxError, Declarer, Emitter, ParamError, Params, ReadingCounter, Spout, SpoutStatus, TaskContext,
};

pub use parse::{Laser, LineParser, Record, RecordError};
pub use reader::{LogError, LogReader, ReadOptions, count_front_scans, read_front_scans, read_log};

use crate::clocked::ScanConditioner;
pub use crate::pace::Pace;
use crate::pace::{Pacer, pace};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CarmenParams {
    /// The log file (plain or gzip).
    log: PathBuf,
    /// `"max"` (the default) or a factor of the recorded rate.
    #[serde(default)]
    rate: Option<toml::Value>,
    /// Skip malformed records (counted) instead of failing.
    #[serde(default)]
    skip_bad: bool,
    /// Range limit (m) when the log gives none. The default is
    /// [`ReadOptions::default`]'s, 80. (An `Option` rather than a
    /// `#[serde(default)]` on the struct: `log` has no default and must
    /// stay required.)
    range_max: Option<f64>,
    /// Stop after this many front scans.
    max_scans: Option<u64>,
    /// `"auto"` (the default), `"log"` or seconds: see the module docs.
    #[serde(default)]
    clock_offset: ClockMode,
    /// Mend steps where the wheels slipped ([`SlipGuard`]; the default:
    /// true).
    #[serde(default = "mend_slips_by_default")]
    mend_slips: bool,
    /// The readings that mean no return: `"auto"` (the default: codes
    /// found in the data), `"declared"` or `[[from, to], ...]` metres
    /// ([`NoReturnMode`]).
    #[serde(default)]
    no_return: NoReturnMode,
}

fn mend_slips_by_default() -> bool {
    true
}

/// Replays a CARMEN log.
#[derive(Debug)]
pub struct CarmenSpout {
    log: PathBuf,
    pacer: Pacer,
    options: ReadOptions,
    max_scans: Option<u64>,
    reader: Option<LogReader>,
    /// The front scans on their way out.
    front: ScanConditioner,
    /// Front scans read.
    scans: u64,
    /// Front scans emitted, for the progress display.
    readings: ReadingCounter,
}

impl CarmenSpout {
    /// Builds the spout from its `params`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: CarmenParams = p.parse()?;
        let range_max = params.range_max.unwrap_or(ReadOptions::default().default_range_max);
        if !(range_max.is_finite() && range_max > 0.0) {
            return Err(ParamError::new("range_max must be a positive number of metres"));
        }
        let pace = pace(params.rate.as_ref())?;
        // Read as fast as it goes, the log's scans wait for the clock's
        // warm-up; paced, they cannot.
        let clock = if pace == Pace::Max {
            ScanClock::new(params.clock_offset)
        } else {
            ScanClock::flowing(params.clock_offset)
        };
        Ok(CarmenSpout {
            pacer: Pacer::new(pace),
            log: params.log,
            options: ReadOptions { default_range_max: range_max, skip_bad: params.skip_bad },
            max_scans: params.max_scans,
            reader: None,
            front: ScanConditioner::new(&params.no_return, clock, params.mend_slips),
            scans: 0,
            readings: ReadingCounter::default(),
        })
    }

    /// Waits until a record stamped `stamp` is due; `Ok(false)` when the
    /// run is stopping. An error names the record's line.
    async fn wait_for(&mut self, stamp: f64) -> Result<bool, BoxError> {
        let waited = self.pacer.wait_for(stamp).await;
        waited.map_err(|e| {
            let line = self.reader.as_ref().map_or(0, LogReader::line);
            format!("{}:{line}: {e}", self.log.display()).into()
        })
    }
}

impl CarmenSpout {
    /// Emits the front scans whose pose the clock has decided.
    async fn emit_ready(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        while let Some(reading) = self.front.next_ready() {
            self.readings.add(1);
            out.emit("scan", reading).await?;
        }
        Ok(())
    }
}

impl Spout for CarmenSpout {
    fn declare(&self, d: &mut Declarer) {
        d.output::<LaserReading>("scan").output::<LaserReading>("rear_scan").output::<Odometry>("odom");
        d.reads(&self.log);
    }

    async fn open(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.pacer.watch(ctx.stop());
        self.reader = Some(LogReader::open(&self.log, self.options)?);
        // One quick pass for the count, when a display shows a percentage
        // and an ETA (a log is read far faster than matched); a log it
        // cannot read is reported by the reader, with the line.
        let (log, max_scans) = (&self.log, self.max_scans);
        self.readings = ctx.readings("scans", || {
            let front = count_front_scans(log).ok()?;
            Some(max_scans.map_or(front, |m| m.min(front)))
        });
        Ok(())
    }

    async fn next(&mut self, out: &mut Emitter) -> Result<SpoutStatus, BoxError> {
        let reader = self.reader.as_mut().ok_or("the log was not opened")?;
        let record =
            if self.max_scans.is_some_and(|m| self.scans >= m) { None } else { reader.next_record() };
        let record = match record {
            None => {
                let (skipped, other) = (reader.skipped(), reader.other_records().values().sum());
                out.count("records_skipped", skipped);
                out.count("records_other_types", other);
                self.front.finish();
                self.emit_ready(out).await?;
                self.front.report(out);
                return Ok(SpoutStatus::Done);
            }
            Some(r) => r?,
        };
        match record {
            Record::Scan(laser, reading) => {
                if !self.wait_for(reading.stamp).await? {
                    return Ok(SpoutStatus::Continue);
                }
                match laser {
                    Laser::Front => {
                        self.scans += 1;
                        self.front.scan(reading);
                    }
                    Laser::Rear => out.emit("rear_scan", reading).await?,
                }
            }
            Record::Odom(odom) => {
                if !self.wait_for(odom.stamp).await? {
                    return Ok(SpoutStatus::Continue);
                }
                self.front.odometry(odom.stamp, odom.pose);
                out.emit("odom", odom).await?;
            }
            Record::Param(..) | Record::Other(_) => {}
        }
        self.emit_ready(out).await?;
        Ok(SpoutStatus::Continue)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_max_defaults_to_the_readers_and_must_be_positive() {
        let spout = |text: &str| CarmenSpout::from_params(&Params::new(toml::from_str(text).unwrap(), 1, 1));
        assert_eq!(spout("log = \"a.clf\"").unwrap().options.default_range_max, 80.0);
        assert_eq!(spout("log = \"a.clf\"\nrange_max = 30").unwrap().options.default_range_max, 30.0);
        let e = spout("log = \"a.clf\"\nrange_max = 0").unwrap_err();
        assert_eq!(e.to_string(), "range_max must be a positive number of metres");
        assert_eq!(spout("range_max = 30").unwrap_err().to_string(), "missing field `log`");
    }
}
