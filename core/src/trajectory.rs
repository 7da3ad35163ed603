//! Timestamped planar poses, and the TUM text format
//! (`t x y z qx qy qz qw`, one pose per line, `#` comments).

use std::fmt::Write as _;
use std::path::Path;

use crate::geometry::Pose2;
use crate::textfile::{self, TextFileError};

/// A problem in a trajectory or relations file.
pub type TrajectoryError = TextFileError;

/// Poses with their stamps, in time order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// Seconds.
    pub stamps: Vec<f64>,
    /// One pose per stamp.
    pub poses: Vec<Pose2>,
}

impl Trajectory {
    /// Appends a pose.
    pub fn push(&mut self, stamp: f64, pose: Pose2) {
        self.stamps.push(stamp);
        self.poses.push(pose);
    }

    /// Number of poses.
    pub fn len(&self) -> usize {
        self.stamps.len()
    }

    /// Whether there are no poses.
    pub fn is_empty(&self) -> bool {
        self.stamps.is_empty()
    }

    /// The pose whose stamp is within `tolerance` seconds of `t` (the
    /// nearest), if any. Stamps must be sorted.
    pub fn at(&self, t: f64, tolerance: f64) -> Option<Pose2> {
        let i = self.stamps.partition_point(|&s| s < t);
        let candidates = [i.checked_sub(1), Some(i)];
        candidates
            .into_iter()
            .flatten()
            .filter(|&j| j < self.stamps.len())
            .min_by(|&a, &b| (self.stamps[a] - t).abs().total_cmp(&(self.stamps[b] - t).abs()))
            .filter(|&j| (self.stamps[j] - t).abs() <= tolerance)
            .map(|j| self.poses[j])
    }

    /// The TUM text: `t x y 0 0 0 sin(θ/2) cos(θ/2)`, stamps with 6
    /// decimals (the precision of CARMEN and relation files).
    pub fn to_tum(&self) -> String {
        let mut s = String::with_capacity(self.len() * 80);
        s.push_str("# timestamp x y z qx qy qz qw\n");
        for (t, p) in self.stamps.iter().zip(&self.poses) {
            let (qz, qw) = (p.theta / 2.0).sin_cos();
            let _ = writeln!(s, "{t:.6} {:.6} {:.6} 0 0 0 {qz:.9} {qw:.9}", p.x, p.y);
        }
        s
    }

    /// [`Self::to_tum`] with a first line declaring the poses' frame
    /// (`# frame: map`), which `squall eval` scores them in. `frame` is one
    /// word.
    pub fn to_tum_in_frame(&self, frame: &str) -> String {
        debug_assert!(!frame.is_empty() && !frame.contains(char::is_whitespace), "{frame:?}");
        format!("{FRAME_COMMENT}{frame}\n{}", self.to_tum())
    }

    /// Parses TUM text; `path` names it in errors. The heading is the yaw of
    /// the quaternion.
    pub fn parse_tum(path: &str, text: &str) -> Result<Self, TrajectoryError> {
        let mut t = Trajectory::default();
        for (line, v) in textfile::numeric_lines(path, text, 8, "t x y z qx qy qz qw", false)? {
            if let Some(&last) = t.stamps.last()
                && v[0] < last
            {
                return Err(TextFileError::Bad {
                    path: path.to_string(),
                    line,
                    message: format!("stamps must not go back in time ({} after {last})", v[0]),
                });
            }
            let (qx, qy, qz, qw) = (v[4], v[5], v[6], v[7]);
            let yaw = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
            t.push(v[0], Pose2::new(v[1], v[2], yaw));
        }
        Ok(t)
    }

    /// Reads a TUM file.
    pub fn read_tum(path: &Path) -> Result<Self, TrajectoryError> {
        let (name, text) = textfile::read(path)?;
        Self::parse_tum(&name, &text)
    }

    /// Reads a TUM file, with the frame it declares (see
    /// [`declared_frame`]).
    pub fn read_tum_with_frame(path: &Path) -> Result<(Self, Option<String>), TrajectoryError> {
        let (name, text) = textfile::read(path)?;
        Ok((Self::parse_tum(&name, &text)?, declared_frame(&text).map(str::to_string)))
    }
}

/// The comment line that declares a trajectory's frame, before the word.
const FRAME_COMMENT: &str = "# frame: ";

/// The frame a TUM text declares in a `# frame: <word>` line among its
/// leading comments (as [`Trajectory::to_tum_in_frame`] writes), if any.
pub fn declared_frame(text: &str) -> Option<&str> {
    text.lines()
        .take_while(|l| l.starts_with('#'))
        .find_map(|l| l.strip_prefix(FRAME_COMMENT))
        .map(str::trim)
        .filter(|f| !f.is_empty())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tum_round_trip_keeps_poses() {
        let mut t = Trajectory::default();
        t.push(70.179699, Pose2::new(1.5, -2.25, 3.0));
        t.push(70.309700, Pose2::new(0.0, 0.0, -1.2));
        let back = Trajectory::parse_tum("t.tum", &t.to_tum()).unwrap();
        assert_eq!(back.stamps, t.stamps);
        for (a, b) in back.poses.iter().zip(&t.poses) {
            assert!(a.distance(b) < 1e-6 && (a.theta - b.theta).abs() < 1e-8, "{a:?} {b:?}");
        }
    }

    #[test]
    fn a_declared_frame_is_read_back_and_ignored_by_the_parser() {
        let mut t = Trajectory::default();
        t.push(1.5, Pose2::new(1.0, 2.0, 0.5));
        let text = t.to_tum_in_frame("map");
        assert_eq!(declared_frame(&text), Some("map"));
        let back = Trajectory::parse_tum("t.tum", &text).unwrap();
        assert_eq!(back.stamps, t.stamps);
        assert_eq!(declared_frame(&t.to_tum()), None, "plain TUM declares nothing");
        // Only the leading comments count: a line after the poses does not.
        assert_eq!(declared_frame(&format!("{}# frame: map\n", t.to_tum())), None);
        assert_eq!(declared_frame("# frame: \n1 0 0 0 0 0 0 1\n"), None);
    }

    #[test]
    fn lookup_by_stamp_within_tolerance() {
        let mut t = Trajectory::default();
        for i in 0..10 {
            t.push(i as f64, Pose2::new(i as f64, 0.0, 0.0));
        }
        assert_eq!(t.at(3.0004, 1e-3).unwrap().x, 3.0);
        assert_eq!(t.at(2.9996, 1e-3).unwrap().x, 3.0);
        assert!(t.at(3.5, 1e-3).is_none());
        assert!(t.at(-1.0, 1e-3).is_none());
    }

    #[test]
    fn bad_lines_name_file_and_line() {
        let e = Trajectory::parse_tum("t.tum", "# c\n1 2 3 0 0 0 0 1\n2 2 3 0 0 0 1\n").unwrap_err();
        assert_eq!(e.to_string(), "t.tum:3: expected 8 fields (t x y z qx qy qz qw), found 7");
        let e = Trajectory::parse_tum("t.tum", "2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n").unwrap_err();
        assert!(e.to_string().starts_with("t.tum:2: stamps must not go back"), "{e}");
    }
}
