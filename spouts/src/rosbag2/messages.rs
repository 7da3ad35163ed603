//! The ROS 2 messages squall reads, decoded from CDR:
//! `sensor_msgs/msg/LaserScan`, `nav_msgs/msg/Odometry`,
//! `tf2_msgs/msg/TFMessage`.

use squall_bolts::geometry::Pose2;

use super::cdr::{Cdr, CdrResult};

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
fn pose(c: &mut Cdr<'_>, what: &str) -> CdrResult<Pose2> {
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
