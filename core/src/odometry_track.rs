//! The odometry stream as a function of time: the pose at any instant
//! between two messages, interpolated.
//!
//! A scan's pose must be the odometry at the instant the laser measured
//! it, which is rarely a message's stamp, and on real robots not even the
//! scan's own stamp (the two sensors' clocks and latencies differ:
//! [`crate::clock`]). Sources that carry the odometry stream
//! (CARMEN `ODOM` lines, a bag's `/odom`) keep it here and ask it for the
//! pose at each scan's instant.

use crate::geometry::{Pose2, normalize_angle};
use crate::sensor::Odometry;

/// How far (s) before the first or after the last message a pose is
/// still given (held at that message's); farther, none is.
pub const MAX_EXTRAPOLATION: f64 = 0.2;

/// The pose between two odometry messages `a` (at `ta`) and `b` (at `tb`)
/// at `t`: position and heading linear in time, the heading turning the
/// short way round.
pub fn interpolate_pose(ta: f64, a: &Pose2, tb: f64, b: &Pose2, t: f64) -> Pose2 {
    let span = tb - ta;
    let f = if span > 0.0 { ((t - ta) / span).clamp(0.0, 1.0) } else { 0.0 };
    Pose2::new(a.x + f * (b.x - a.x), a.y + f * (b.y - a.y), a.theta + f * normalize_angle(b.theta - a.theta))
}

/// The pose at `t` of `odometry` (messages in stamp order): interpolated
/// between the messages around it, held at the first or last within
/// [`MAX_EXTRAPOLATION`] of them, `None` farther out (or for a `t` that is
/// not finite).
pub fn pose_at(odometry: &[Odometry], t: f64) -> Option<Pose2> {
    let (first, last) = (odometry.first()?, odometry.last()?);
    if !t.is_finite() {
        return None;
    }
    if t <= first.stamp {
        return (first.stamp - t <= MAX_EXTRAPOLATION).then_some(first.pose);
    }
    if t >= last.stamp {
        return (t - last.stamp <= MAX_EXTRAPOLATION).then_some(last.pose);
    }
    let i = odometry.partition_point(|o| o.stamp <= t);
    let (a, b) = (&odometry[i - 1], &odometry[i]);
    Some(interpolate_pose(a.stamp, &a.pose, b.stamp, &b.pose, t))
}

/// Odometry messages in stamp order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OdometryTrack {
    messages: Vec<Odometry>,
}

impl OdometryTrack {
    /// An empty track.
    pub fn new() -> Self {
        OdometryTrack::default()
    }

    /// Appends a message. One stamped before the last, or not finite, is
    /// refused (`false`): a stream out of order has no pose at an instant.
    /// One stamped as the last replaces it.
    pub fn push(&mut self, stamp: f64, pose: Pose2) -> bool {
        if !stamp.is_finite() || self.messages.last().is_some_and(|last| stamp < last.stamp) {
            return false;
        }
        let message = Odometry { stamp, pose, linear_velocity: 0.0, angular_velocity: 0.0 };
        match self.messages.last_mut() {
            Some(last) if last.stamp == stamp => *last = message,
            _ => self.messages.push(message),
        }
        true
    }

    /// Messages held.
    pub fn len(&self) -> usize {
        self.messages.len()
    }

    /// Whether no message is held.
    pub fn is_empty(&self) -> bool {
        self.messages.is_empty()
    }

    /// The first and last stamps.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((self.messages.first()?.stamp, self.messages.last()?.stamp))
    }

    /// The pose at `t` ([`pose_at`]).
    pub fn at(&self, t: f64) -> Option<Pose2> {
        pose_at(&self.messages, t)
    }

    /// Drops the messages stamped before `t` except the last of them, so
    /// that [`Self::at`] still answers from `t` on: a live stream's track
    /// stays bounded.
    pub fn forget_before(&mut self, t: f64) {
        let keep_from = self.messages.partition_point(|m| m.stamp < t).saturating_sub(1);
        if keep_from > 0 {
            self.messages.drain(..keep_from);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Real;

    fn track(samples: &[(f64, Real, Real)]) -> OdometryTrack {
        let mut t = OdometryTrack::new();
        for &(s, x, theta) in samples {
            assert!(t.push(s, Pose2::new(x, 0.0, theta)));
        }
        t
    }

    #[test]
    fn interpolates_position_and_heading_across_the_wrap() {
        let t = track(&[(1.0, 0.0, 3.1), (2.0, 1.0, -3.1)]);
        let p = t.at(1.5).unwrap();
        assert!((p.x - 0.5).abs() < 1e-12);
        assert!((normalize_angle(p.theta) - std::f64::consts::PI).abs() < 1e-9, "{}", p.theta);
        assert_eq!(t.at(0.9).unwrap().x, 0.0);
        assert_eq!(t.at(2.1).unwrap().x, 1.0);
        assert!(t.at(0.5).is_none() && t.at(2.5).is_none() && t.at(f64::NAN).is_none());
        assert!(OdometryTrack::new().at(1.0).is_none());
    }

    #[test]
    fn refuses_messages_out_of_order_and_replaces_a_repeated_stamp() {
        let mut t = track(&[(1.0, 0.0, 0.0), (2.0, 1.0, 0.0)]);
        assert!(!t.push(1.5, Pose2::IDENTITY));
        assert!(!t.push(f64::INFINITY, Pose2::IDENTITY));
        assert!(t.push(2.0, Pose2::new(2.0, 0.0, 0.0)));
        assert_eq!((t.len(), t.at(2.0).unwrap().x), (2, 2.0));
    }

    #[test]
    fn forgetting_keeps_the_pose_at_the_cut() {
        let mut t = track(&[(1.0, 0.0, 0.0), (2.0, 1.0, 0.0), (3.0, 2.0, 0.0), (4.0, 3.0, 0.0)]);
        t.forget_before(2.5);
        assert_eq!(t.len(), 3);
        assert!((t.at(2.5).unwrap().x - 1.5).abs() < 1e-12);
    }
}
