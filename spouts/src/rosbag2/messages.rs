//! The ROS 2 messages squall reads, decoded from CDR:
//! `sensor_msgs/msg/LaserScan`, `nav_msgs/msg/Odometry`,
//! `tf2_msgs/msg/TFMessage`; and those it sends back to a robot, encoded:
//! `geometry_msgs/msg/PoseStamped`, `nav_msgs/msg/OccupancyGrid`,
//! `tf2_msgs/msg/TFMessage`.

use squall_core::geometry::Pose2;
use squall_core::sensor::{LaserReading, Odometry, check_scan_geometry};

use super::cdr::{Cdr, CdrError, CdrResult, CdrWriter};

/// `std_msgs/Header`: stamp (s) and frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// Seconds.
    pub stamp: f64,
    /// Frame id.
    pub frame_id: String,
}

fn header(c: &mut Cdr<'_>) -> CdrResult<Header> {
    let sec = c.i32("header.stamp.sec")?;
    let nanosec = c.u32("header.stamp.nanosec")?;
    let frame_id = c.string("header.frame_id")?;
    Ok(Header { stamp: f64::from(sec) + f64::from(nanosec) * 1e-9, frame_id })
}

/// Heading of a quaternion (yaw about z).
pub fn yaw(x: f64, y: f64, z: f64, w: f64) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// A planar pose from a 3-D position and orientation: x, y and yaw.
fn pose(c: &mut Cdr<'_>, what: &'static str) -> CdrResult<Pose2> {
    let x = c.f64(what)?;
    let y = c.f64(what)?;
    let _z = c.f64(what)?;
    let (qx, qy, qz, qw) = (c.f64(what)?, c.f64(what)?, c.f64(what)?, c.f64(what)?);
    Ok(Pose2::new(x, y, yaw(qx, qy, qz, qw)))
}

/// `sensor_msgs/msg/LaserScan`.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Stamp and laser frame.
    pub header: Header,
    /// First beam angle, rad.
    pub angle_min: f32,
    /// Beam spacing, rad.
    pub angle_increment: f32,
    /// Valid range limits, m.
    pub range_min: f32,
    /// Valid range limits, m.
    pub range_max: f32,
    /// Ranges, m.
    pub ranges: Vec<f32>,
}

impl LaserScan {
    /// The reading this scan makes, with the robot's `odometry` at its
    /// stamp and the laser's pose on the robot.
    pub fn into_reading(self, odometry: Pose2, laser_offset: Pose2) -> LaserReading {
        LaserReading {
            stamp: self.header.stamp,
            ranges: self.ranges,
            angle_min: f64::from(self.angle_min),
            angle_increment: f64::from(self.angle_increment),
            range_min: f64::from(self.range_min),
            range_max: f64::from(self.range_max),
            odometry,
            laser_offset,
        }
    }
}

/// Decodes a `LaserScan`.
pub fn laser_scan(bytes: &[u8]) -> CdrResult<LaserScan> {
    let mut c = Cdr::new(bytes)?;
    let header = header(&mut c)?;
    let angle_min = c.f32("angle_min")?;
    let _angle_max = c.f32("angle_max")?;
    let angle_increment = c.f32("angle_increment")?;
    let _time_increment = c.f32("time_increment")?;
    let _scan_time = c.f32("scan_time")?;
    let range_min = c.f32("range_min")?;
    let range_max = c.f32("range_max")?;
    let ranges = c.f32_seq("ranges")?;
    let _intensities = c.f32_seq("intensities")?;
    check_scan_geometry(ranges.len(), f64::from(angle_min), f64::from(angle_increment))
        .map_err(CdrError::ScanGeometry)?;
    Ok(LaserScan { header, angle_min, angle_increment, range_min, range_max, ranges })
}

/// `nav_msgs/msg/Odometry`, planar part.
#[derive(Debug, Clone, PartialEq)]
pub struct OdometryMsg {
    /// Stamp and odometry frame.
    pub header: Header,
    /// The robot's pose.
    pub pose: Pose2,
    /// Forward velocity, m/s.
    pub linear_x: f64,
    /// Turn rate, rad/s.
    pub angular_z: f64,
}

impl OdometryMsg {
    /// The odometry reading it carries.
    pub fn into_odometry(self) -> Odometry {
        Odometry {
            stamp: self.header.stamp,
            pose: self.pose,
            linear_velocity: self.linear_x,
            angular_velocity: self.angular_z,
        }
    }
}

/// Decodes an `Odometry`.
pub fn odometry(bytes: &[u8]) -> CdrResult<OdometryMsg> {
    let mut c = Cdr::new(bytes)?;
    let header = header(&mut c)?;
    let _child = c.string("child_frame_id")?;
    let pose = pose(&mut c, "pose.pose")?;
    c.skip_f64s(36, "pose.covariance")?;
    let linear_x = c.f64("twist.linear.x")?;
    c.skip_f64s(4, "twist")?;
    let angular_z = c.f64("twist.angular.z")?;
    c.skip_f64s(36, "twist.covariance")?;
    Ok(OdometryMsg { header, pose, linear_x, angular_z })
}

/// One `geometry_msgs/TransformStamped`, planar part.
#[derive(Debug, Clone, PartialEq)]
pub struct Transform {
    /// Stamp and parent frame.
    pub header: Header,
    /// Child frame.
    pub child_frame_id: String,
    /// The child's pose in the parent frame.
    pub pose: Pose2,
}

/// Decodes a `TFMessage`.
pub fn tf_message(bytes: &[u8]) -> CdrResult<Vec<Transform>> {
    let mut c = Cdr::new(bytes)?;
    // A transform takes at least 4+4+4+4+7*8 bytes.
    let n = c.seq_len(72, "transforms")?;
    (0..n)
        .map(|_| {
            let header = header(&mut c)?;
            let child_frame_id = c.string("child_frame_id")?;
            let pose = pose(&mut c, "transform")?;
            Ok(Transform { header, child_frame_id, pose })
        })
        .collect()
}

/// `builtin_interfaces/Time`: whole seconds and nanoseconds.
fn write_stamp(w: &mut CdrWriter, stamp: f64) {
    let sec = stamp.floor();
    // Stamps outside i32 seconds (year 2038 on) saturate.
    w.i32(sec.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32);
    w.u32((((stamp - sec) * 1e9).round() as u32).min(999_999_999));
}

/// `std_msgs/Header`.
fn write_header(w: &mut CdrWriter, stamp: f64, frame_id: &str) {
    write_stamp(w, stamp);
    w.string(frame_id);
}

/// A planar pose as a 3-D position (z = 0) and a yaw quaternion.
fn write_pose(w: &mut CdrWriter, pose: &Pose2) {
    let (s, c) = (pose.theta * 0.5).sin_cos();
    for v in [pose.x, pose.y, 0.0, 0.0, 0.0, s, c] {
        w.f64(v);
    }
}

/// Encodes a `geometry_msgs/msg/PoseStamped` (a robot's estimated pose).
pub fn pose_stamped(stamp: f64, frame_id: &str, pose: &Pose2) -> Vec<u8> {
    let mut w = CdrWriter::new();
    write_header(&mut w, stamp, frame_id);
    write_pose(&mut w, pose);
    w.finish()
}

/// Decodes a `geometry_msgs/msg/PoseStamped` (planar part).
pub fn read_pose_stamped(bytes: &[u8]) -> CdrResult<(Header, Pose2)> {
    let mut c = Cdr::new(bytes)?;
    let header = header(&mut c)?;
    Ok((header, pose(&mut c, "pose")?))
}

/// A map to send as `nav_msgs/msg/OccupancyGrid`: row-major cells from
/// the origin's corner, each −1 (unknown) or 0–100 (occupancy, %).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OccupancyGridMsg<'a> {
    /// Stamp, seconds.
    pub stamp: f64,
    /// The map's frame.
    pub frame_id: &'a str,
    /// Metres per cell.
    pub resolution: f32,
    /// Cells per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// The pose of cell (0, 0)'s corner.
    pub origin: Pose2,
    /// `width × height` cells.
    pub data: &'a [i8],
}

/// Encodes a `nav_msgs/msg/OccupancyGrid`; `None` if `data` does not hold
/// `width × height` cells.
pub fn occupancy_grid(map: &OccupancyGridMsg<'_>) -> Option<Vec<u8>> {
    if map.data.len() != map.width as usize * map.height as usize {
        return None;
    }
    let mut w = CdrWriter::new();
    write_header(&mut w, map.stamp, map.frame_id);
    // info: map_load_time, resolution, width, height, origin.
    write_stamp(&mut w, map.stamp);
    w.f32(map.resolution);
    w.u32(map.width);
    w.u32(map.height);
    write_pose(&mut w, &map.origin);
    w.byte_seq(map.data.iter().map(|&v| v as u8));
    Some(w.finish())
}

/// Encodes a `sensor_msgs/msg/LaserScan` as a ROS 2 driver would publish
/// it (no intensities; angle_max from the beam count).
pub fn laser_scan_cdr(scan: &LaserReading, frame_id: &str) -> Vec<u8> {
    let mut w = CdrWriter::new();
    write_header(&mut w, scan.stamp, frame_id);
    let last = scan.ranges.len().saturating_sub(1) as f64;
    w.f32(scan.angle_min as f32);
    w.f32((scan.angle_min + last * scan.angle_increment) as f32);
    w.f32(scan.angle_increment as f32);
    w.f32(0.0);
    w.f32(0.0);
    w.f32(scan.range_min as f32);
    w.f32(scan.range_max as f32);
    w.u32(scan.ranges.len() as u32);
    for &r in &scan.ranges {
        w.f32(r);
    }
    w.u32(0);
    w.finish()
}

/// Encodes a `nav_msgs/msg/Odometry` with the planar pose (covariances and
/// velocities zero).
pub fn odometry_cdr(stamp: f64, frame_id: &str, child_frame_id: &str, pose: &Pose2) -> Vec<u8> {
    let mut w = CdrWriter::new();
    write_header(&mut w, stamp, frame_id);
    w.string(child_frame_id);
    write_pose(&mut w, pose);
    for _ in 0..36 + 6 + 36 {
        w.f64(0.0);
    }
    w.finish()
}

/// One transform to send: the `child_frame_id` frame's pose in
/// `frame_id` at `stamp`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransformOut<'a> {
    /// Seconds.
    pub stamp: f64,
    /// The parent frame.
    pub frame_id: &'a str,
    /// The child frame.
    pub child_frame_id: &'a str,
    /// The child's pose in the parent frame.
    pub pose: Pose2,
}

/// Encodes a `tf2_msgs/msg/TFMessage` of planar transforms.
pub fn tf_message_cdr(transforms: &[TransformOut<'_>]) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.u32(u32::try_from(transforms.len()).unwrap_or(u32::MAX));
    for t in transforms {
        write_header(&mut w, t.stamp, t.frame_id);
        w.string(t.child_frame_id);
        write_pose(&mut w, &t.pose);
    }
    w.finish()
}

#[cfg(test)]
mod encode_tests {
    use super::*;

    /// A 3 × 2 map with every kind of cell.
    fn small_map() -> OccupancyGridMsg<'static> {
        OccupancyGridMsg {
            stamp: 3.5,
            frame_id: "map",
            resolution: 0.05,
            width: 3,
            height: 2,
            origin: Pose2::new(-1.0, -0.5, 0.0),
            data: &[-1, 0, 100, 50, -1, 0],
        }
    }

    #[test]
    fn scans_and_odometry_read_back_as_written() {
        let scan = LaserReading {
            stamp: 7.5,
            ranges: vec![1.0, 2.5, 80.0],
            angle_min: -1.5,
            angle_increment: 1.5,
            range_min: 0.1,
            range_max: 80.0,
            odometry: Pose2::IDENTITY,
            laser_offset: Pose2::IDENTITY,
        };
        let back = laser_scan(&laser_scan_cdr(&scan, "laser")).unwrap();
        assert_eq!(back.header, Header { stamp: 7.5, frame_id: "laser".into() });
        assert_eq!((back.angle_min, back.angle_increment, back.range_max), (-1.5, 1.5, 80.0));
        assert_eq!(back.ranges, scan.ranges);
        let odom = odometry(&odometry_cdr(7.25, "odom", "base_link", &Pose2::new(1.0, 2.0, -0.5))).unwrap();
        assert_eq!(odom.header.stamp, 7.25);
        assert!((odom.pose.x - 1.0).abs() < 1e-12 && (odom.pose.theta + 0.5).abs() < 1e-12);
    }

    #[test]
    fn a_pose_stamped_has_ros_2s_layout() {
        let bytes = pose_stamped(12.25, "map", &Pose2::new(1.0, -2.0, std::f64::consts::FRAC_PI_2));
        let (h, p) = read_pose_stamped(&bytes).unwrap();
        assert_eq!((h.stamp, p.x), (12.25, 1.0));
        // header: sec, nanosec, "map\0" (len 4) = 16 bytes, already 8-aligned;
        // then position (3 f64) and orientation (4 f64).
        assert_eq!(bytes.len(), 4 + 16 + 56);
        let mut c = Cdr::new(&bytes).unwrap();
        assert_eq!(header(&mut c).unwrap(), Header { stamp: 12.25, frame_id: "map".into() });
        let p = pose(&mut c, "pose").unwrap();
        assert!((p.x - 1.0).abs() < 1e-12 && (p.y + 2.0).abs() < 1e-12);
        assert!((p.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn an_occupancy_grid_has_ros_2s_layout() {
        let map = small_map();
        let bytes = occupancy_grid(&map).unwrap();
        let mut c = Cdr::new(&bytes).unwrap();
        assert_eq!(header(&mut c).unwrap().frame_id, "map");
        assert_eq!((c.i32("sec").unwrap(), c.u32("nsec").unwrap()), (3, 500_000_000));
        assert_eq!(c.f32("resolution").unwrap(), 0.05);
        assert_eq!((c.u32("w").unwrap(), c.u32("h").unwrap()), (3, 2));
        assert_eq!(pose(&mut c, "origin").unwrap(), Pose2::new(-1.0, -0.5, 0.0));
        let n = c.seq_len(1, "data").unwrap();
        assert_eq!(n, 6);
        // The cells are the last bytes: nothing follows them.
        assert_eq!(&bytes[bytes.len() - 6..], &[255, 0, 100, 50, 255, 0]);
        assert!(occupancy_grid(&OccupancyGridMsg { width: 4, ..map }).is_none());
    }

    /// Bytes from an independent implementation: the `rosbags` Python
    /// package's `serialize_cdr` (ROS 2 Humble types) for the same values.
    fn golden(hex: &str) -> Vec<u8> {
        (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect()
    }

    #[test]
    fn the_encodings_match_an_independent_implementation() {
        let pose = pose_stamped(12.25, "map", &Pose2::new(1.0, -2.0, std::f64::consts::FRAC_PI_2));
        assert_eq!(
            pose,
            golden(
                "000100000c00000080b2e60e040000006d617000000000000000f03f00000000000000c00000000000000000\
                 00000000000000000000000000000000cc3b7f669ea0e63fcd3b7f669ea0e63f"
            )
        );
        let map = small_map();
        assert_eq!(
            occupancy_grid(&map).unwrap(),
            golden(
                "00010000030000000065cd1d040000006d617000030000000065cd1dcdcc4c3d030000000200000000000000\
                 000000000000f0bf000000000000e0bf000000000000000000000000000000000000000000000000000000000\
                 0000000000000000000f03f06000000ff006432ff00"
            )
        );
    }
}
