//! The relation metric (Kümmerle et al. 2009).
//!
//! A relation `t1 t2 x y z roll pitch yaw` is the true motion of the robot
//! from the scan at `t1` to the scan at `t2`, in the frame of the first. The
//! error of a trajectory on it is `(p2 ⊖ p1) ⊖ δ`: its translation length
//! and the absolute value of its angle. The metric is the mean and standard
//! deviation of both over all relations.

use serde::Serialize;

use crate::eval::mean_std;
use crate::geometry::{Pose2, normalize_angle};
use crate::textfile;
use crate::trajectory::{Trajectory, TrajectoryError};

/// How far (s) a trajectory stamp may be from a relation's stamp to match.
pub const STAMP_TOLERANCE: f64 = 1e-3;

/// One ground-truth relation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Relation {
    /// Stamp of the first scan, seconds.
    pub t1: f64,
    /// Stamp of the second scan, seconds.
    pub t2: f64,
    /// True motion from the first to the second, in the first's frame.
    pub motion: Pose2,
}

/// Parses a relations file; `path` names it in errors.
pub fn parse_relations(path: &str, text: &str) -> Result<Vec<Relation>, TrajectoryError> {
    Ok(textfile::numeric_lines(path, text, 8, "t1 t2 x y z roll pitch yaw", false)?
        .into_iter()
        .map(|(_, v)| Relation { t1: v[0], t2: v[1], motion: Pose2::new(v[2], v[3], v[7]) })
        .collect())
}

/// Reads a relations file.
pub fn read_relations(path: &std::path::Path) -> Result<Vec<Relation>, TrajectoryError> {
    let (name, text) = textfile::read(path)?;
    parse_relations(&name, &text)
}

/// The relation metric of one trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RelationScore {
    /// Relations whose two stamps both have a pose.
    pub matched: usize,
    /// Relations in the file.
    pub total: usize,
    /// Mean translational error, metres.
    pub trans_mean: f64,
    /// Its standard deviation, metres.
    pub trans_std: f64,
    /// Mean rotational error, degrees.
    pub rot_mean_deg: f64,
    /// Its standard deviation, degrees.
    pub rot_std_deg: f64,
    /// The translational error by the time between a relation's two
    /// scans ([`SPANS`]): short relations measure local accuracy, long
    /// ones whether loops closed.
    pub by_span: [SpanScore; 3],
}

/// The span classes of [`RelationScore::by_span`], seconds: [from, to).
pub const SPANS: [(f64, f64); 3] = [(0.0, 10.0), (10.0, 100.0), (100.0, f64::INFINITY)];

/// The relations of one span class.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SpanScore {
    /// Shortest span in the class, seconds.
    pub from_secs: f64,
    /// Span the class ends below, seconds (`None`: no end).
    pub to_secs: Option<f64>,
    /// Matched relations in the class.
    pub matched: usize,
    /// Their mean translational error, metres (0 without relations).
    pub trans_mean: f64,
    /// Their share of the summed translational error of all classes.
    pub share: f64,
}

/// The error of one relation: (translation m, rotation rad).
pub fn relation_error(p1: &Pose2, p2: &Pose2, truth: &Pose2) -> (f64, f64) {
    let estimated = p2.relative_to(p1);
    let e = estimated.relative_to(truth);
    (e.x.hypot(e.y), normalize_angle(e.theta).abs())
}

/// Scores `trajectory` on `relations`; relations without poses at both
/// stamps are not counted (see `matched`).
pub fn score(trajectory: &Trajectory, relations: &[Relation]) -> RelationScore {
    let (mut trans, mut rot) = (Vec::new(), Vec::new());
    let mut sums = [(0usize, 0.0); SPANS.len()];
    for r in relations {
        let (Some(p1), Some(p2)) =
            (trajectory.at(r.t1, STAMP_TOLERANCE), trajectory.at(r.t2, STAMP_TOLERANCE))
        else {
            continue;
        };
        let (t, a) = relation_error(&p1, &p2, &r.motion);
        trans.push(t);
        rot.push(a.to_degrees());
        let span = (r.t2 - r.t1).abs();
        if let Some(class) = SPANS.iter().position(|&(from, to)| span >= from && span < to) {
            sums[class].0 += 1;
            sums[class].1 += t;
        }
    }
    let (trans_mean, trans_std) = mean_std(&trans);
    let (rot_mean_deg, rot_std_deg) = mean_std(&rot);
    let total: f64 = sums.iter().map(|s| s.1).sum();
    let by_span = std::array::from_fn(|i| {
        let ((from_secs, to), (matched, sum)) = (SPANS[i], sums[i]);
        SpanScore {
            from_secs,
            to_secs: to.is_finite().then_some(to),
            matched,
            trans_mean: if matched > 0 { sum / matched as f64 } else { 0.0 },
            share: if total > 0.0 { sum / total } else { 0.0 },
        }
    });
    RelationScore {
        matched: trans.len(),
        total: relations.len(),
        trans_mean,
        trans_std,
        rot_mean_deg,
        rot_std_deg,
        by_span,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_walk() -> Trajectory {
        let mut t = Trajectory::default();
        let mut p = Pose2::IDENTITY;
        for i in 0..40 {
            t.push(i as f64, p);
            let step = if i % 10 == 9 {
                Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2)
            } else {
                Pose2::new(1.0, 0.0, 0.0)
            };
            p = p.compose(&step);
        }
        t
    }

    fn exact_relations(t: &Trajectory) -> Vec<Relation> {
        (0..t.len() - 3)
            .map(|i| Relation {
                t1: t.stamps[i],
                t2: t.stamps[i + 3],
                motion: t.poses[i + 3].relative_to(&t.poses[i]),
            })
            .collect()
    }

    #[test]
    fn the_true_trajectory_scores_zero() {
        let t = square_walk();
        let s = score(&t, &exact_relations(&t));
        assert_eq!((s.matched, s.total), (37, 37));
        assert!(s.trans_mean < 1e-12 && s.rot_mean_deg < 1e-9, "{s:?}");
    }

    #[test]
    fn a_known_drift_gives_a_known_error() {
        let t = square_walk();
        let relations = exact_relations(&t);
        // Every step 10 % too long: over 3 steps the estimate overshoots 0.3 m
        // along the path, whatever the turns.
        let mut drift = Trajectory::default();
        let mut p = Pose2::IDENTITY;
        for i in 0..40 {
            drift.push(i as f64, p);
            let step = if i % 10 == 9 {
                Pose2::new(1.1, 0.0, std::f64::consts::FRAC_PI_2)
            } else {
                Pose2::new(1.1, 0.0, 0.0)
            };
            p = p.compose(&step);
        }
        let s = score(&drift, &relations);
        let straight: Vec<f64> = relations
            .iter()
            .filter(|r| r.motion.theta.abs() < 1e-9)
            .map(|r| {
                relation_error(&drift.at(r.t1, 0.0).unwrap(), &drift.at(r.t2, 0.0).unwrap(), &r.motion).0
            })
            .collect();
        assert!(straight.iter().all(|e| (e - 0.3).abs() < 1e-9), "{straight:?}");
        assert!(s.trans_mean > 0.25 && s.rot_mean_deg < 1e-9, "{s:?}");
    }

    #[test]
    fn errors_are_broken_down_by_span() {
        let t = square_walk();
        // Exact 3-step relations (3 s) and one 30 s relation that is 1 m off.
        let mut relations = exact_relations(&t);
        let (p0, p30) = (t.poses[0], t.poses[30]);
        let off = p30.relative_to(&p0).compose(&Pose2::new(1.0, 0.0, 0.0));
        relations.push(Relation { t1: 0.0, t2: 30.0, motion: off });
        let s = score(&t, &relations);
        let [short, middle, long] = s.by_span;
        assert_eq!((short.matched, middle.matched, long.matched), (37, 1, 0));
        assert!(short.trans_mean < 1e-12 && short.share < 1e-9, "{short:?}");
        assert!((middle.trans_mean - 1.0).abs() < 1e-9 && (middle.share - 1.0).abs() < 1e-9, "{middle:?}");
        assert_eq!((middle.from_secs, middle.to_secs, long.to_secs), (10.0, Some(100.0), None));
        assert_eq!((long.trans_mean, long.share), (0.0, 0.0));
    }

    #[test]
    fn unmatched_stamps_are_not_counted() {
        let t = square_walk();
        let mut relations = exact_relations(&t);
        relations.push(Relation { t1: 100.0, t2: 101.0, motion: Pose2::IDENTITY });
        let s = score(&t, &relations);
        assert_eq!((s.matched, s.total), (37, 38));
    }

    #[test]
    fn parses_kummerle_files() {
        let r = parse_relations(
            "r",
            "90.239599 90.719599 0.422330 -0.000750 0.000000 0.000000 0.000000 0.017260\n",
        )
        .unwrap();
        assert_eq!(r[0].t2, 90.719599);
        assert_eq!(r[0].motion, Pose2::new(0.42233, -0.00075, 0.01726));
        assert!(
            parse_relations("r", "1 2 3\n").unwrap_err().to_string().starts_with("r:1: expected 8 fields")
        );
    }
}
