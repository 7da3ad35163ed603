//! Writes a simulated run the way real logs come: `sim.clf` (CARMEN
//! `PARAM`, `FLASER`, `ODOM`), `ground_truth.tum` (the true pose at every
//! scan) and `sim.relations` (Kümmerle format), so that simulated and real
//! runs are evaluated the same way. Also `world.png`: the walls with the true
//! path drawn.

use std::fmt::Write as _;
use std::path::Path;

use squall_core::geometry::{Pose2, Real, normalize_angle};
use squall_core::map_files::write_png;
use squall_core::occupancy::OccupancyGrid;
use squall_core::trajectory::Trajectory;
use squall_topology::fsio::write_atomic;

use super::robot::{SimEvent, Simulation};
use crate::{Error, Result};
use squall_core::linemap::LineMap;

/// Local relations join scans this far apart along the true path, metres.
pub const LOCAL_RELATION_METRES: Real = 1.0;
/// Loop relations join scans at most this far apart in space...
pub const LOOP_RELATION_METRES: Real = 1.0;
/// ...and at least this far apart in time, seconds.
pub const LOOP_RELATION_SECS: Real = 30.0;

/// What a written run holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimSummary {
    /// Scans written.
    pub scans: usize,
    /// Local relations written.
    pub local_relations: usize,
    /// Loop relations written.
    pub loop_relations: usize,
}

/// Runs `sim` to the end and writes its files into `dir`.
pub fn write_run(sim: Simulation, dir: &Path) -> Result<SimSummary> {
    let world = sim.floor().world.clone();
    let mut clf = String::new();
    let mut truth = Trajectory::default();
    let mut header_written = false;
    let stop = squall_topology::runtime::process_stop();
    for event in sim {
        if stop.is_made() {
            return Err(Error::Stopped);
        }
        match event {
            SimEvent::Scan(scan, true_pose) => {
                if !header_written {
                    let _ =
                        writeln!(clf, "# squall simulated run: FLASER and ODOM; poses are wheel odometry");
                    let _ = writeln!(clf, "PARAM laser_front_laser_angle_min {:.9} nohost 0", scan.angle_min);
                    let _ = writeln!(
                        clf,
                        "PARAM laser_front_laser_angle_increment {:.9} nohost 0",
                        scan.angle_increment
                    );
                    let _ = writeln!(clf, "PARAM robot_front_laser_max {:.2} nohost 0", scan.range_max);
                    header_written = true;
                }
                let _ = write!(clf, "FLASER {}", scan.ranges.len());
                for r in &scan.ranges {
                    let _ = write!(clf, " {r:.3}");
                }
                let o = scan.odometry;
                let _ = writeln!(
                    clf,
                    " {:.6} {:.6} {:.6} {:.6} {:.6} {:.6} {:.6} nohost {:.6}",
                    o.x, o.y, o.theta, o.x, o.y, o.theta, scan.stamp, scan.stamp
                );
                truth.push(scan.stamp, true_pose);
            }
            SimEvent::Odom(odom) => {
                let p = odom.pose;
                let _ = writeln!(
                    clf,
                    "ODOM {:.6} {:.6} {:.6} {} {} 0 {:.6} nohost {:.6}",
                    p.x, p.y, p.theta, odom.linear_velocity, odom.angular_velocity, odom.stamp, odom.stamp
                );
            }
        }
    }
    write_file(&dir.join("sim.clf"), clf.as_bytes())?;
    write_file(&dir.join("ground_truth.tum"), truth.to_tum().as_bytes())?;
    let (relations, local, loops) = relations(&truth);
    write_file(&dir.join("sim.relations"), relations.as_bytes())?;
    // 5 cm pixels, coarser for a world wider than MAX_IMAGE_SIDE of them.
    let (x0, y0, x1, y1) = world.bounds();
    let resolution = ((x1 - x0).max(y1 - y0) / MAX_IMAGE_SIDE).max(0.05);
    write_png(&rasterize(&world, resolution), &truth.poses, &dir.join("world.png"))?;
    Ok(SimSummary { scans: truth.len(), local_relations: local, loop_relations: loops })
}

/// The widest `world.png`, pixels: a map kilometres wide is drawn coarser
/// rather than as gigapixels.
const MAX_IMAGE_SIDE: Real = 8192.0;

/// Writes `bytes` to `path` atomically; an error names the file.
fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, bytes).map_err(|source| Error::Write { path: path.to_path_buf(), source })
}

fn relation_line(out: &mut String, t: &Trajectory, i: usize, j: usize) {
    let d = t.poses[j].relative_to(&t.poses[i]);
    let _ = writeln!(
        out,
        "{:.6} {:.6} {:.6} {:.6} 0.000000 0.000000 0.000000 {:.6}",
        t.stamps[i], t.stamps[j], d.x, d.y, d.theta
    );
}

/// Relations from the true trajectory: from every 5th scan to the first
/// scan at least [`LOCAL_RELATION_METRES`] further along the path, and loop
/// relations between every 10th scan and the first later one (by at least
/// [`LOOP_RELATION_SECS`]) within [`LOOP_RELATION_METRES`] and 45°.
pub fn relations(t: &Trajectory) -> (String, usize, usize) {
    let mut out = String::new();
    let (mut local, mut loops) = (0, 0);
    let n = t.len();
    for i in (0..n).step_by(5) {
        let mut travelled = 0.0;
        for j in i + 1..n {
            travelled += t.poses[j].distance(&t.poses[j - 1]);
            if travelled >= LOCAL_RELATION_METRES {
                relation_line(&mut out, t, i, j);
                local += 1;
                break;
            }
        }
    }
    for i in (0..n).step_by(10) {
        let revisit = (i + 1..n).step_by(10).find(|&j| {
            t.stamps[j] - t.stamps[i] >= LOOP_RELATION_SECS
                && t.poses[j].distance(&t.poses[i]) <= LOOP_RELATION_METRES
                && normalize_angle(t.poses[j].theta - t.poses[i].theta).abs() <= std::f64::consts::FRAC_PI_4
        });
        if let Some(j) = revisit {
            relation_line(&mut out, t, i, j);
            loops += 1;
        }
    }
    (out, local, loops)
}

/// The walls drawn into a grid of `resolution` metres: wall cells occupied,
/// the rest free.
pub fn rasterize(world: &LineMap, resolution: Real) -> OccupancyGrid {
    let (x0, y0, x1, y1) = world.bounds();
    let margin = 1.0;
    let width = ((x1 - x0 + 2.0 * margin) / resolution).ceil() as usize;
    let height = ((y1 - y0 + 2.0 * margin) / resolution).ceil() as usize;
    let mut grid = OccupancyGrid::unknown(width, height, resolution, (x0 - margin, y0 - margin));
    grid.cells.iter_mut().for_each(|c| *c = 0);
    for w in &world.walls {
        let length = (w.b.0 - w.a.0).hypot(w.b.1 - w.a.1);
        let steps = (length / (resolution * 0.5)).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let f = k as Real / steps as Real;
            let p = Pose2::new(w.a.0 + f * (w.b.0 - w.a.0), w.a.1 + f * (w.b.1 - w.a.1), 0.0);
            if let Some((cx, cy)) = grid.cell_of(p.x, p.y) {
                grid.set(cx, cy, 100);
            }
        }
    }
    grid
}
