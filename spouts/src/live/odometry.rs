//! The robot's odometry as the live link hears it: the `odom → base_link`
//! transform on `/tf` when the robot broadcasts one (what gmapping and
//! slam_toolbox read), else `nav_msgs/Odometry` on `/odom`; kept for about
//! the last ten seconds so a scan, or a pose, can be placed at its stamp.

use squall_core::geometry::Pose2;
use squall_core::sensor::Odometry;

use crate::rosbag2::CdrError;
use crate::rosbag2::messages;
use crate::rosbag2::{MAX_EXTRAPOLATION, interpolate};

/// How long odometry is kept, seconds.
const KEPT: f64 = 10.0;

/// Odometry received, oldest first.
#[derive(Debug, Clone)]
pub struct OdometryTrack {
    odom_frame: String,
    base_frame: String,
    history: Vec<Odometry>,
    /// Whether the robot broadcasts `odom → base_link`: from then on the
    /// transforms are the odometry and `/odom` messages are not used.
    from_tf: bool,
}

/// A frame name without the leading slash ROS 1 habits leave.
fn frame(name: &str) -> &str {
    name.trim_start_matches('/')
}

impl OdometryTrack {
    /// A track of the transform `odom_frame → base_frame`.
    pub fn new(odom_frame: &str, base_frame: &str) -> Self {
        OdometryTrack {
            odom_frame: frame(odom_frame).to_string(),
            base_frame: frame(base_frame).to_string(),
            history: Vec::new(),
            from_tf: false,
        }
    }

    /// Whether the odometry comes from `/tf`.
    pub fn from_tf(&self) -> bool {
        self.from_tf
    }

    /// Takes an `/odom` message (CDR); ignored once `/tf` carries the
    /// odometry.
    pub fn take_odometry(&mut self, bytes: &[u8]) -> Result<(), CdrError> {
        let odometry = messages::odometry(bytes)?;
        if !self.from_tf {
            self.push(odometry.into_odometry());
        }
        Ok(())
    }

    /// Takes a `TFMessage` (CDR): its `odom → base_link` transforms, if
    /// any, become the odometry (the first one replaces what `/odom`
    /// gave: the two need not agree).
    pub fn take_tf(&mut self, bytes: &[u8]) -> Result<(), CdrError> {
        for t in messages::tf_message(bytes)? {
            if frame(&t.header.frame_id) != self.odom_frame || frame(&t.child_frame_id) != self.base_frame {
                continue;
            }
            if !self.from_tf {
                self.from_tf = true;
                self.history.clear();
            }
            self.push(Odometry {
                stamp: t.header.stamp,
                pose: t.pose,
                linear_velocity: 0.0,
                angular_velocity: 0.0,
            });
        }
        Ok(())
    }

    /// The odometry pose at `t`, interpolated; `None` outside what was
    /// received (beyond a short extrapolation).
    pub fn at(&self, t: f64) -> Option<Pose2> {
        interpolate(&self.history, t)
    }

    /// Keeps `o` if it is newer than the last, and about the last 10 s.
    fn push(&mut self, o: Odometry) {
        if self.history.last().is_some_and(|last| o.stamp <= last.stamp) {
            return;
        }
        let old = self.history.partition_point(|first| o.stamp - first.stamp > KEPT + MAX_EXTRAPOLATION);
        // Drained in batches, so each entry is moved about once.
        if old > 64 {
            self.history.drain(..old);
        }
        self.history.push(o);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf(stamp: f64, parent: &str, child: &str, x: f64) -> Vec<u8> {
        messages::tf_message_cdr(&[messages::TransformOut {
            stamp,
            frame_id: parent,
            child_frame_id: child,
            pose: Pose2::new(x, 0.0, 0.0),
        }])
    }

    #[test]
    fn odom_messages_serve_until_the_robot_broadcasts_odom_to_base_link() {
        let mut track = OdometryTrack::new("odom", "base_link");
        for k in 0..5 {
            let t = f64::from(k);
            track
                .take_odometry(&messages::odometry_cdr(t, "odom", "base_link", &Pose2::new(t, 0.0, 0.0)))
                .unwrap();
        }
        assert!((track.at(2.5).unwrap().x - 2.5).abs() < 1e-9);
        // Other transforms change nothing.
        track.take_tf(&tf(5.0, "map", "odom", 100.0)).unwrap();
        assert!(!track.from_tf());
        // The robot's own transform takes over, with a leading slash or not.
        track.take_tf(&tf(5.0, "/odom", "base_link", 10.0)).unwrap();
        track.take_tf(&tf(6.0, "odom", "/base_link", 12.0)).unwrap();
        track
            .take_odometry(&messages::odometry_cdr(5.5, "odom", "base_link", &Pose2::new(-1.0, 0.0, 0.0)))
            .unwrap();
        assert!(track.from_tf());
        assert!((track.at(5.5).unwrap().x - 11.0).abs() < 1e-9);
        assert!(track.at(2.5).is_none(), "the /odom history is dropped");
        assert!(track.take_tf(b"\x00\x01\x00\x00\xff").is_err());
    }
}
