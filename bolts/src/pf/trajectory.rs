//! A pose for every scan from the poses the filter corrected at processed
//! scans and the odometry of all of them.
//!
//! Between two processed scans the filter knows only odometry, which drifts;
//! the next processed scan's correction then shows up as a jump. Written
//! after the run, the trajectory can spread that correction back over the
//! scans before it, in proportion to the odometry noise the motion model
//! expects along the way, so the poses between processed scans follow both
//! ends rather than only the earlier one.

use serde::{Deserialize, Serialize};

use squall_core::geometry::{Pose2, Real, normalize_angle};

use super::smoother::smooth;
pub(crate) use super::smoother::{MeasuredStep, Smoother};

/// How poses between processed scans are filled in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BetweenScans {
    /// The correction at the next processed scan is spread back over the
    /// scans since the previous one, weighted by expected odometry noise.
    #[default]
    Interpolate,
    /// The last corrected pose composed with the odometry since (what
    /// GMapping reports): a jump at each processed scan.
    Odometry,
}

/// How the written trajectory is made from the best lineage: smoothed,
/// then filled in between processed scans.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryOutput {
    /// How poses between processed scans are filled in.
    pub between: BetweenScans,
    /// Odometry noise weights for that filling.
    pub noise: NoiseWeights,
    /// What is done to the processed scans' poses first.
    pub smoother: Smoother,
}

/// A processed scan: (stamp, corrected pose, odometry at that scan).
pub(crate) type Corrected = (f64, Pose2, Pose2);

/// Odometry noise weights: how much translation noise one metre of travel
/// and one radian of turning add (the motion model's srr and str).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseWeights {
    /// Per metre of translation.
    pub per_metre: Real,
    /// Per radian of rotation.
    pub per_radian: Real,
}

/// A pose for each of `scans` (stamp, odometry), in order, from the
/// processed scans `corrected` (oldest first, stamps among the scans'),
/// smoothed and filled in as `output` says, with the model's measurements
/// of the steps between processed scans (`measured[k]`: from
/// `corrected[k]` to `corrected[k + 1]`; empty where it made none).
/// Scans before the first processed scan get no pose (the filter had
/// none), so the output may be shorter than the input.
pub(crate) fn fill(
    corrected: &[Corrected],
    scans: &[(f64, Pose2)],
    output: TrajectoryOutput,
    measured: &[Option<MeasuredStep>],
) -> Vec<(f64, Pose2)> {
    let corrected = &smooth(corrected, output.smoother, measured)[..];
    let TrajectoryOutput { between: mode, noise, .. } = output;
    let along = expected_noise_along(scans, noise);
    let mut out = Vec::with_capacity(scans.len());
    let mut k = 0;
    // Index in `scans` of the processed scan `corrected[k]`, and of the
    // next one once looked up.
    let mut from = 0;
    let mut to: Option<usize> = None;
    for (i, &(stamp, odometry)) in scans.iter().enumerate() {
        while k + 1 < corrected.len() && corrected[k + 1].0 <= stamp {
            k += 1;
            from = i;
            to = None;
        }
        let Some(&(start, pose, at)) = corrected.get(k) else { break };
        if stamp < start {
            continue;
        }
        let forward = pose.compose(&odometry.relative_to(&at));
        let next = corrected.get(k + 1).filter(|_| mode == BetweenScans::Interpolate);
        let Some(&(next_stamp, next_pose, next_at)) = next else {
            out.push((stamp, forward));
            continue;
        };
        let j = *to.get_or_insert_with(|| {
            i + scans[i..].iter().position(|s| s.0 >= next_stamp).unwrap_or(scans.len() - 1 - i)
        });
        let backward = next_pose.compose(&odometry.relative_to(&next_at));
        let span = along[j] - along[from];
        let f = if span > 0.0 { (along[i] - along[from]) / span } else { 0.0 };
        out.push((stamp, blend(&forward, &backward, f)));
    }
    out
}

/// The model's measurement of each step of `lineage` (from its reading k
/// to k + 1), found by the later reading's stamp; `None` where none was
/// made.
pub(crate) fn measured_steps(
    lineage: &[Corrected],
    measured: &[(f64, Option<MeasuredStep>)],
) -> Vec<Option<MeasuredStep>> {
    let by_stamp: std::collections::HashMap<u64, MeasuredStep> =
        measured.iter().filter_map(|&(stamp, m)| Some((stamp.to_bits(), m?))).collect();
    lineage.iter().skip(1).map(|node| by_stamp.get(&node.0.to_bits()).copied()).collect()
}

/// Cumulative expected odometry noise at each scan.
fn expected_noise_along(scans: &[(f64, Pose2)], noise: NoiseWeights) -> Vec<Real> {
    let mut total = 0.0;
    let mut previous: Option<Pose2> = None;
    scans
        .iter()
        .map(|&(_, odometry)| {
            if let Some(p) = previous {
                let d = odometry.relative_to(&p);
                total += noise.per_metre * d.x.hypot(d.y) + noise.per_radian * normalize_angle(d.theta).abs();
            }
            previous = Some(odometry);
            total
        })
        .collect()
}

/// `a` moved the fraction `f` of the way to `b` (the heading the short way
/// round).
pub(crate) fn blend(a: &Pose2, b: &Pose2, f: Real) -> Pose2 {
    Pose2::new(a.x + f * (b.x - a.x), a.y + f * (b.y - a.y), a.theta + f * normalize_angle(b.theta - a.theta))
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOISE: NoiseWeights = NoiseWeights { per_metre: 0.1, per_radian: 0.1 };

    /// Filling as `between` says, without smoothing.
    fn output(between: BetweenScans) -> TrajectoryOutput {
        TrajectoryOutput { between, noise: NOISE, smoother: Smoother::None }
    }

    /// Odometry that drives straight along x, 0.1 m per scan, while the
    /// truth drives 0.11 m per scan: processed at scans 0 and 10.
    fn drifting() -> (Vec<Corrected>, Vec<(f64, Pose2)>) {
        let scans: Vec<(f64, Pose2)> =
            (0..=12).map(|i| (f64::from(i), Pose2::new(0.1 * f64::from(i), 0.0, 0.0))).collect();
        let corrected =
            vec![(0.0, Pose2::IDENTITY, scans[0].1), (10.0, Pose2::new(1.1, 0.0, 0.0), scans[10].1)];
        (corrected, scans)
    }

    #[test]
    fn interpolation_spreads_the_correction_over_the_scans_before_it() {
        let (corrected, scans) = drifting();
        let poses = fill(&corrected, &scans, output(BetweenScans::Interpolate), &[]);
        assert_eq!(poses.len(), scans.len());
        for (i, (stamp, p)) in poses.iter().enumerate().take(11) {
            assert_eq!(*stamp, i as f64);
            assert!((p.x - 0.11 * i as f64).abs() < 1e-12, "scan {i}: {p:?}");
        }
        // After the last processed scan only odometry is known.
        assert!((poses[12].1.x - 1.3).abs() < 1e-12);
    }

    #[test]
    fn odometry_mode_jumps_at_the_processed_scan() {
        let (corrected, scans) = drifting();
        let poses = fill(&corrected, &scans, output(BetweenScans::Odometry), &[]);
        assert!((poses[9].1.x - 0.9).abs() < 1e-12);
        assert!((poses[10].1.x - 1.1).abs() < 1e-12);
    }

    #[test]
    fn turning_in_place_takes_its_share_of_the_correction() {
        // Scan 1 turns by one radian in place, scan 2 drives 1 m: with
        // equal weights per metre and per radian, scan 1 sits halfway.
        let scans = vec![
            (0.0, Pose2::IDENTITY),
            (1.0, Pose2::new(0.0, 0.0, 1.0)),
            (2.0, Pose2::new(1.0_f64.cos(), 1.0_f64.sin(), 1.0)),
        ];
        let end = Pose2::new(scans[2].1.x, scans[2].1.y + 0.2, 1.0);
        let corrected = vec![(0.0, Pose2::IDENTITY, scans[0].1), (2.0, end, scans[2].1)];
        let poses = fill(&corrected, &scans, output(BetweenScans::Interpolate), &[]);
        let backward = end.compose(&scans[1].1.relative_to(&scans[2].1));
        let expected = blend(&scans[1].1, &backward, 0.5);
        assert!((poses[1].1.y - expected.y).abs() < 1e-12 && (poses[1].1.y - 0.1).abs() < 1e-12);
    }

    #[test]
    fn scans_before_the_first_processed_one_get_no_pose() {
        let (mut corrected, scans) = drifting();
        corrected.remove(0);
        let poses = fill(&corrected, &scans, output(BetweenScans::Interpolate), &[]);
        assert_eq!(poses.first().map(|p| p.0), Some(10.0));
        assert!(fill(&[], &scans, output(BetweenScans::Interpolate), &[]).is_empty());
    }
}
