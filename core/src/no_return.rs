//! Which ranges a laser writes when a beam hits nothing.
//!
//! A scan declares its largest valid range, and a reading at or above it
//! is "no return". Real drivers do not always keep to that: FR079 declares
//! 80 m and writes no return as 81.91 m (above it, harmless); another log
//! declares 80 m and writes 51.05–51.12 m, so that every beam into open
//! space looks like a wall 51 m away, and the map and the matcher take it
//! for one; another writes both 81.91 and 81.83 m below its declared
//! 81.90 m.
//!
//! A no-return code is a range that repeats whatever the robot's pose; a
//! surface's ranges move with the robot. So the detector samples a scan
//! each time the robot has travelled [`SAMPLE_SPACING_M`] since the last
//! sample (turning on the spot does not count: a wall's perpendicular
//! distance stays the same under a turn), puts every beam into
//! centimetre bins, and calls a window of [`WINDOW_HALF_BINS`] either side
//! of a bin a code where it holds [`CODE_RATIO`] times the beams its
//! surroundings (± 1 m) hold in a window of that width. Measured with 0.5 m
//! samples: surfaces reach at most 3.7 times on ACES, Intel, MIT CSAIL,
//! FR079 and both Wean Hall logs (10.5 in the simulated office); the codes
//! of those logs reach 55 (Wean Hall's first log) to 5366 times
//! (decision 0037).
//!
//! It looks only below the declared range (above it, a reading is already
//! no return). A code once found stays found, so a scan is never treated
//! two ways; scans are marked as they go out with the codes known then.

use serde::Deserialize;

use crate::geometry::Real;
use crate::sensor::LaserReading;

/// Travel (m) between sampled scans: enough that every surface's ranges
/// have changed by more than a bin.
pub const SAMPLE_SPACING_M: Real = 0.5;
/// A bin's width, m: the resolution CARMEN logs write ranges at.
const BIN_M: Real = 0.01;
/// A code's window: this many bins either side (a code's readings spread
/// over 8 cm in the logs seen).
const WINDOW_HALF_BINS: usize = 5;
/// The surroundings a window is compared with: this many bins either side,
/// leaving out the [`EXCLUDED_HALF_BINS`] around it.
const BACKGROUND_HALF_BINS: usize = 100;
const EXCLUDED_HALF_BINS: usize = 15;
/// How many times its surroundings' beams a code's window holds (surfaces
/// reach 3.7 on real logs and 10.5 simulated, codes 55 and more).
const CODE_RATIO: f64 = 25.0;
/// The least beams, and sampled scans, a code is seen in: a handful of
/// beams into one bin is chance.
const MIN_BEAMS: u32 = 20;
const MIN_SCANS: u32 = 10;
/// Ranges binned at most, m (a longer declared range is binned up to this).
const MAX_BINNED_M: Real = 1000.0;
/// Scans are counted per block of this many bins: a window overlaps at
/// most two blocks, so its count is at most twice its scans.
const BLOCK_BINS: usize = 10;

/// A range band, metres, `from ≤ r < to`, whose readings mean no return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeBand {
    /// Its lower end, m.
    pub from: Real,
    /// Its upper end, m (excluded).
    pub to: Real,
}

impl RangeBand {
    fn holds(&self, r: Real) -> bool {
        self.from <= r && r < self.to
    }
}

/// A source's `no_return` setting: `"auto"` (the default: codes found in
/// the data), `"declared"` (only the declared range, as the log says) or
/// a list of `[from, to]` bands in metres.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(try_from = "NoReturnSetting")]
pub enum NoReturnMode {
    /// Found in the data.
    #[default]
    Auto,
    /// The declared range only.
    Declared,
    /// These bands, as given.
    Bands(Vec<RangeBand>),
}

/// A `no_return` setting as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum NoReturnSetting {
    /// `"auto"` or `"declared"`.
    Word(String),
    /// `[[from, to], ...]`, metres.
    Bands(Vec<(f64, f64)>),
}

impl TryFrom<NoReturnSetting> for NoReturnMode {
    type Error = String;

    fn try_from(setting: NoReturnSetting) -> Result<Self, String> {
        let expected = "expected \"auto\", \"declared\" or a list of [from, to] bands in metres";
        match setting {
            NoReturnSetting::Word(w) if w == "auto" => Ok(NoReturnMode::Auto),
            NoReturnSetting::Word(w) if w == "declared" => Ok(NoReturnMode::Declared),
            NoReturnSetting::Word(w) => Err(format!("no_return = {w:?}: {expected}")),
            NoReturnSetting::Bands(bands) => {
                for &(from, to) in &bands {
                    if !(from.is_finite() && to.is_finite() && 0.0 < from && from < to) {
                        return Err(format!(
                            "no_return band [{from}, {to}]: {expected}, each with 0 < from < to"
                        ));
                    }
                }
                Ok(NoReturnMode::Bands(bands.into_iter().map(|(from, to)| RangeBand { from, to }).collect()))
            }
        }
    }
}

/// Finds a stream's no-return codes and marks their readings as no return;
/// see the module docs.
#[derive(Debug)]
pub struct NoReturnCodes {
    detect: bool,
    bands: Vec<RangeBand>,
    /// Sampled beams per centimetre bin.
    beams: Vec<u32>,
    /// Sampled scans with a beam in each block of [`BLOCK_BINS`] bins, and
    /// the last sample that counted there.
    scans: Vec<u32>,
    last_counted: Vec<u32>,
    /// Scratch for the search's prefix sums, kept between searches.
    prefix: Vec<u64>,
    samples: u32,
    last_sample: Option<(Real, Real)>,
    /// Scans read when the first code was found.
    found_after: Option<u64>,
    read: u64,
    marked: u64,
}

impl NoReturnCodes {
    /// A detector for `mode`.
    pub fn new(mode: &NoReturnMode) -> Self {
        let (detect, bands) = match mode {
            NoReturnMode::Auto => (true, Vec::new()),
            NoReturnMode::Declared => (false, Vec::new()),
            NoReturnMode::Bands(b) => (false, b.clone()),
        };
        NoReturnCodes {
            detect,
            bands,
            beams: Vec::new(),
            scans: Vec::new(),
            last_counted: Vec::new(),
            prefix: Vec::new(),
            samples: 0,
            last_sample: None,
            found_after: None,
            read: 0,
            marked: 0,
        }
    }

    /// A scan as read: sampled where the robot has moved on.
    pub fn observe(&mut self, scan: &LaserReading) {
        self.read += 1;
        if !self.detect {
            return;
        }
        let here = (scan.odometry.x, scan.odometry.y);
        if let Some(last) = self.last_sample
            && (here.0 - last.0).hypot(here.1 - last.1) < SAMPLE_SPACING_M
        {
            return;
        }
        self.last_sample = Some(here);
        self.samples += 1;
        let top = scan.range_max.min(MAX_BINNED_M);
        let bins = (top / BIN_M).ceil() as usize + 1;
        if self.beams.len() < bins {
            self.beams.resize(bins, 0);
            self.scans.resize(bins.div_ceil(BLOCK_BINS), 0);
            self.last_counted.resize(bins.div_ceil(BLOCK_BINS), 0);
        }
        for &r in &scan.ranges {
            let r = Real::from(r);
            if !(r.is_finite() && r > scan.range_min && r < top) || self.known(r) {
                continue;
            }
            let b = (r / BIN_M) as usize;
            self.beams[b] += 1;
            let block = b / BLOCK_BINS;
            if self.last_counted[block] != self.samples {
                self.last_counted[block] = self.samples;
                self.scans[block] += 1;
            }
        }
        self.search();
    }

    /// Marks `scan`'s readings in a known code as no return (`+∞`, as ROS's
    /// REP 117 writes it).
    pub fn mark(&mut self, scan: &mut LaserReading) {
        if self.bands.is_empty() {
            return;
        }
        for r in &mut scan.ranges {
            let v = Real::from(*r);
            if v.is_finite() && self.bands.iter().any(|b| b.holds(v)) {
                *r = f32::INFINITY;
                self.marked += 1;
            }
        }
    }

    /// The codes known, lowest first.
    pub fn bands(&self) -> &[RangeBand] {
        &self.bands
    }

    /// Readings marked as no return so far.
    pub fn marked(&self) -> u64 {
        self.marked
    }

    /// Scans read when the first code was found, if one was.
    pub fn found_after_scans(&self) -> Option<u64> {
        self.found_after
    }

    /// Whether `self` detects codes (`"auto"`).
    pub fn detects(&self) -> bool {
        self.detect
    }

    fn known(&self, r: Real) -> bool {
        self.bands.iter().any(|b| b.holds(r))
    }

    /// Looks for windows that hold far more than their surroundings.
    fn search(&mut self) {
        let n = self.beams.len();
        if n == 0 {
            return;
        }
        // Prefix sums: the beams in bins a..b are at[b] - at[a].
        let mut at = std::mem::take(&mut self.prefix);
        at.clear();
        at.push(0u64);
        let mut total = 0;
        for &c in &self.beams {
            total += u64::from(c);
            at.push(total);
        }
        let sum = |a: usize, b: usize| at[b.min(n)] - at[a.min(n)];
        let window = 2 * WINDOW_HALF_BINS + 1;
        let mut b = 0;
        while b < n {
            let (lo, hi) = (b.saturating_sub(WINDOW_HALF_BINS), b + WINDOW_HALF_BINS + 1);
            let inside = sum(lo, hi);
            let scans: u32 = self.scans[lo / BLOCK_BINS..=(hi.min(n) - 1) / BLOCK_BINS].iter().sum();
            if inside < u64::from(MIN_BEAMS) || scans < MIN_SCANS {
                b += 1;
                continue;
            }
            let (near_lo, near_hi) = (b.saturating_sub(EXCLUDED_HALF_BINS), b + EXCLUDED_HALF_BINS + 1);
            let (far_lo, far_hi) = (b.saturating_sub(BACKGROUND_HALF_BINS), b + BACKGROUND_HALF_BINS + 1);
            let around = sum(far_lo, near_lo) + sum(near_hi, far_hi);
            let around_bins = (near_lo - far_lo) + far_hi.min(n).saturating_sub(near_hi.min(n));
            let per_window = around as f64 * window as f64 / around_bins.max(1) as f64;
            if (inside as f64) < CODE_RATIO * (per_window + 1.0) {
                b += 1;
                continue;
            }
            // A code: its band runs over the window's bins that hold more
            // than their surroundings' share, and a bin of margin either
            // side for its stragglers.
            let per_bin = per_window / window as f64;
            let busy = |k: usize| f64::from(self.beams[k]) > (5.0 * per_bin).max(1.0);
            let Some(first) = (lo..hi.min(n)).find(|&k| busy(k)) else {
                b += 1;
                continue;
            };
            let last = (lo..hi.min(n)).rev().find(|&k| busy(k)).unwrap_or(first);
            let (from, to) = (first.saturating_sub(1), last + 2);
            self.add_band(RangeBand { from: from as Real * BIN_M, to: to as Real * BIN_M });
            self.beams[lo..hi.min(n)].fill(0);
            b = hi;
        }
        self.prefix = at;
    }

    fn add_band(&mut self, band: RangeBand) {
        if self.found_after.is_none() {
            self.found_after = Some(self.read);
        }
        match self.bands.iter_mut().find(|b| b.from <= band.to && band.from <= b.to) {
            Some(b) => {
                b.from = b.from.min(band.from);
                b.to = b.to.max(band.to);
            }
            None => self.bands.push(band),
        }
        self.bands.sort_by(|a, b| a.from.total_cmp(&b.from));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;
    use crate::random::{standard_normal, stream_for_purpose};
    use rand::RngExt;
    use rand_chacha::ChaCha8Rng;

    /// A robot driving along a corridor 2 m wide, ranges to its walls, and
    /// no return (written as `code`, ± 4 cm) where the corridor is open.
    fn corridor_scan(step: usize, code: Option<f32>, rng: &mut ChaCha8Rng) -> LaserReading {
        let x = 0.5 * step as Real;
        let n = 181;
        let ranges = (0..n)
            .map(|i| {
                let a = -std::f64::consts::FRAC_PI_2 + i as Real * std::f64::consts::PI / 180.0;
                let (s, c) = a.sin_cos();
                // Side walls at y = ±1 (the robot wanders ± 5 cm across),
                // an end wall 60 m ahead of the start.
                let y = 0.05 * (step as Real * 0.7).sin();
                let side = if s > 1e-9 {
                    (1.0 - y) / s
                } else if s < -1e-9 {
                    (-1.0 - y) / s
                } else {
                    Real::INFINITY
                };
                let end = if c > 1e-9 { (60.0 - x) / c } else { Real::INFINITY };
                let r = side.min(end) + 0.01 * standard_normal(rng);
                if r > 30.0 {
                    code.map_or(80.0, |c| c + 0.04 * (2.0 * rng.random::<f64>() - 1.0) as f32)
                } else {
                    r as f32
                }
            })
            .collect();
        LaserReading {
            stamp: step as f64,
            ranges,
            angle_min: -std::f64::consts::FRAC_PI_2,
            angle_increment: std::f64::consts::PI / 180.0,
            range_min: 0.0,
            range_max: 80.0,
            odometry: Pose2::new(x, 0.0, 0.0),
            laser_offset: Pose2::IDENTITY,
        }
    }

    fn run(mode: &NoReturnMode, code: Option<f32>) -> (NoReturnCodes, Vec<LaserReading>) {
        let mut rng = stream_for_purpose(7, "no-return test");
        let mut codes = NoReturnCodes::new(mode);
        let mut out = Vec::new();
        for step in 0..60 {
            let mut s = corridor_scan(step, code, &mut rng);
            codes.observe(&s);
            codes.mark(&mut s);
            out.push(s);
        }
        (codes, out)
    }

    #[test]
    fn a_code_below_the_declared_range_is_found_and_marked() {
        let (codes, scans) = run(&NoReturnMode::Auto, Some(51.08));
        let bands = codes.bands();
        assert_eq!(bands.len(), 1, "{bands:?}");
        assert!(bands[0].from >= 51.03 && bands[0].to <= 51.14, "{bands:?}");
        assert!(codes.found_after_scans().unwrap() <= 20);
        // Once found, no reading of the code is left as a return.
        let late = &scans[30..];
        assert!(late.iter().all(|s| s.ranges.iter().all(|&r| !(51.0..51.2).contains(&r))));
        assert!(codes.marked() > 0);
    }

    #[test]
    fn walls_seen_from_a_steady_course_are_not_codes() {
        // The side walls are at the same perpendicular distance at every
        // sample; the end wall's range shrinks: neither is a code.
        let (codes, scans) = run(&NoReturnMode::Auto, None);
        assert!(codes.bands().is_empty(), "{:?}", codes.bands());
        assert_eq!(codes.marked(), 0);
        assert!(scans.iter().all(|s| s.ranges.iter().all(|r| r.is_finite())));
    }

    #[test]
    fn declared_keeps_the_readings_and_bands_mark_what_they_name() {
        let (codes, _) = run(&NoReturnMode::Declared, Some(51.08));
        assert!(codes.bands().is_empty());
        let given = NoReturnMode::Bands(vec![RangeBand { from: 51.0, to: 51.2 }]);
        let (codes, scans) = run(&given, Some(51.08));
        assert!(codes.marked() > 0);
        assert!(scans.iter().all(|s| s.ranges.iter().all(|&r| !(51.0..51.2).contains(&r))));
    }

    #[test]
    fn a_turn_on_the_spot_is_not_sampled() {
        let mut rng = stream_for_purpose(3, "no-return turn");
        let mut codes = NoReturnCodes::new(&NoReturnMode::Auto);
        for k in 0..200 {
            let mut s = corridor_scan(0, None, &mut rng);
            s.odometry = Pose2::new(0.0, 0.0, 0.05 * k as Real);
            codes.observe(&s);
        }
        assert_eq!(codes.samples, 1);
    }

    #[test]
    fn settings_parse_or_say_what_was_expected() {
        #[derive(Deserialize)]
        struct P {
            no_return: NoReturnMode,
        }
        let p = |s: &str| toml::from_str::<P>(s).map(|p| p.no_return).map_err(|e| e.to_string());
        assert_eq!(p("no_return = \"auto\""), Ok(NoReturnMode::Auto));
        assert_eq!(p("no_return = \"declared\""), Ok(NoReturnMode::Declared));
        assert_eq!(
            p("no_return = [[51.0, 51.2]]"),
            Ok(NoReturnMode::Bands(vec![RangeBand { from: 51.0, to: 51.2 }]))
        );
        assert!(p("no_return = \"max\"").unwrap_err().contains("expected \"auto\", \"declared\""));
        assert!(p("no_return = [[51.2, 51.0]]").unwrap_err().contains("0 < from < to"));
    }
}
