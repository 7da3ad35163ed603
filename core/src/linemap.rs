//! Line maps: a building as wall segments, loaded from a file or generated,
//! and ray cast (by the simulated laser, and by localization's observable
//! scenes).

use std::path::Path;

use crate::geometry::{Real, ray_line};
use crate::textfile::{self, TextFileError};

/// A wall from `a` to `b`, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// One end.
    pub a: (Real, Real),
    /// The other end.
    pub b: (Real, Real),
}

/// The walls of a building.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LineMap {
    /// Every wall; zero-length segments are kept (they never hit a ray).
    pub walls: Vec<Segment>,
}

impl LineMap {
    /// Parses a line map: one wall per line, `x1,y1,x2,y2` (commas and/or
    /// spaces), metres; `#` comments and blank lines ignored.
    pub fn parse(path: &str, text: &str) -> Result<LineMap, TextFileError> {
        let walls: Vec<Segment> = textfile::numeric_lines(path, text, 4, "x1,y1,x2,y2", true)?
            .into_iter()
            .map(|(_, v)| Segment { a: (v[0], v[1]), b: (v[2], v[3]) })
            .collect();
        if walls.is_empty() {
            return Err(TextFileError::Bad {
                path: path.to_string(),
                line: 0,
                message: "the map has no wall segments".into(),
            });
        }
        Ok(LineMap { walls })
    }

    /// Reads a line-map file.
    pub fn load(path: &Path) -> Result<LineMap, TextFileError> {
        let (name, text) = textfile::read(path)?;
        Self::parse(&name, &text)
    }

    /// Distance (m) along the ray from `origin` in direction `angle` to the
    /// nearest wall, if one is within `max_range`.
    pub fn cast(&self, origin: (Real, Real), angle: Real, max_range: Real) -> Option<Real> {
        let (dx, dy) = (angle.cos(), angle.sin());
        let mut best = max_range;
        let mut hit = false;
        for w in &self.walls {
            let Some((t, u)) = ray_line(origin, (dx, dy), w.a, w.b) else { continue };
            if t > 1e-9 && t < best && (0.0..=1.0).contains(&u) {
                best = t;
                hit = true;
            }
        }
        hit.then_some(best)
    }

    /// Whether the ray from `origin` in direction `angle` meets a wall
    /// within `max_range`: `cast(..).is_some()`, stopping at the first wall
    /// met rather than looking for the nearest.
    pub fn blocked(&self, origin: (Real, Real), angle: Real, max_range: Real) -> bool {
        let dir = (angle.cos(), angle.sin());
        self.walls.iter().any(|w| {
            ray_line(origin, dir, w.a, w.b)
                .is_some_and(|(t, u)| t > 1e-9 && t < max_range && (0.0..=1.0).contains(&u))
        })
    }

    /// Whether the straight path from `a` to `b` crosses no wall.
    pub fn clear(&self, a: (Real, Real), b: (Real, Real)) -> bool {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let length = dx.hypot(dy);
        length == 0.0 || !self.blocked(a, dy.atan2(dx), length)
    }

    /// Bounding box (min x, min y, max x, max y).
    pub fn bounds(&self) -> (Real, Real, Real, Real) {
        self.walls.iter().fold((Real::MAX, Real::MAX, Real::MIN, Real::MIN), |(a, b, c, d), w| {
            (
                a.min(w.a.0).min(w.b.0),
                b.min(w.a.1).min(w.b.1),
                c.max(w.a.0).max(w.b.0),
                d.max(w.a.1).max(w.b.1),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> LineMap {
        LineMap::parse("sq", "0,0,4,0\n4,0 4,4\n4 4 0 4\n0,4,0,0\n1,1,1,1\n").unwrap()
    }

    #[test]
    fn rays_hit_the_nearest_wall() {
        let w = square();
        assert_eq!(w.walls.len(), 5, "zero-length segments are kept");
        let d = w.cast((1.0, 2.0), 0.0, 10.0).unwrap();
        assert!((d - 3.0).abs() < 1e-12);
        let d = w.cast((1.0, 2.0), std::f64::consts::PI, 10.0).unwrap();
        assert!((d - 1.0).abs() < 1e-12);
        let diag = w.cast((2.0, 2.0), std::f64::consts::FRAC_PI_4, 10.0).unwrap();
        assert!((diag - 2.0 * 2f64.sqrt()).abs() < 1e-9);
        assert_eq!(w.cast((2.0, 2.0), 0.0, 1.5), None, "beyond max range");
        assert!(w.clear((1.0, 1.5), (3.0, 3.0)));
        assert!(!w.clear((1.0, 1.0), (5.0, 1.0)));
    }

    #[test]
    fn a_ray_is_blocked_exactly_when_a_cast_hits() {
        let w = square();
        for i in 0..40 {
            for k in 0..24 {
                let origin = (-1.0 + 0.15 * i as Real, 0.5 + 0.1 * i as Real);
                let angle = k as Real * std::f64::consts::PI / 12.0;
                for reach in [0.5, 2.0, 10.0] {
                    let cast = w.cast(origin, angle, reach).is_some();
                    assert_eq!(w.blocked(origin, angle, reach), cast, "{origin:?} {angle} {reach}");
                }
            }
        }
    }

    #[test]
    fn malformed_lines_name_file_and_line() {
        let e = LineMap::parse("m.txt", "0,0,1,1\n0,0,1\n").unwrap_err();
        assert_eq!(e.to_string(), "m.txt:2: expected 4 fields (x1,y1,x2,y2), found 3");
        let e = LineMap::parse("m.txt", "0,0,x,1\n").unwrap_err();
        assert_eq!(e.to_string(), "m.txt:1: expected a number, found \"x\"");
        assert!(LineMap::parse("m.txt", "# nothing\n").unwrap_err().to_string().contains("no wall segments"));
    }
}
