//! `squall eval`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use squall_core::eval::ground_truth::{self, GroundTruthScore};
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
    /// A ground-truth trajectory (TUM) for ATE and RPE.
    #[arg(long, value_name = "FILE")]
    ground_truth: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `squall eval`.
pub(super) fn eval(args: &EvalArgs) -> ExitCode {
    match scores(args) {
        Ok((trajectory, rel, gt)) => {
            if args.json {
                let mut obj = serde_json::Map::new();
                for value in [serde_json::to_value(rel), serde_json::to_value(gt)].into_iter().flatten() {
                    if let serde_json::Value::Object(m) = value {
                        obj.extend(m);
                    }
                }
                println!("{}", serde_json::Value::Object(obj));
            } else {
                println!("trajectory: {} ({} poses)", args.trajectory.display(), trajectory.len());
                if let Some(r) = rel {
                    println!("relations: {} of {} matched", r.matched, r.total);
                    println!("  translational error: {:.4} ± {:.4} m", r.trans_mean, r.trans_std);
                    println!("  rotational error:    {:.3} ± {:.3} deg", r.rot_mean_deg, r.rot_std_deg);
                    for span in r.by_span.iter().filter(|s| s.matched > 0) {
                        let spans = match span.to_secs {
                            Some(to) => format!("{}–{to} s", span.from_secs),
                            None => format!("{} s or more", span.from_secs),
                        };
                        println!(
                            "  spanning {spans}: {} relations, {:.4} m ({:.0}% of the summed error)",
                            span.matched,
                            span.trans_mean,
                            100.0 * span.share
                        );
                    }
                }
                if let Some(g) = gt {
                    println!("ground truth: {} poses matched", g.pairs);
                    println!(
                        "  ATE: {:.4} m RMSE, {:.3} deg mean heading error",
                        g.ate_rmse, g.ate_rot_mean_deg
                    );
                    println!(
                        "  RPE: {:.4} m, {:.3} deg RMSE (consecutive poses)",
                        g.rpe_trans_rmse, g.rpe_rot_rmse_deg
                    );
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

type Scores = (Trajectory, Option<RelationScore>, Option<GroundTruthScore>);

fn scores(args: &EvalArgs) -> Result<Scores, String> {
    if args.relations.is_none() && args.ground_truth.is_none() {
        return Err("give --relations FILE and/or --ground-truth FILE to score against".to_string());
    }
    let trajectory = load_trajectory(&args.trajectory)?;
    if trajectory.is_empty() {
        return Err(format!("{}: the trajectory has no poses", args.trajectory.display()));
    }
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
    let gt = match &args.ground_truth {
        Some(path) => {
            let truth = Trajectory::read_tum(path).map_err(|e| e.to_string())?;
            let score = ground_truth::score(&trajectory, &truth);
            if score.pairs == 0 {
                return Err(format!("no pose of {} shares a stamp with the trajectory", path.display()));
            }
            Some(score)
        }
        None => None,
    };
    Ok((trajectory, rel, gt))
}

fn load_trajectory(path: &Path) -> Result<Trajectory, String> {
    if is_carmen(path) {
        odometry_at_scans(path)
    } else {
        Trajectory::read_tum(path).map_err(|e| e.to_string())
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
