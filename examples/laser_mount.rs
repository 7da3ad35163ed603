//! Diagnostic: where is the laser on the robot? Matches consecutive front
//! scans of a CARMEN log in the laser's own frame (the log's mounting
//! ignored) and fits, over the pairs where the robot turned, the laser's
//! position on the robot and the odometry's distance scale:
//!
//!   t_laser = s · t_odometry + (R(Δθ) − I) · m
//!
//! (the laser's motion is the robot's seen from a point m ahead of it: a
//! turn on the spot moves the laser along a circle of radius |m|). The
//! odometry is the `ODOM` stream (else the scans' own poses) at each
//! scan's stamp plus OFFSET seconds (the scan clock's offset, as
//! `metrics.json`'s `clock_offset_ms` reports it). Prints the fit, its
//! standard errors and the log's declared mounting.
//!
//! `cargo run --release --example laser_mount -- LOG.clf [OFFSET_SECS]`
//!
//! `TURNED=RAD` in the environment sets the least turn of a pair used
//! (default 0.03; 0 uses every pair, for the distance scale).
//!
//! See docs/decisions/0038.

use squall_core::geometry::{Pose2, Real, normalize_angle};
use squall_core::odometry_track::OdometryTrack;
use squall_core::scan_match::match_scans_from;
use squall_core::sensor::LaserReading;
use squall_spouts::carmen::{Laser, ReadOptions, Record, read_log};

/// Pairs used: the odometry turned at least this much between the scans
/// (rad), so that the mounting shows.
const TURNED: Real = 0.03;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: laser_mount LOG.clf [OFFSET_SECS]");
        std::process::exit(2);
    };
    let offset: f64 = args.get(2).map_or(0.0, |s| s.parse().expect("OFFSET_SECS: seconds"));
    let records = read_log(std::path::Path::new(path), ReadOptions::default()).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2);
    });
    let mut track = OdometryTrack::new();
    let mut scans: Vec<LaserReading> = Vec::new();
    for r in records {
        match r {
            Record::Odom(o) => {
                track.push(o.stamp, o.pose);
            }
            Record::Scan(Laser::Front, s) => scans.push(s),
            _ => {}
        }
    }
    let declared = scans.first().map(|s| s.laser_offset).unwrap_or(Pose2::IDENTITY);
    let use_stream = track.len() > 1;
    let pose_at = |s: &LaserReading| if use_stream { track.at(s.stamp + offset) } else { Some(s.odometry) };
    // Normal equations of [s, mx, my].
    let mut rows: Vec<([Real; 3], [Real; 3], Real, Real)> = Vec::new();
    for k in 0..scans.len().saturating_sub(1) {
        let (a, b) = (&scans[k], &scans[k + 1]);
        let (Some(pa), Some(pb)) = (pose_at(a), pose_at(b)) else { continue };
        let odo = pb.relative_to(&pa);
        let turned = std::env::var("TURNED").ok().and_then(|v| v.parse().ok()).unwrap_or(TURNED);
        if odo.theta.abs() < turned {
            continue;
        }
        let mut la = a.clone();
        let mut lb = b.clone();
        la.laser_offset = Pose2::IDENTITY;
        lb.laser_offset = Pose2::IDENTITY;
        // The guess: the odometry's motion seen from the declared mount.
        let guess = Pose2::IDENTITY.relative_to(&declared).compose(&odo).compose(&declared);
        let Some(step) = match_scans_from(&la, &lb, guess) else { continue };
        let dtheta = step.motion.theta;
        let (c, s) = (dtheta.cos(), dtheta.sin());
        // t_l = s·t_o + (R − I) m: two rows.
        let row_x = [odo.x, c - 1.0, -s];
        let row_y = [odo.y, s, c - 1.0];
        rows.push((row_x, row_y, step.motion.x, step.motion.y));
    }
    // Two passes: least squares, then again without the pairs 3 cm off.
    let mut fit = [1.0, 0.0, 0.0];
    for pass in 0..2 {
        let mut ata = [[0.0f64; 3]; 3];
        let mut atb = [0.0f64; 3];
        let mut used = 0;
        let mut sq = 0.0;
        for (rx, ry, tx, ty) in &rows {
            let res = |r: &[Real; 3], t: Real| r[0] * fit[0] + r[1] * fit[1] + r[2] * fit[2] - t;
            if pass > 0 && res(rx, *tx).hypot(res(ry, *ty)) > 0.03 {
                continue;
            }
            used += 1;
            for (r, t) in [(rx, *tx), (ry, *ty)] {
                for i in 0..3 {
                    for j in 0..3 {
                        ata[i][j] += r[i] * r[j];
                    }
                    atb[i] += r[i] * t;
                }
            }
        }
        fit = solve(ata, atb);
        for (rx, ry, tx, ty) in &rows {
            let res = |r: &[Real; 3], t: Real| r[0] * fit[0] + r[1] * fit[1] + r[2] * fit[2] - t;
            if pass == 0 || res(rx, *tx).hypot(res(ry, *ty)) <= 0.03 {
                sq += res(rx, *tx).powi(2) + res(ry, *ty).powi(2);
            }
        }
        let sigma2 = sq / (2 * used - 3).max(1) as f64;
        let inv = invert(ata);
        println!(
            "pass {pass}: {used} of {} turning pairs; odometry scale {:.4} ± {:.4}; laser at x {:+.4} ± {:.4} m, y {:+.4} ± {:.4} m (residual σ {:.4} m)",
            rows.len(),
            fit[0],
            (sigma2 * inv[0][0]).sqrt(),
            fit[1],
            (sigma2 * inv[1][1]).sqrt(),
            fit[2],
            (sigma2 * inv[2][2]).sqrt(),
            sigma2.sqrt()
        );
    }
    println!(
        "declared: laser at x {:+.4} m, y {:+.4} m, θ {:+.4} rad",
        declared.x,
        declared.y,
        normalize_angle(declared.theta)
    );
}

fn det(m: [[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

fn invert(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let d = det(m);
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let (r0, r1) = ((j + 1) % 3, (j + 2) % 3);
            let (c0, c1) = ((i + 1) % 3, (i + 2) % 3);
            *v = (m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]) / d;
        }
    }
    out
}

fn solve(a: [[f64; 3]; 3], b: [f64; 3]) -> [f64; 3] {
    let inv = invert(a);
    [0, 1, 2].map(|i| (0..3).map(|j| inv[i][j] * b[j]).sum())
}
