//! Each scan's odometry pose at the instant the laser measured it.
//!
//! A log attaches to each scan the odometry at the scan's stamp, or the
//! last odometry message before it; neither is the instant of the
//! measurement when the two sensors' clocks or latencies differ (see
//! [`offset`]). A source hands its scans and its odometry stream to a
//! [`ScanClock`], which learns the offset from the first readings (the
//! warm-up: scans are held until the offset is settled) and then gives
//! each scan the odometry interpolated at its stamp plus the offset: from
//! the odometry stream where the log has one (CARMEN `ODOM` lines, a bag's
//! `/odom`), from the scans' own poses otherwise.
//!
//! A log read as fast as it goes holds its scans through the warm-up, so
//! every scan gets the learnt offset. A source paced at the recorded rate
//! (or live) cannot make its consumers wait: its scans flow with the poses
//! the log attached until the offset is decided, and carry it from then on
//! ([`ScanClock::flowing`]).
//!
//! It is a pure function of the order readings are handed to it, so a
//! replayed log gives the same poses whatever the machine.

pub mod offset;

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

pub use offset::{ClockOffset, TurnPair, estimate};

use crate::geometry::{Pose2, Real, normalize_angle};
use crate::odometry_track::OdometryTrack;
use crate::sensor::LaserReading;

/// How a source times its scans against its odometry: a source's
/// `clock_offset` setting, `"auto"` (the default), `"log"` or a number of
/// seconds within [`offset::MAX_OFFSET`].
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(try_from = "ClockSetting")]
pub enum ClockMode {
    /// Estimated from the first readings (the default); where they do not
    /// settle it, the poses the log attached are kept.
    #[default]
    Auto,
    /// The poses the log attached, as recorded.
    Log,
    /// A known offset, seconds: each scan's instant on the odometry's
    /// clock is its stamp plus this.
    Fixed(f64),
}

/// A `clock_offset` setting as written: a word or seconds.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum ClockSetting {
    /// `"auto"` or `"log"`.
    Word(String),
    /// Seconds.
    Seconds(f64),
}

impl TryFrom<ClockSetting> for ClockMode {
    type Error = String;

    fn try_from(setting: ClockSetting) -> Result<Self, String> {
        let expected = "expected \"auto\", \"log\" or seconds in [-0.5, 0.5]";
        match setting {
            ClockSetting::Word(w) if w == "auto" => Ok(ClockMode::Auto),
            ClockSetting::Word(w) if w == "log" => Ok(ClockMode::Log),
            ClockSetting::Word(w) => Err(format!("clock_offset = {w:?}: {expected}")),
            ClockSetting::Seconds(s) if s.is_finite() && s.abs() <= offset::MAX_OFFSET => {
                Ok(ClockMode::Fixed(s))
            }
            ClockSetting::Seconds(s) => Err(format!("clock_offset = {s}: {expected}")),
        }
    }
}

/// The warm-up's bounds: the scans held at most before the offset is
/// decided, and how settled it must be to end the warm-up early.
const WARMUP_SCANS: usize = 3000;
/// Log seconds of scans held at most.
const WARMUP_SECS: f64 = 300.0;
/// The standard error (s) that ends the warm-up early, with at least
/// [`WARMUP_PAIRS`] pairs: twice it, the 95% interval, within the 20 ms a
/// map needs (at 30°/s, 20 ms is 0.6° of heading).
const SETTLED: f64 = 0.01;
const WARMUP_PAIRS: usize = 200;
/// Scans held with a known offset, to see whether the odometry stream
/// covers them.
const FIXED_WARMUP_SCANS: usize = 20;
/// How often (pairs) the estimate is tried during the warm-up.
const TRY_EVERY: usize = 50;
/// A pair of scans is matched only where the odometry turned by at least
/// this (rad) over it or the pair before: a change of turn rate is what
/// tells offsets apart, and a straight run tells nothing.
const TURNING: Real = 0.01;

/// Where the scans' poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseSource {
    /// The odometry stream, interpolated.
    OdometryStream,
    /// The scans' own odometry poses, interpolated between scans.
    ScanPoses,
    /// The poses the log attached, as recorded.
    AsLogged,
}

/// What the clock decided, for `metrics.json`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockReport {
    /// Where the poses come from.
    pub source: PoseSource,
    /// The offset applied, seconds.
    pub offset: f64,
    /// The estimate, where one was made.
    pub estimate: Option<ClockOffset>,
    /// Scans the warm-up took (held, or flowing with the logged poses).
    pub warmup_scans: usize,
}

/// Gives each scan the odometry at its instant; see the module docs.
#[derive(Debug)]
pub struct ScanClock {
    mode: ClockMode,
    stream: OdometryTrack,
    scan_poses: OdometryTrack,
    pending: VecDeque<LaserReading>,
    pairs: Vec<TurnPair>,
    /// The last scan and the odometry turn over the pair ending at it.
    last: Option<(LaserReading, Real)>,
    pairs_at_last_try: usize,
    decided: Option<ClockReport>,
    finished: bool,
    /// Scans given the logged pose because the track had none at their
    /// instant (beyond its ends).
    held_as_logged: u64,
    /// Whether scans flow during the warm-up instead of being held.
    flowing: bool,
    /// Scans given out during a flowing warm-up, with the logged poses.
    flowed_as_logged: u64,
    /// The warm-up's scans: how many, and the first and last stamps.
    warmup: (usize, Option<(f64, f64)>),
}

impl ScanClock {
    /// A clock in `mode`.
    pub fn new(mode: ClockMode) -> Self {
        let decided = match mode {
            ClockMode::Log => Some(ClockReport {
                source: PoseSource::AsLogged,
                offset: 0.0,
                estimate: None,
                warmup_scans: 0,
            }),
            _ => None,
        };
        ScanClock {
            mode,
            stream: OdometryTrack::new(),
            scan_poses: OdometryTrack::new(),
            pending: VecDeque::new(),
            pairs: Vec::new(),
            last: None,
            pairs_at_last_try: 0,
            decided,
            finished: false,
            held_as_logged: 0,
            flowing: false,
            flowed_as_logged: 0,
            warmup: (0, None),
        }
    }

    /// A clock whose scans flow during the warm-up, with the poses the log
    /// attached, rather than being held: for a source paced at the
    /// recorded rate or live, whose consumers cannot wait.
    pub fn flowing(mode: ClockMode) -> Self {
        ScanClock { flowing: true, ..ScanClock::new(mode) }
    }

    /// An odometry message of the stream (out-of-order ones are ignored).
    pub fn odometry(&mut self, stamp: f64, pose: Pose2) {
        if self.decided.is_some_and(|d| d.source != PoseSource::OdometryStream) {
            return;
        }
        self.stream.push(stamp, pose);
    }

    /// A scan, with the pose the log attached.
    pub fn scan(&mut self, reading: LaserReading) {
        if self.decided.is_some_and(|d| d.source == PoseSource::AsLogged) {
            self.pending.push_back(reading);
            return;
        }
        // The scans' own poses are a track while it may be chosen, and
        // once it is.
        if self.decided.is_none_or(|d| d.source == PoseSource::ScanPoses) {
            self.scan_poses.push(reading.stamp, reading.odometry);
        }
        if self.decided.is_none() {
            self.learn_from(&reading);
            let (count, span) = &mut self.warmup;
            *count += 1;
            *span = Some(span.map_or((reading.stamp, reading.stamp), |(first, _)| (first, reading.stamp)));
        }
        self.pending.push_back(reading);
        if self.decided.is_none() {
            self.try_to_decide();
        }
    }

    /// The end of the input: every held scan is ready.
    pub fn finish(&mut self) {
        self.finished = true;
        if self.decided.is_none() {
            self.decide();
        }
    }

    /// The next scan whose pose is decided, in order.
    pub fn next_ready(&mut self) -> Option<LaserReading> {
        let Some(decided) = self.decided else {
            if !self.flowing {
                return None;
            }
            let reading = self.pending.pop_front()?;
            self.flowed_as_logged += 1;
            return Some(reading);
        };
        let front = self.pending.front()?;
        if decided.source == PoseSource::AsLogged {
            return self.pending.pop_front();
        }
        let track = match decided.source {
            PoseSource::OdometryStream => &self.stream,
            _ => &self.scan_poses,
        };
        let instant = front.stamp + decided.offset;
        let covered = track.span().is_some_and(|(_, last)| last >= instant);
        if !(covered || self.finished) {
            return None;
        }
        let mut reading = self.pending.pop_front()?;
        match track.at(instant) {
            Some(pose) => reading.odometry = pose,
            None => self.held_as_logged += 1,
        }
        let keep_from = self.pending.front().map_or(instant, |r| r.stamp + decided.offset);
        self.stream.forget_before(keep_from - 1.0);
        self.scan_poses.forget_before(keep_from - 1.0);
        Some(reading)
    }

    /// What was decided, once it is.
    pub fn report(&self) -> Option<ClockReport> {
        self.decided
    }

    /// Scans given the logged pose for want of odometry at their instant.
    pub fn held_as_logged(&self) -> u64 {
        self.held_as_logged
    }

    /// Scans given out with the logged pose during a flowing warm-up.
    pub fn flowed_as_logged(&self) -> u64 {
        self.flowed_as_logged
    }

    fn learn_from(&mut self, reading: &LaserReading) {
        if self.mode != ClockMode::Auto {
            return;
        }
        if let Some((previous, turn_before)) = &self.last {
            let turn = normalize_angle(reading.odometry.theta - previous.odometry.theta).abs();
            if turn.max(*turn_before) >= TURNING
                && let Some(pair) = TurnPair::measure(previous, reading)
            {
                self.pairs.push(pair);
            }
            self.last = Some((reading.clone(), turn));
        } else {
            self.last = Some((reading.clone(), 0.0));
        }
    }

    fn try_to_decide(&mut self) {
        let (count, span) = self.warmup;
        let span = span.map_or(0.0, |(first, last)| last - first);
        // A known offset still waits a few scans, for the odometry stream
        // to show whether it covers them.
        let enough = match self.mode {
            ClockMode::Auto => count >= WARMUP_SCANS || span >= WARMUP_SECS,
            _ => count >= FIXED_WARMUP_SCANS,
        };
        if enough {
            self.decide();
            return;
        }
        if self.pairs.len() >= WARMUP_PAIRS && self.pairs.len() >= self.pairs_at_last_try + TRY_EVERY {
            self.pairs_at_last_try = self.pairs.len();
            let settled = self.estimate_now().is_some_and(|(_, e)| e.standard_error <= SETTLED);
            if settled {
                self.decide();
            }
        }
    }

    /// The track to use and the estimate against it.
    fn estimate_now(&self) -> Option<(PoseSource, ClockOffset)> {
        let (source, track) = self.track_choice();
        Some((source, estimate(&self.pairs, track)?))
    }

    /// The odometry stream where it covers the scans held, the scans' own
    /// poses otherwise.
    fn track_choice(&self) -> (PoseSource, &OdometryTrack) {
        let held = self.warmup.1;
        let covers = match (self.stream.span(), held) {
            (Some((first, last)), Some((a, b))) => {
                self.stream.len() >= 2 && first <= a + 1.0 && last >= b - 1.0
            }
            _ => false,
        };
        if covers {
            (PoseSource::OdometryStream, &self.stream)
        } else {
            (PoseSource::ScanPoses, &self.scan_poses)
        }
    }

    fn decide(&mut self) {
        let warmup_scans = self.warmup.0;
        let report = match self.mode {
            ClockMode::Log => {
                ClockReport { source: PoseSource::AsLogged, offset: 0.0, estimate: None, warmup_scans }
            }
            ClockMode::Fixed(offset) => {
                ClockReport { source: self.track_choice().0, offset, estimate: None, warmup_scans }
            }
            ClockMode::Auto => match self.estimate_now() {
                // An offset the readings cannot tell from zero (within
                // twice its standard error) is not applied: the stream is
                // read at the stamps.
                Some((source, e)) if e.is_settled() => {
                    let offset = if e.offset.abs() > 2.0 * e.standard_error { e.offset } else { 0.0 };
                    ClockReport { source, offset, estimate: Some(e), warmup_scans }
                }
                other => ClockReport {
                    source: PoseSource::AsLogged,
                    offset: 0.0,
                    estimate: other.map(|o| o.1),
                    warmup_scans,
                },
            },
        };
        self.decided = Some(report);
        self.pairs = Vec::new();
        self.last = None;
    }
}

#[cfg(test)]
mod tests;
