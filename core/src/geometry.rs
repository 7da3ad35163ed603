//! Planar rigid motions (SE(2)) in SI units: metres and radians.

use serde::{Deserialize, Serialize};

/// The scalar type of the geometry code.
pub type Real = f64;

/// `v` rounded to the nearest integer (ties to even), as a float and as an
/// integer, for |`v`| < 2⁵¹. Adding 1.5·2⁵² leaves the rounded value in the
/// low bits of the sum: in hot loops this replaces a float-to-integer
/// conversion, whose saturation checks cost more than the rest.
#[inline(always)]
pub fn round_small(v: Real) -> (Real, i64) {
    const SHIFTER: Real = 6_755_399_441_055_744.0;
    let shifted = v + SHIFTER;
    (shifted - SHIFTER, shifted.to_bits() as i64 - SHIFTER.to_bits() as i64)
}

/// Wraps an angle into (-π, π].
pub fn normalize_angle(a: Real) -> Real {
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut r = a % two_pi;
    if r <= -std::f64::consts::PI {
        r += two_pi;
    } else if r > std::f64::consts::PI {
        r -= two_pi;
    }
    r
}

/// Where the ray from `origin` along `dir` meets the line through `a` and
/// `b`: (distance along the ray in units of `dir`, position along a→b with
/// 0 at `a` and 1 at `b`); `None` when they are parallel. The one
/// intersection behind laser casting, observable scenes and depth
/// rendering.
#[inline]
pub fn ray_line(
    origin: (Real, Real),
    dir: (Real, Real),
    a: (Real, Real),
    b: (Real, Real),
) -> Option<(Real, Real)> {
    let (ex, ey) = (b.0 - a.0, b.1 - a.1);
    let denom = dir.0 * ey - dir.1 * ex;
    if denom.abs() < 1e-12 {
        return None;
    }
    let (ox, oy) = (a.0 - origin.0, a.1 - origin.1);
    Some(((ox * ey - oy * ex) / denom, (ox * dir.1 - oy * dir.0) / denom))
}

/// A pose in the plane: position (m) and heading (rad, in (-π, π]).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    /// x, metres.
    pub x: Real,
    /// y, metres.
    pub y: Real,
    /// Heading, radians, in (-π, π].
    pub theta: Real,
}

impl Pose2 {
    /// A pose; the heading is normalized.
    pub fn new(x: Real, y: Real, theta: Real) -> Self {
        Pose2 { x, y, theta: normalize_angle(theta) }
    }

    /// The identity motion.
    pub const IDENTITY: Pose2 = Pose2 { x: 0.0, y: 0.0, theta: 0.0 };

    /// `self ⊕ other`: `other` expressed in `self`'s frame, composed.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            self.theta + other.theta,
        )
    }

    /// The inverse motion: `p.inverse().compose(&p)` is the identity.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(-c * self.x - s * self.y, s * self.x - c * self.y, -self.theta)
    }

    /// `self ⊖ from`: the motion from `from` to `self`, in `from`'s frame.
    pub fn relative_to(&self, from: &Pose2) -> Pose2 {
        from.inverse().compose(self)
    }

    /// Distance between the positions, metres.
    pub fn distance(&self, other: &Pose2) -> Real {
        (self.x - other.x).hypot(self.y - other.y)
    }
}

/// Calls `visit` for each cell on the line from `a` to `b`, both included
/// (Bresenham), in order from `a`.
#[inline]
pub fn line_cells(a: (i64, i64), b: (i64, i64), mut visit: impl FnMut((i64, i64))) {
    let mut line = LineStepper::new(a, b);
    visit(a);
    while !line.done() {
        visit(line.step());
    }
}

/// Bresenham's line from cell `a` to cell `b`, walked a cell at a time by
/// the caller (for walks that act on runs of cells, such as a beam's cells
/// tile by tile).
#[derive(Debug, Clone)]
pub struct LineStepper {
    at: (i64, i64),
    end: (i64, i64),
    d: (i64, i64),
    s: (i64, i64),
    err: i64,
}

impl LineStepper {
    /// A walk that stands at `a`.
    #[inline]
    pub fn new(a: (i64, i64), b: (i64, i64)) -> Self {
        let d = ((b.0 - a.0).abs(), -(b.1 - a.1).abs());
        let s = (if a.0 < b.0 { 1 } else { -1 }, if a.1 < b.1 { 1 } else { -1 });
        LineStepper { at: a, end: b, d, s, err: d.0 + d.1 }
    }

    /// Whether the walk stands at `b`.
    #[inline]
    pub fn done(&self) -> bool {
        self.at == self.end
    }

    /// Moves to the next cell and returns it (call only while not
    /// [`done`](Self::done)).
    #[inline]
    pub fn step(&mut self) -> (i64, i64) {
        let e2 = 2 * self.err;
        if e2 >= self.d.1 {
            self.err += self.d.1;
            self.at.0 += self.s.0;
        }
        if e2 <= self.d.0 {
            self.err += self.d.0;
            self.at.1 += self.s.1;
        }
        self.at
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn close(a: &Pose2, b: &Pose2) -> bool {
        (a.x - b.x).abs() < 1e-12
            && (a.y - b.y).abs() < 1e-12
            && normalize_angle(a.theta - b.theta).abs() < 1e-12
    }

    #[test]
    fn angles_wrap_into_the_half_open_interval() {
        assert_eq!(normalize_angle(PI), PI);
        assert!((normalize_angle(-PI) - PI).abs() < 1e-15);
        assert!((normalize_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((normalize_angle(2.5 * PI) - 0.5 * PI).abs() < 1e-12);
        assert!((normalize_angle(-0.5 * PI) + 0.5 * PI).abs() < 1e-15);
    }

    #[test]
    fn compose_moves_in_the_local_frame() {
        let facing_up = Pose2::new(1.0, 2.0, PI / 2.0);
        let forward = Pose2::new(1.0, 0.0, 0.0);
        assert!(close(&facing_up.compose(&forward), &Pose2::new(1.0, 3.0, PI / 2.0)));
    }

    #[test]
    fn inverse_and_relative_round_trip() {
        let a = Pose2::new(3.0, -1.0, 2.5);
        let b = Pose2::new(-0.5, 4.0, -2.9);
        assert!(close(&a.inverse().compose(&a), &Pose2::IDENTITY));
        assert!(close(&a.compose(&b.relative_to(&a)), &b));
    }

    #[test]
    fn lines_include_both_ends_and_stay_on_the_line() {
        for (a, b) in
            [((0, 0), (4, 2)), ((4, 2), (0, 0)), ((-3, 5), (7, -1)), ((2, 2), (2, -6)), ((3, 3), (3, 3))]
        {
            let mut cells: Vec<(i64, i64)> = Vec::new();
            line_cells(a, b, |c| cells.push(c));
            assert_eq!((cells[0], cells[cells.len() - 1]), (a, b));
            let (dx, dy) = ((b.0 - a.0) as f64, (b.1 - a.1) as f64);
            assert_eq!(cells.len() as f64, dx.abs().max(dy.abs()) + 1.0, "{a:?}→{b:?}");
            let length = dx.hypot(dy).max(1e-9);
            for w in cells.windows(2) {
                assert!(
                    (w[1].0 - w[0].0).abs() <= 1 && (w[1].1 - w[0].1).abs() <= 1,
                    "steps are to neighbours"
                );
            }
            for c in &cells {
                // Distance of the cell from the ideal line, in cells.
                let d = ((c.0 - a.0) as f64 * dy - (c.1 - a.1) as f64 * dx).abs() / length;
                assert!(d <= 0.5 + 1e-9 || length < 1e-6, "{c:?} is {d} off {a:?}→{b:?}");
            }
        }
    }
}
