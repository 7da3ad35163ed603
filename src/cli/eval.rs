//! `squall eval`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use squall_core::eval::ground_truth::{self, GroundTruthScore};
use squall_core::eval::map_frame::{self, MapFrameScore, WITHIN_DEG, WITHIN_M};
use squall_core::eval::relations::{self, RelationScore, read_relations};
use squall_core::trajectory::Trajectory;
use squall_spouts::carmen::{Laser, ReadOptions, Record, read_log};

use super::EXIT_INVALID;

#[derive(Debug, clap::Args)]
pub(super) struct EvalArgs {
    /// The trajectory: TUM (`t x y z qx qy qz qw`), or a CARMEN log (.clf,
    /// .clf.gz) to score its raw odometry at the scans.
    #[arg(long, value_name = "FILE")]
    trajectory: PathBuf,
    /// Ground-truth relations (Kümmerle et al. 2009 format).
    #[arg(long, value_name = "FILE")]
    relations: Option<PathBuf>,
    /// A ground-truth trajectory (TUM): ATE and RPE, or in the map frame
    /// the errors as they are.
    #[arg(long, value_name = "FILE")]
    ground_truth: Option<PathBuf>,
    /// How poses are compared with the ground truth: `aligned` (ATE after
    /// the best rigid alignment: a SLAM map's frame is its own) or `map`
    /// (as they are: a localizer's poses are in the given map's frame).
    /// The default is the frame the trajectory file declares (`# frame:
    /// map`, as `squall localize` writes), else `aligned`.
    #[arg(long, value_name = "aligned|map")]
    frame: Option<Frame>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// How a trajectory is compared with its ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum Frame {
    /// After the best rigid alignment.
    Aligned,
    /// As the poses are, in the map frame.
    Map,
}

/// The scores against ground truth, in the frame chosen.
enum TruthScore {
    Aligned(GroundTruthScore),
    Map(MapFrameScore),
}

/// Runs `squall eval`.
pub(super) fn eval(args: &EvalArgs) -> ExitCode {
    match scores(args) {
        Ok(Scores { trajectory, frame, relations: rel, truth }) => {
            if args.json {
                let mut obj = serde_json::Map::new();
                let truth = match truth {
                    Some(TruthScore::Aligned(g)) => serde_json::to_value(g),
                    Some(TruthScore::Map(m)) => serde_json::to_value(m),
                    None => Ok(serde_json::Value::Null),
                };
                for value in [serde_json::to_value(rel), truth].into_iter().flatten() {
                    if let serde_json::Value::Object(m) = value {
                        obj.extend(m);
                    }
                }
                if args.ground_truth.is_some() {
                    obj.insert("frame".into(), frame.name().into());
                }
                outln!("{}", serde_json::Value::Object(obj));
            } else {
                outln!("trajectory: {} ({} poses)", args.trajectory.display(), trajectory.len());
                if let Some(r) = rel {
                    outln!("relations: {} of {} matched", r.matched, r.total);
                    outln!("  translational error: {:.4} ± {:.4} m", r.trans_mean, r.trans_std);
                    outln!("  rotational error:    {:.3} ± {:.3} deg", r.rot_mean_deg, r.rot_std_deg);
                    for span in r.by_span.iter().filter(|s| s.matched > 0) {
                        let spans = match span.to_secs {
                            Some(to) => format!("{}–{to} s", span.from_secs),
                            None => format!("{} s or more", span.from_secs),
                        };
                        outln!(
                            "  spanning {spans}: {} relations, {:.4} m ({:.0}% of the summed error)",
                            span.matched,
                            span.trans_mean,
                            100.0 * span.share
                        );
                    }
                }
                match truth {
                    Some(TruthScore::Aligned(g)) => {
                        outln!("ground truth: {} poses matched, compared after alignment", g.pairs);
                        outln!(
                            "  ATE: {:.4} m RMSE, {:.3} deg mean heading error",
                            g.ate_rmse,
                            g.ate_rot_mean_deg
                        );
                        outln!(
                            "  RPE: {:.4} m, {:.3} deg RMSE (consecutive poses)",
                            g.rpe_trans_rmse,
                            g.rpe_rot_rmse_deg
                        );
                    }
                    Some(TruthScore::Map(m)) => print_map_frame(&m, args.frame.is_none()),
                    None => {}
                }
            }
            ExitCode::SUCCESS
        }
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::from(EXIT_INVALID)
        }
    }
}

/// What `squall eval` found: the trajectory, the frame it was compared
/// in, and its scores.
struct Scores {
    trajectory: Trajectory,
    frame: Frame,
    relations: Option<RelationScore>,
    truth: Option<TruthScore>,
}

impl Scores {
    /// Whether every error is a finite number: coordinates near `f64`'s
    /// largest make differences and squares overflow, and "ATE: inf" is no
    /// score.
    fn finite(&self) -> bool {
        let mut errors: Vec<f64> = Vec::new();
        if let Some(r) = &self.relations {
            errors.extend([r.trans_mean, r.trans_std, r.rot_mean_deg, r.rot_std_deg]);
        }
        match &self.truth {
            Some(TruthScore::Aligned(g)) => {
                errors.extend([g.ate_rmse, g.ate_rot_mean_deg, g.rpe_trans_rmse, g.rpe_rot_rmse_deg]);
            }
            Some(TruthScore::Map(m)) => errors.extend([m.map_mean_m, m.map_max_m, m.map_rot_mean_deg]),
            None => {}
        }
        errors.iter().all(|e| e.is_finite())
    }
}

impl Frame {
    fn name(self) -> &'static str {
        match self {
            Frame::Aligned => "aligned",
            Frame::Map => "map",
        }
    }
}

/// Prints a map-frame score; `declared`: the frame came from the file.
pub(super) fn print_map_frame(m: &MapFrameScore, declared: bool) {
    let why = if declared { " (the trajectory declares its frame)" } else { "" };
    outln!("ground truth: {} poses matched, compared in the map frame, no alignment{why}", m.pairs);
    outln!("  position error: {:.4} m mean, {:.4} m max", m.map_mean_m, m.map_max_m);
    outln!("  heading error:  {:.3} deg mean, {:.3} deg max", m.map_rot_mean_deg, m.map_rot_max_deg);
    outln!("  within {WITHIN_M} m and {WITHIN_DEG} deg: {:.1}% of the poses", 100.0 * m.map_within_share);
    match m.converged_after_s {
        Some(t) => outln!("  converged after {t:.2} s and stayed"),
        None => outln!("  not converged: the last pose is off"),
    }
}

fn scores(args: &EvalArgs) -> Result<Scores, String> {
    if args.relations.is_none() && args.ground_truth.is_none() {
        return Err("give --relations FILE and/or --ground-truth FILE to score against".to_string());
    }
    let (trajectory, declared) = load_trajectory(&args.trajectory)?;
    if trajectory.is_empty() {
        return Err(format!("{}: the trajectory has no poses", args.trajectory.display()));
    }
    let frame = match (args.frame, declared.as_deref()) {
        (Some(frame), _) => frame,
        (None, Some("map")) => Frame::Map,
        (None, Some(other)) => {
            return Err(format!(
                "{}: declares frame \"{other}\", which eval does not know; give --frame aligned or --frame map",
                args.trajectory.display()
            ));
        }
        (None, None) => Frame::Aligned,
    };
    let rel = match &args.relations {
        Some(path) => {
            let relations = read_relations(path).map_err(|e| e.to_string())?;
            let score = relations::score(&trajectory, &relations);
            if score.matched == 0 {
                return Err(format!(
                    "no relation of {} matches the trajectory's stamps (within {} s)",
                    path.display(),
                    relations::STAMP_TOLERANCE
                ));
            }
            Some(score)
        }
        None => None,
    };
    let truth = match &args.ground_truth {
        Some(path) => {
            let truth = Trajectory::read_tum(path).map_err(|e| e.to_string())?;
            let no_pair = || format!("no pose of {} shares a stamp with the trajectory", path.display());
            Some(match frame {
                Frame::Aligned => {
                    let score = ground_truth::score(&trajectory, &truth);
                    if score.pairs == 0 {
                        return Err(no_pair());
                    }
                    TruthScore::Aligned(score)
                }
                Frame::Map => TruthScore::Map(map_frame::score(&trajectory, &truth).ok_or_else(no_pair)?),
            })
        }
        None => None,
    };
    let scores = Scores { trajectory, frame, relations: rel, truth };
    if !scores.finite() {
        return Err(format!(
            "{}: the errors do not fit a double (coordinates near 1e308?): no finite score",
            args.trajectory.display()
        ));
    }
    Ok(scores)
}

/// The trajectory and the frame its file declares (a CARMEN log's
/// odometry declares none).
fn load_trajectory(path: &Path) -> Result<(Trajectory, Option<String>), String> {
    if is_carmen(path) {
        Ok((odometry_at_scans(path)?, None))
    } else {
        Trajectory::read_tum_with_frame(path).map_err(|e| e.to_string())
    }
}

/// Whether `path` names a CARMEN log (`.clf`, `.clf.gz`).
pub(super) fn is_carmen(path: &Path) -> bool {
    let name = path.to_string_lossy();
    name.ends_with(".clf") || name.ends_with(".clf.gz")
}

/// A CARMEN log's raw odometry at its front scans: the trajectory a robot
/// without SLAM would report, the baseline that SLAM must beat.
pub(super) fn odometry_at_scans(path: &Path) -> Result<Trajectory, String> {
    let records = read_log(path, ReadOptions::default()).map_err(|e| e.to_string())?;
    let mut t = Trajectory::default();
    for r in records {
        if let Record::Scan(Laser::Front, scan) = r {
            t.push(scan.stamp, scan.odometry);
        }
    }
    Ok(t)
}
