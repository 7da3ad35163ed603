//! squall's messages as Foxglove's well-known schemas, in the frames a
//! ROS user expects: `map` (the estimate's), `odom` (the odometry's),
//! `base_link` (the robot) and `laser` (the scanner, at the reading's
//! mount). Pure functions: what a sink publishes is tested here.

use foxglove::messages::line_primitive::Type as LineType;
use foxglove::messages::packed_element_field::NumericType;
use foxglove::messages::{
    Color, FrameTransform, Grid, LaserScan, LinePrimitive, PackedElementField, Point3, PointCloud, Pose,
    PoseInFrame, PosesInFrame, Quaternion, SceneEntity, SceneUpdate, Timestamp, Vector2, Vector3,
};
use squall_core::geometry::{Pose2, Real};
use squall_core::linemap::LineMap;
use squall_core::occupancy::OccupancyGrid;
use squall_core::sensor::LaserReading;

use crate::cgr::observation::Observation2d;

/// The estimate's frame.
pub const MAP: &str = "map";
/// The odometry's frame.
pub const ODOM: &str = "odom";
/// The robot's frame.
pub const BASE_LINK: &str = "base_link";
/// The scanner's frame.
pub const LASER: &str = "laser";

/// A reading's stamp (seconds on its own clock; negative ones are 0).
pub fn timestamp(stamp: f64) -> Timestamp {
    let stamp = if stamp.is_finite() { stamp.max(0.0) } else { 0.0 };
    let sec = stamp.floor().min(f64::from(u32::MAX));
    let nsec = ((stamp - sec) * 1e9).round().min(999_999_999.0);
    Timestamp::new(sec as u32, nsec as u32)
}

/// A planar pose as a 3-D one (a turn about z).
pub fn pose(p: &Pose2) -> Pose {
    let (s, c) = (p.theta / 2.0).sin_cos();
    Pose {
        position: Some(Vector3 { x: p.x, y: p.y, z: 0.0 }),
        orientation: Some(Quaternion { x: 0.0, y: 0.0, z: s, w: c }),
    }
}

/// The transform placing `child` at `p` in `parent`.
pub fn transform(parent: &str, child: &str, p: &Pose2, stamp: f64) -> FrameTransform {
    let Pose { position, orientation } = pose(p);
    FrameTransform {
        timestamp: Some(timestamp(stamp)),
        parent_frame_id: parent.to_string(),
        child_frame_id: child.to_string(),
        translation: position,
        rotation: orientation,
    }
}

/// A scan in the `laser` frame; beams without a return are NaN (drawn as
/// nothing).
pub fn laser_scan(r: &LaserReading) -> LaserScan {
    let n = r.ranges.len();
    LaserScan {
        timestamp: Some(timestamp(r.stamp)),
        frame_id: LASER.to_string(),
        pose: Some(pose(&Pose2::IDENTITY)),
        start_angle: r.angle_min,
        end_angle: r.angle_min + n.saturating_sub(1) as Real * r.angle_increment,
        ranges: (0..n).map(|i| if r.is_valid(i) { f64::from(r.ranges[i]) } else { f64::NAN }).collect(),
        intensities: Vec::new(),
    }
}

/// A pose in the `map` frame.
pub fn pose_in_map(p: &Pose2, stamp: f64) -> PoseInFrame {
    PoseInFrame { timestamp: Some(timestamp(stamp)), frame_id: MAP.to_string(), pose: Some(pose(p)) }
}

/// Poses in the `map` frame (a trajectory, a particle set, hypotheses).
pub fn poses_in_map<'a>(poses: impl IntoIterator<Item = &'a Pose2>, stamp: f64) -> PosesInFrame {
    PosesInFrame {
        timestamp: Some(timestamp(stamp)),
        frame_id: MAP.to_string(),
        poses: poses.into_iter().map(pose).collect(),
    }
}

/// An occupancy grid in the `map` frame: one signed byte a cell,
/// percent occupied or -1 unknown, row 0 at the lowest y (as Foxglove's
/// grid and ROS's `nav_msgs/OccupancyGrid` both have it).
pub fn grid(g: &OccupancyGrid, stamp: f64) -> Grid {
    Grid {
        timestamp: Some(timestamp(stamp)),
        frame_id: MAP.to_string(),
        pose: Some(pose(&Pose2::new(g.origin.0, g.origin.1, 0.0))),
        column_count: g.width as u32,
        cell_size: Some(Vector2 { x: g.resolution, y: g.resolution }),
        row_stride: g.width as u32,
        cell_stride: 1,
        fields: vec![PackedElementField {
            name: "occupancy".to_string(),
            offset: 0,
            r#type: NumericType::Int8 as i32,
        }],
        data: g.cells.iter().map(|&c| c as u8).collect::<Vec<u8>>().into(),
    }
}

/// Points seen (plane-filtered depth, or a scan's points with normals),
/// in the `base_link` frame, as x, y, z float32s.
pub fn points(o: &Observation2d) -> PointCloud {
    let mut data = Vec::with_capacity(o.points.len() * 12);
    for p in &o.points {
        for v in [p[0], p[1], 0.0f32] {
            data.extend_from_slice(&v.to_le_bytes());
        }
    }
    let field = |name: &str, offset| PackedElementField {
        name: name.to_string(),
        offset,
        r#type: NumericType::Float32 as i32,
    };
    PointCloud {
        timestamp: Some(timestamp(o.stamp)),
        frame_id: BASE_LINK.to_string(),
        pose: Some(pose(&Pose2::IDENTITY)),
        point_stride: 12,
        fields: vec![field("x", 0), field("y", 4), field("z", 8)],
        data: data.into(),
    }
}

/// A line map's walls as one scene entity of line segments in `map`.
pub fn line_map(map: &LineMap, stamp: f64) -> SceneUpdate {
    let points = map
        .walls
        .iter()
        .flat_map(|w| [Point3 { x: w.a.0, y: w.a.1, z: 0.0 }, Point3 { x: w.b.0, y: w.b.1, z: 0.0 }])
        .collect();
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![SceneEntity {
            timestamp: Some(timestamp(stamp)),
            frame_id: MAP.to_string(),
            id: "line_map".to_string(),
            frame_locked: true,
            lines: vec![LinePrimitive {
                r#type: LineType::LineList as i32,
                pose: Some(pose(&Pose2::IDENTITY)),
                thickness: 0.05,
                scale_invariant: false,
                points,
                color: Some(Color { r: 0.1, g: 0.1, b: 0.1, a: 1.0 }),
                ..Default::default()
            }],
            ..Default::default()
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use squall_core::linemap::Segment;

    #[test]
    fn stamps_keep_their_nanoseconds_and_never_go_negative() {
        let t = timestamp(12.25);
        assert_eq!((t.sec(), t.nsec()), (12, 250_000_000));
        let t = timestamp(-3.0);
        assert_eq!((t.sec(), t.nsec()), (0, 0));
        assert_eq!(timestamp(f64::NAN).total_nanos(), 0);
    }

    #[test]
    fn a_heading_is_a_turn_about_z() {
        let p = pose(&Pose2::new(1.0, 2.0, std::f64::consts::FRAC_PI_2));
        let q = p.orientation.unwrap();
        assert!((q.z - (0.5f64).sqrt()).abs() < 1e-12 && (q.w - (0.5f64).sqrt()).abs() < 1e-12);
        assert_eq!((q.x, q.y), (0.0, 0.0));
        let t = p.position.unwrap();
        assert_eq!((t.x, t.y, t.z), (1.0, 2.0, 0.0));
    }

    #[test]
    fn a_scan_keeps_its_angles_and_marks_beams_without_return() {
        let r = LaserReading {
            stamp: 1.5,
            ranges: vec![1.0, 0.0, 2.0, 50.0],
            angle_min: -0.3,
            angle_increment: 0.2,
            range_min: 0.05,
            range_max: 40.0,
            odometry: Pose2::IDENTITY,
            laser_offset: Pose2::IDENTITY,
        };
        let s = laser_scan(&r);
        assert_eq!(s.frame_id, LASER);
        assert!((s.start_angle + 0.3).abs() < 1e-12 && (s.end_angle - 0.3).abs() < 1e-12);
        assert_eq!(s.ranges[0], 1.0);
        assert!(s.ranges[1].is_nan() && s.ranges[3].is_nan());
        assert_eq!(s.ranges[2], 2.0);
    }

    #[test]
    fn a_grid_is_a_byte_per_cell_from_its_lower_left_corner() {
        let mut g = OccupancyGrid::unknown(3, 2, 0.05, (-1.0, -2.0));
        g.set(2, 1, 100);
        g.set(0, 0, 0);
        let f = grid(&g, 0.0);
        assert_eq!((f.column_count, f.row_stride, f.cell_stride), (3, 3, 1));
        assert_eq!(&f.data[..], &[0, 255, 255, 255, 255, 100]);
        let origin = f.pose.unwrap().position.unwrap();
        assert_eq!((origin.x, origin.y), (-1.0, -2.0));
        assert_eq!(f.fields[0].r#type, NumericType::Int8 as i32);
    }

    #[test]
    fn points_are_packed_xyz_float32() {
        let o = Observation2d { points: vec![[1.0, 2.0], [3.0, -4.0]], ..Observation2d::default() };
        let c = points(&o);
        assert_eq!(c.data.len(), 24);
        assert_eq!(&c.data[12..16], &3.0f32.to_le_bytes());
        assert_eq!(&c.data[16..20], &(-4.0f32).to_le_bytes());
    }

    #[test]
    fn a_line_map_is_a_list_of_segments() {
        let map = LineMap {
            walls: vec![Segment { a: (0.0, 0.0), b: (1.0, 0.0) }, Segment { a: (1.0, 0.0), b: (1.0, 2.0) }],
        };
        let u = line_map(&map, 0.0);
        let lines = &u.entities[0].lines[0];
        assert_eq!(lines.points.len(), 4);
        assert_eq!(lines.r#type, LineType::LineList as i32);
        assert_eq!((lines.points[3].x, lines.points[3].y), (1.0, 2.0));
    }
}
