//! CARMEN log lines → readings.
//!
//! Formats (CARMEN 0.7 and the Radish logs):
//! - `ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp`
//! - `FLASER n r_1 .. r_n laser_x laser_y laser_theta odom_x odom_y odom_theta
//!   ipc_timestamp host logger_timestamp` (`RLASER` likewise, rear laser)
//! - `ROBOTLASER1 type start_angle fov resolution max_range accuracy
//!   remission_mode n r_1 .. r_n m e_1 .. e_m laser_x laser_y laser_theta
//!   robot_x robot_y robot_theta tv rv forward_safety side_safety turn_axis
//!   ipc_timestamp host logger_timestamp`
//! - `PARAM name value host timestamp`: `laser_{front,rear}_laser_angle_min`,
//!   `laser_{front,rear}_laser_angle_increment`, `robot_{front,rear}_laser_max`
//!   give the FLASER/RLASER beam geometry. Without them, n beams span 180°:
//!   beam i is at −90° + i·180°/(n−1).
//!
//! Field counts are checked exactly, so a cut-off line is an error, never a
//! short scan. Other message types are recognised as such and skipped by the
//! caller (and counted there).

use std::f64::consts::PI;

use squall_core::geometry::{Pose2, Real};
use squall_core::sensor::{LaserReading, Odometry};

/// Which laser a scan came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Laser {
    /// FLASER, or a ROBOTLASER1.
    Front,
    /// RLASER.
    Rear,
}

/// One parsed line.
#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// A scan with the odometry pose at its stamp.
    Scan(Laser, LaserReading),
    /// An odometry message.
    Odom(Odometry),
    /// A parameter (already applied to later scans).
    Param(String, String),
    /// A message type this reader does not use (e.g. `SYNC`, `TRUEPOS`).
    Other(String),
}

/// What is wrong with a line: what was expected and what was found. A
/// [`LogError`](super::LogError) adds the file and line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RecordError {
    /// A record with more or fewer fields than its layout has.
    #[error(
        "{keyword} {layout} needs {expected} fields after the keyword, found {found}{}",
        if .found < .expected { " (line cut off?)" } else { "" }
    )]
    FieldCount {
        /// The message type (`ODOM`, `FLASER`, ...).
        keyword: String,
        /// The fields expected, or how many readings they hold.
        layout: String,
        /// Fields expected after the keyword.
        expected: usize,
        /// Fields found.
        found: usize,
    },
    /// A field that must be a finite number is not.
    #[error("{keyword}: expected a number for {what} (field {field}), found \"{found}\"")]
    NotANumber {
        /// The message type.
        keyword: String,
        /// What the field holds.
        what: &'static str,
        /// 1-based field after the keyword.
        field: usize,
        /// The text found.
        found: String,
    },
    /// A field that must be a count (of readings) is not.
    #[error("{keyword}: expected a count for {what} (field {field}), found \"{found}\"")]
    NotACount {
        /// The message type.
        keyword: String,
        /// What the count counts.
        what: &'static str,
        /// 1-based field after the keyword.
        field: usize,
        /// The text found.
        found: String,
    },
    /// The line ends before a field the rest of the layout depends on.
    #[error("{keyword}: missing {what} (line cut off?)")]
    Missing {
        /// The message type.
        keyword: String,
        /// The missing field.
        what: &'static str,
    },
    /// A scan of fewer than 2 readings: its beams have no spacing.
    #[error("{keyword}: a scan needs at least 2 readings, found {found}")]
    TooFewReadings {
        /// The message type.
        keyword: String,
        /// Readings found.
        found: usize,
    },
    /// A scan whose geometry no laser has (see
    /// [`LaserReading::check_geometry`]).
    #[error("{keyword}: {message}")]
    Geometry {
        /// The message type.
        keyword: String,
        /// What is wrong.
        message: String,
    },
    /// A `PARAM` line without both a name and a value.
    #[error("PARAM needs a name and a value")]
    ParamIncomplete,
    /// A laser geometry `PARAM` whose value is not a number.
    #[error("PARAM {name}: expected a number, found \"{value}\"")]
    ParamNotANumber {
        /// The parameter.
        name: String,
        /// Its value.
        value: String,
    },
    /// A laser geometry `PARAM` whose number cannot describe a laser.
    #[error("PARAM {name}: expected {expected}, found {value}")]
    ParamOutOfRange {
        /// The parameter.
        name: String,
        /// Its value, as written.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
}

/// Beam geometry of one laser, from PARAM lines or defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Geometry {
    angle_min: Option<Real>,
    angle_increment: Option<Real>,
    range_max: Option<Real>,
}

/// Parses lines, remembering PARAM values for the scans after them.
#[derive(Debug, Clone)]
pub struct LineParser {
    front: Geometry,
    rear: Geometry,
    default_range_max: Real,
}

impl LineParser {
    /// A parser; `default_range_max` (metres) applies to lasers whose log
    /// gives no `robot_*_laser_max`.
    pub fn new(default_range_max: Real) -> Self {
        let none = Geometry { angle_min: None, angle_increment: None, range_max: None };
        LineParser { front: none, rear: none, default_range_max }
    }

    /// Parses one line (without its newline). `Ok(None)` for blank lines
    /// and comments; `Err` says what was expected.
    pub fn parse(&mut self, line: &str) -> Result<Option<Record>, RecordError> {
        let line = line.trim_end_matches('\r');
        let mut fields = line.split_ascii_whitespace();
        let Some(keyword) = fields.next() else { return Ok(None) };
        if keyword.starts_with('#') {
            return Ok(None);
        }
        let rest: Fields<'_> = Fields { items: fields.collect(), keyword };
        match keyword {
            "ODOM" => rest.odom().map(|o| Some(Record::Odom(o))),
            "FLASER" => {
                rest.flaser(&self.front, self.default_range_max).map(|r| Some(Record::Scan(Laser::Front, r)))
            }
            "RLASER" => {
                rest.flaser(&self.rear, self.default_range_max).map(|r| Some(Record::Scan(Laser::Rear, r)))
            }
            "ROBOTLASER1" => rest.robotlaser1().map(|r| Some(Record::Scan(Laser::Front, r))),
            "PARAM" => {
                let (name, value) = rest.param()?;
                self.apply_param(&name, &value)?;
                Ok(Some(Record::Param(name, value)))
            }
            other => Ok(Some(Record::Other(other.to_string()))),
        }
    }

    fn apply_param(&mut self, name: &str, value: &str) -> Result<(), RecordError> {
        use std::f64::consts::{PI, TAU};
        // What a laser's geometry can be: a first beam within a turn either
        // way, a nonzero step of at most half a turn, a positive range.
        // NaN fails every test.
        type Valid = (fn(Real) -> bool, &'static str);
        const ANGLE: Valid = (|v| v.abs() <= TAU, "an angle in [-2π, 2π]");
        const STEP: Valid = (|v| v != 0.0 && v.abs() <= PI, "a nonzero step in [-π, π]");
        const RANGE: Valid = (|v| v > 0.0 && v.is_finite(), "a range > 0");
        let (target, (valid, expected)) = match name {
            "laser_front_laser_angle_min" => (&mut self.front.angle_min, ANGLE),
            "laser_front_laser_angle_increment" => (&mut self.front.angle_increment, STEP),
            "robot_front_laser_max" => (&mut self.front.range_max, RANGE),
            "laser_rear_laser_angle_min" => (&mut self.rear.angle_min, ANGLE),
            "laser_rear_laser_angle_increment" => (&mut self.rear.angle_increment, STEP),
            "robot_rear_laser_max" => (&mut self.rear.range_max, RANGE),
            _ => return Ok(()),
        };
        let v: Real = value
            .parse()
            .map_err(|_| RecordError::ParamNotANumber { name: name.to_string(), value: value.to_string() })?;
        if !valid(v) {
            return Err(RecordError::ParamOutOfRange {
                name: name.to_string(),
                value: value.to_string(),
                expected,
            });
        }
        *target = Some(v);
        Ok(())
    }
}

struct Fields<'a> {
    items: Vec<&'a str>,
    keyword: &'a str,
}

impl<'a> Fields<'a> {
    fn expect_len(&self, n: usize, layout: impl Into<String>) -> Result<(), RecordError> {
        if self.items.len() == n {
            Ok(())
        } else {
            Err(RecordError::FieldCount {
                keyword: self.keyword.to_string(),
                layout: layout.into(),
                expected: n,
                found: self.items.len(),
            })
        }
    }

    fn num(&self, i: usize, what: &'static str) -> Result<Real, RecordError> {
        // Callers check the field count first; a line cut off still gives
        // an error, never a panic.
        let Some(&s) = self.items.get(i) else {
            return Err(RecordError::Missing { keyword: self.keyword.to_string(), what });
        };
        match s.parse::<Real>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(RecordError::NotANumber {
                keyword: self.keyword.to_string(),
                what,
                field: i + 1,
                found: s.to_string(),
            }),
        }
    }

    fn count(&self, i: usize, what: &'static str) -> Result<usize, RecordError> {
        let &s = self
            .items
            .get(i)
            .ok_or_else(|| RecordError::Missing { keyword: self.keyword.to_string(), what })?;
        s.parse::<usize>().map_err(|_| RecordError::NotACount {
            keyword: self.keyword.to_string(),
            what,
            field: i + 1,
            found: s.to_string(),
        })
    }

    fn pose(&self, i: usize, what: &'static str) -> Result<Pose2, RecordError> {
        Ok(Pose2::new(self.num(i, what)?, self.num(i + 1, what)?, self.num(i + 2, what)?))
    }

    fn ranges(&self, from: usize, n: usize) -> Result<Vec<f32>, RecordError> {
        (from..from.saturating_add(n)).map(|i| self.num(i, "a range").map(|r| r as f32)).collect()
    }

    fn odom(&self) -> Result<Odometry, RecordError> {
        self.expect_len(9, "(x y theta tv rv accel ipc_timestamp host logger_timestamp)")?;
        Ok(Odometry {
            pose: self.pose(0, "the pose")?,
            linear_velocity: self.num(3, "tv")?,
            angular_velocity: self.num(4, "rv")?,
            stamp: self.num(6, "ipc_timestamp")?,
        })
    }

    /// The scan, if its geometry is one a laser can have.
    fn checked(&self, scan: LaserReading) -> Result<LaserReading, RecordError> {
        scan.check_geometry()
            .map_err(|message| RecordError::Geometry { keyword: self.keyword.to_string(), message })?;
        Ok(scan)
    }

    fn flaser(&self, geometry: &Geometry, default_range_max: Real) -> Result<LaserReading, RecordError> {
        let n = self.count(0, "num_readings")?;
        if n < 2 {
            return Err(RecordError::TooFewReadings { keyword: self.keyword.to_string(), found: n });
        }
        // Saturating: a count near usize::MAX is simply more fields than
        // the line has.
        self.expect_len(n.saturating_add(10), format!("with {n} readings"))?;
        let ranges = self.ranges(1, n)?;
        let laser = self.pose(n + 1, "the laser pose")?;
        let odometry = self.pose(n + 4, "the odometry pose")?;
        self.checked(LaserReading {
            stamp: self.num(n + 7, "ipc_timestamp")?,
            ranges,
            angle_min: geometry.angle_min.unwrap_or(-PI / 2.0),
            angle_increment: geometry.angle_increment.unwrap_or(PI / (n - 1) as Real),
            range_min: 0.0,
            range_max: geometry.range_max.unwrap_or(default_range_max),
            laser_offset: laser.relative_to(&odometry),
            odometry,
        })
    }

    fn robotlaser1(&self) -> Result<LaserReading, RecordError> {
        let n = self.count(7, "num_readings")?;
        let m = self.count(n.saturating_add(8), "num_remissions")?;
        // `m` was found after the `n` readings, so `n + 9` cannot overflow;
        // saturating, an absurd `m` is simply more fields than the line has.
        // Once the count matches, every index below is within the line.
        let fields = (n + 9).saturating_add(m).saturating_add(14);
        self.expect_len(fields, format!("with {n} readings and {m} remissions"))?;
        let start_angle = self.num(1, "start_angle")?;
        let resolution = self.num(3, "angular_resolution")?;
        let range_max = self.num(4, "maximum_range")?;
        let ranges = self.ranges(8, n)?;
        let at = 8 + n + 1 + m;
        let laser = self.pose(at, "the laser pose")?;
        let odometry = self.pose(at + 3, "the robot pose")?;
        self.checked(LaserReading {
            stamp: self.num(at + 11, "ipc_timestamp")?,
            ranges,
            angle_min: start_angle,
            angle_increment: resolution,
            range_min: 0.0,
            range_max,
            laser_offset: laser.relative_to(&odometry),
            odometry,
        })
    }

    fn param(&self) -> Result<(String, String), RecordError> {
        if self.items.len() < 2 {
            return Err(RecordError::ParamIncomplete);
        }
        Ok((self.items[0].to_string(), self.items[1].to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(line: &str, p: &mut LineParser) -> LaserReading {
        match p.parse(line).unwrap() {
            Some(Record::Scan(_, r)) => r,
            other => panic!("not a scan: {other:?}"),
        }
    }

    #[test]
    fn flaser_without_params_spans_180_degrees() {
        let mut p = LineParser::new(80.0);
        let r = scan("FLASER 3 1.0 2.0 81.91 1.5 2.0 0.0 1.0 2.0 0.0 12.5 host 12.6", &mut p);
        assert_eq!(r.ranges, vec![1.0, 2.0, 81.91]);
        assert_eq!(r.stamp, 12.5);
        assert!((r.angle_min + PI / 2.0).abs() < 1e-12);
        assert!((r.angle_increment - PI / 2.0).abs() < 1e-12);
        assert_eq!(r.range_max, 80.0);
        assert!(!r.is_valid(2), "81.91 is a no-return reading");
        assert_eq!(r.odometry, Pose2::new(1.0, 2.0, 0.0));
        // The laser sits 0.5 m ahead of the robot along its heading.
        assert!((r.laser_offset.x - 0.5).abs() < 1e-9 && r.laser_offset.y.abs() < 1e-9);
    }

    #[test]
    fn params_set_the_geometry_of_later_scans() {
        let mut p = LineParser::new(80.0);
        for line in [
            "PARAM laser_front_laser_angle_min -1.570796371 nohost 0",
            "PARAM laser_front_laser_angle_increment 0.017550798 nohost 0",
            "PARAM robot_front_laser_max 50.00 nohost 0",
        ] {
            assert!(matches!(p.parse(line).unwrap(), Some(Record::Param(..))));
        }
        let r = scan("FLASER 2 1 2 0 0 0 0 0 0 1.0 h 1.0", &mut p);
        assert_eq!((r.angle_min, r.angle_increment, r.range_max), (-1.570796371, 0.017550798, 50.0));
    }

    #[test]
    fn odom_and_robotlaser1() {
        let mut p = LineParser::new(80.0);
        let o = p.parse("ODOM 1 2 3 0.5 0.1 0 70.18 nohost 70.18").unwrap();
        assert!(matches!(o, Some(Record::Odom(Odometry { stamp: 70.18, linear_velocity: 0.5, .. }))));
        let line = "ROBOTLASER1 0 -1.5708 3.1416 0.0175 81.9 0.01 0 3 1 2 3 0 \
                    1 1 0 1 1 0 0 0 0 0 0 5.5 host 5.6";
        let r = scan(line, &mut p);
        assert_eq!((r.ranges.len(), r.stamp, r.range_max), (3, 5.5, 81.9));
    }

    #[test]
    fn absurd_counts_are_errors_not_overflows() {
        let mut p = LineParser::new(80.0);
        let max = usize::MAX;
        let e = p.parse(&format!("FLASER {max} 1 2 3 4 5 6 7 8 9 10 11")).unwrap_err().to_string();
        assert!(e.starts_with(&format!("FLASER with {max} readings needs {max} fields")), "{e}");
        let e = p.parse(&format!("ROBOTLASER1 0 0 0 0 0 0 0 {max} 1 2")).unwrap_err();
        assert_eq!(e.to_string(), "ROBOTLASER1: missing num_remissions (line cut off?)");
        let e = p.parse(&format!("ROBOTLASER1 0 0 0 0 0 0 0 1 5 {max} 0 0 0")).unwrap_err().to_string();
        assert!(e.contains(&format!("with 1 readings and {max} remissions needs")), "{e}");
    }

    #[test]
    fn a_scan_no_laser_could_make_is_an_error_naming_it() {
        let flaser = |n: usize| {
            let ranges = vec!["1.0"; n].join(" ");
            format!("FLASER {n} {ranges} 0 0 0 0 0 0 1.0 h 1.0")
        };
        let mut p = LineParser::new(80.0);
        assert!(p.parse(&flaser(65536)).is_ok(), "the most beams a scan may have");
        let e = p.parse(&flaser(65537)).unwrap_err().to_string();
        assert_eq!(e, "FLASER: 65537 beams: expected at most 65536 (no laser has more)");
        // Beams 3 rad apart: 360 of them wind round 171 times.
        p.parse("PARAM laser_front_laser_angle_increment 3.0 h 0").unwrap();
        let e = p.parse(&flaser(360)).unwrap_err().to_string();
        assert!(
            e.starts_with("FLASER: 360 beams 3 rad apart span 171.4 turns: expected at most one turn"),
            "{e}"
        );
        let robot = |step: f64| {
            format!("ROBOTLASER1 0 -1.5 3.1 {step} 80 0 0 4 1 1 1 1 0 {} 1.0 h 1.0", ["0"; 11].join(" "))
        };
        assert!(p.parse(&robot(2.0)).is_ok(), "4 beams 2 rad apart: within a turn");
        let e = p.parse(&robot(3.1)).unwrap_err().to_string();
        assert!(e.starts_with("ROBOTLASER1: 4 beams 3.1 rad apart span 1.5 turns"), "{e}");
    }

    #[test]
    fn cut_off_and_malformed_lines_say_what_was_expected() {
        let mut p = LineParser::new(80.0);
        let e = p.parse("FLASER 180 1.0 2.0 3.0").unwrap_err().to_string();
        assert!(
            e.contains(
                "FLASER with 180 readings needs 190 fields after the keyword, found 4 (line cut off?)"
            ),
            "{e}"
        );
        let e = p.parse("ODOM 1 2 x 0 0 0 1 h 1").unwrap_err().to_string();
        assert!(e.contains("expected a number for the pose (field 3), found \"x\""), "{e}");
        let e = p.parse("FLASER many 1 2").unwrap_err().to_string();
        assert!(e.contains("expected a count for num_readings"), "{e}");
        let e = p.parse("PARAM robot_front_laser_max far h 0").unwrap_err();
        assert_eq!(e.to_string(), "PARAM robot_front_laser_max: expected a number, found \"far\"");
        // Numbers that describe no laser: each used to be taken and to
        // degrade the map silently.
        for (line, expected) in [
            (
                "PARAM laser_front_laser_angle_increment nan h 0",
                "expected a nonzero step in [-π, π], found nan",
            ),
            ("PARAM laser_front_laser_angle_increment 0 h 0", "expected a nonzero step in [-π, π], found 0"),
            ("PARAM laser_rear_laser_angle_min inf h 0", "expected an angle in [-2π, 2π], found inf"),
            ("PARAM robot_front_laser_max -1 h 0", "expected a range > 0, found -1"),
        ] {
            let e = p.parse(line).unwrap_err().to_string();
            assert!(e.ends_with(expected), "{line}: {e}");
        }
        assert_eq!(p.parse("PARAM x").unwrap_err(), RecordError::ParamIncomplete);
        assert_eq!(
            p.parse("FLASER 1 5 0 0 0 0 0 0 1 h 1").unwrap_err().to_string(),
            "FLASER: a scan needs at least 2 readings, found 1"
        );
        assert_eq!(p.parse("   ").unwrap(), None);
        assert_eq!(p.parse("# comment").unwrap(), None);
        assert_eq!(p.parse("SYNC 1 2").unwrap(), Some(Record::Other("SYNC".into())));
    }
}
