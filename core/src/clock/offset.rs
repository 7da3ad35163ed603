//! The offset between the laser's clock and the odometry's, estimated from
//! the readings themselves.
//!
//! A scan's stamp is rarely the instant its beams were measured on the
//! odometry's clock: drivers stamp on arrival, after the sweep and the
//! serial line, and the two sensors' clocks differ. On FR079 consecutive
//! scans line up best with the pose of the scan before. While the robot
//! turns at 30°/s an offset of 0.1 s is 3° of heading error at every scan,
//! a map smeared at every turn.
//!
//! The estimate compares the turn between consecutive scans measured by
//! matching them ([`crate::scan_match`], which needs no odometry but a
//! first guess) with the turn the odometry stream makes between the two
//! scans' instants shifted by a candidate offset δ:
//!
//! ```text
//! r_k ≈ s · (θ(t_{k+1} + δ) − θ(t_k + δ))
//! ```
//!
//! where `s` is the odometry's turn scale (wheels misjudge turns by a few
//! per cent; fitted for each δ, so a scale error is not taken for an
//! offset). δ is where the robust (Huber) sum of the residuals is least,
//! searched on a grid and refined by a parabola; what tells offsets apart
//! is a change of the turn rate (a constant turn gives the same increments
//! at any δ), and the curvature of the sum there gives the estimate's
//! standard error. This is the temporal calibration that visual–inertial
//! systems do by aligning angular rates (Furgale, Rehder and Siegwart
//! 2013), with the laser's rate from scan matching.

use crate::geometry::{Real, normalize_angle};
use crate::odometry_track::OdometryTrack;
use crate::scan_match::match_scans;
use crate::sensor::LaserReading;

/// The offsets searched, seconds either way: a second is far beyond any
/// driver's latency, and a scan period or two beyond it would match the
/// wrong scans.
pub const MAX_OFFSET: f64 = 0.5;
/// The grid's step, seconds; the parabola refines within it.
const STEP: f64 = 0.005;
/// The Huber loss's corner, radians: a scan match's heading is good to a
/// few milliradians, and a failed match (a wrong minimum) must not pull.
const HUBER: Real = 0.01;
/// The least heading noise (rad) of one scan match.
const MATCH_NOISE: Real = 0.002;
/// Consecutive scans farther apart than this (s) are not a pair: a gap in
/// the log.
const MAX_PAIR_GAP: f64 = 1.0;
/// The turn scales fitted, a share of what the odometry reports: outside
/// them the wheels or the matcher have failed, not misjudged.
const SCALE_RANGE: (Real, Real) = (0.8, 1.25);
/// The standard error (s) above which the readings do not settle the
/// offset: the robot hardly changed its turn rate, or the estimate
/// wanders from batch to batch.
pub const MAX_STANDARD_ERROR: f64 = 0.02;

/// The turn between two consecutive scans, measured and where.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnPair {
    /// The earlier and later scans' stamps.
    pub from: f64,
    /// The later scan's stamp.
    pub to: f64,
    /// The turn matching the scans measured, radians.
    pub measured: Real,
}

impl TurnPair {
    /// The turn between `from` and `to` measured by matching their scans;
    /// `None` when they are too far apart in time or do not match.
    pub fn measure(from: &LaserReading, to: &LaserReading) -> Option<TurnPair> {
        let gap = to.stamp - from.stamp;
        if !(gap > 0.0 && gap <= MAX_PAIR_GAP) {
            return None;
        }
        let step = match_scans(from, to)?;
        Some(TurnPair { from: from.stamp, to: to.stamp, measured: step.motion.theta })
    }
}

/// What the readings say of the offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockOffset {
    /// The scan's instant on the odometry's clock is its stamp plus this,
    /// seconds (negative: the scan was measured before its stamp says).
    pub offset: f64,
    /// The estimate's standard error, seconds.
    pub standard_error: f64,
    /// The odometry's turn scale at the offset (measured turn per
    /// reported turn).
    pub turn_scale: Real,
    /// Pairs of scans the estimate rests on.
    pub pairs: usize,
}

impl ClockOffset {
    /// Whether the readings settle the offset (its standard error at most
    /// [`MAX_STANDARD_ERROR`]); where they do not, the sources' own stamps
    /// are the better guess.
    pub fn is_settled(&self) -> bool {
        self.standard_error <= MAX_STANDARD_ERROR
    }
}

/// The robust misfit of `pairs` at offset `delta`, with the scale fitted.
/// `reported` is scratch space, reused across the offsets searched.
fn misfit(
    pairs: &[TurnPair],
    track: &OdometryTrack,
    delta: f64,
    reported: &mut Vec<(Real, Real)>,
) -> Option<(Real, Real, usize)> {
    reported.clear();
    for p in pairs {
        let a = track.at(p.from + delta);
        let b = track.at(p.to + delta);
        if let (Some(a), Some(b)) = (a, b) {
            reported.push((p.measured, normalize_angle(b.theta - a.theta)));
        }
    }
    if reported.is_empty() {
        return None;
    }
    let (ro, oo) = reported.iter().fold((0.0, 0.0), |(ro, oo), &(r, o)| (ro + r * o, oo + o * o));
    let scale = if oo > 0.0 { (ro / oo).clamp(SCALE_RANGE.0, SCALE_RANGE.1) } else { 1.0 };
    let cost = reported
        .iter()
        .map(|&(r, o)| {
            let e = (r - scale * o).abs();
            if e <= HUBER { 0.5 * e * e } else { HUBER * (e - 0.5 * HUBER) }
        })
        .sum();
    Some((cost, scale, reported.len()))
}

/// The offset that best explains `pairs` on `track`; `None` where the
/// track covers none of them. See the module docs.
///
/// The standard error is the larger of two: the curvature's, which
/// takes the residuals as independent, and the spread of the estimates
/// from [`BATCHES`] consecutive batches of the pairs (batch means), which
/// does not. On FR079 the second is about three times the first: scan
/// matches of neighbouring scans share their errors, and the offset
/// itself may wander as the two clocks drift.
pub fn estimate(pairs: &[TurnPair], track: &OdometryTrack) -> Option<ClockOffset> {
    let mut whole = best_offset(pairs, track)?;
    if pairs.len() >= BATCHES * MIN_BATCH {
        let size = pairs.len() / BATCHES;
        let batches: Vec<f64> = pairs
            .chunks(size)
            .take(BATCHES)
            .filter_map(|b| best_offset(b, track))
            .map(|b| b.offset)
            .collect();
        if batches.len() == BATCHES {
            let n = BATCHES as f64;
            let mean = batches.iter().sum::<f64>() / n;
            let variance = batches.iter().map(|b| (b - mean).powi(2)).sum::<f64>() / (n - 1.0);
            whole.standard_error = whole.standard_error.max((variance / n).sqrt());
        }
    } else {
        // Too few pairs to see how the estimate varies: not settled.
        whole.standard_error = f64::INFINITY;
    }
    Some(whole)
}

/// Batches of pairs whose estimates' spread bounds the standard error.
pub const BATCHES: usize = 5;
/// The fewest pairs in a batch.
const MIN_BATCH: usize = 40;

/// The grid search and the parabola over `pairs`, with the curvature's
/// standard error.
fn best_offset(pairs: &[TurnPair], track: &OdometryTrack) -> Option<ClockOffset> {
    let steps = (MAX_OFFSET / STEP).round() as i64;
    let mut reported = Vec::with_capacity(pairs.len());
    let grid: Vec<(f64, Real, Real, usize)> = (-steps..=steps)
        .filter_map(|k| {
            let delta = k as f64 * STEP;
            misfit(pairs, track, delta, &mut reported).map(|(c, s, n)| (delta, c, s, n))
        })
        .collect();
    // Compare offsets on the same pairs only: near the search's ends the
    // track may not cover every pair.
    let most = grid.iter().map(|g| g.3).max()?;
    let full: Vec<_> = grid.into_iter().filter(|g| g.3 == most).collect();
    let best = (0..full.len()).min_by(|&a, &b| full[a].1.total_cmp(&full[b].1))?;
    let (mut offset, mut curvature) = (full[best].0, 0.0);
    if best > 0 && best + 1 < full.len() {
        let (l, c, r) = (full[best - 1].1, full[best].1, full[best + 1].1);
        let second = l - 2.0 * c + r;
        if second > 0.0 {
            offset += 0.5 * STEP * (l - r) / second;
            curvature = second / (STEP * STEP);
        }
    }
    // The sum is half the squares inside the Huber corner: with residuals
    // of variance σ², its curvature is Σ (∂e/∂δ)² and the offset's variance
    // σ² over it; σ² is estimated from the residuals at the minimum.
    // A scan match is not better than a couple of milliradians, however
    // well the residuals fit: without this floor a perfect fit would make
    // any offset look settled.
    let residual_variance = (2.0 * full[best].1 / most as Real).max(MATCH_NOISE * MATCH_NOISE);
    let standard_error = if curvature > 0.0 { (residual_variance / curvature).sqrt() } else { f64::INFINITY };
    Some(ClockOffset { offset, standard_error, turn_scale: full[best].2, pairs: most })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;

    /// A robot turning on the spot with a rate that changes (turns of
    /// alternating sign), odometry at 50 Hz, and pairs measured exactly at
    /// the true instants: scans stamped `lag` after they were taken.
    fn turning(lag: f64, scale: Real) -> (Vec<TurnPair>, OdometryTrack) {
        let heading = |t: f64| 0.6 * (t * 0.9).sin() + 0.3 * (t * 2.3).sin();
        let mut track = OdometryTrack::new();
        for k in 0..3000 {
            let t = k as f64 * 0.02;
            track.push(t, Pose2::new(0.0, 0.0, normalize_angle(heading(t) / scale)));
        }
        let pairs = (0..250)
            .map(|k| {
                let (a, b) = (1.0 + k as f64 * 0.2, 1.2 + k as f64 * 0.2);
                TurnPair { from: a + lag, to: b + lag, measured: heading(b) - heading(a) }
            })
            .collect();
        (pairs, track)
    }

    #[test]
    fn finds_a_known_lag_and_the_odometrys_turn_scale() {
        for lag in [0.0, 0.05, 0.137, -0.08] {
            let (pairs, track) = turning(lag, 1.05);
            let e = estimate(&pairs, &track).unwrap();
            assert!((e.offset + lag).abs() < 0.002, "lag {lag}: {e:?}");
            assert!((e.turn_scale - 1.05).abs() < 0.01, "{e:?}");
            assert!(e.is_settled(), "{e:?}");
        }
    }

    #[test]
    fn failed_matches_do_not_pull_the_estimate() {
        let (mut pairs, track) = turning(0.1, 1.0);
        for p in pairs.iter_mut().step_by(10) {
            p.measured += 0.5;
        }
        let e = estimate(&pairs, &track).unwrap();
        assert!((e.offset + 0.1).abs() < 0.005, "{e:?}");
    }

    #[test]
    fn a_constant_turn_settles_nothing() {
        let mut track = OdometryTrack::new();
        for k in 0..2000 {
            let t = k as f64 * 0.02;
            track.push(t, Pose2::new(0.0, 0.0, normalize_angle(0.3 * t)));
        }
        let pairs: Vec<_> = (0..100)
            .map(|k| TurnPair { from: 1.0 + k as f64 * 0.2, to: 1.2 + k as f64 * 0.2, measured: 0.06 })
            .collect();
        let e = estimate(&pairs, &track).unwrap();
        assert!(!e.is_settled(), "{e:?}");
        assert!(estimate(&pairs, &OdometryTrack::new()).is_none());
    }
}
