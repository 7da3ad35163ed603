//! A 2-D world of wall segments: loaded from a line-map file or generated,
//! and ray cast by the simulated laser.

use std::path::Path;

use squall_bolts::geometry::Real;

/// A wall from `a` to `b`, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// One end.
    pub a: (Real, Real),
    /// The other end.
    pub b: (Real, Real),
}

/// A problem in a line-map file.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("{path}:{line}: {message}")]
    Bad {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// What was expected.
        message: String,
    },
    /// The file holds no wall.
    #[error("{0}: the map has no wall segments")]
    Empty(String),
}

/// The walls of a world.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct World {
    /// Every wall; zero-length segments are kept (they never hit a ray).
    pub walls: Vec<Segment>,
}

impl World {
    /// Parses a line map: one wall per line, `x1,y1,x2,y2` (commas and/or
    /// spaces), metres; `#` comments and blank lines ignored.
    pub fn parse_linemap(path: &str, text: &str) -> Result<World, WorldError> {
        let mut walls = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let bad = |message: String| WorldError::Bad { path: path.to_string(), line: i + 1, message };
            let v: Vec<Real> = line
                .split(|c: char| c == ',' || c.is_ascii_whitespace())
                .filter(|f| !f.is_empty())
                .map(|f| match f.parse::<Real>() {
                    Ok(v) if v.is_finite() => Ok(v),
                    _ => Err(bad(format!("expected a number, found \"{f}\""))),
                })
                .collect::<Result<_, _>>()?;
            if v.len() != 4 {
                return Err(bad(format!("expected 4 numbers x1,y1,x2,y2, found {}", v.len())));
            }
            walls.push(Segment { a: (v[0], v[1]), b: (v[2], v[3]) });
        }
        if walls.is_empty() {
            return Err(WorldError::Empty(path.to_string()));
        }
        Ok(World { walls })
    }

    /// Reads a line-map file.
    pub fn load_linemap(path: &Path) -> Result<World, WorldError> {
        let name = path.display().to_string();
        let text =
            std::fs::read_to_string(path).map_err(|source| WorldError::Io { path: name.clone(), source })?;
        Self::parse_linemap(&name, &text)
    }

    /// Distance (m) along the ray from `origin` in direction `angle` to the
    /// nearest wall, if one is within `max_range`.
    pub fn cast(&self, origin: (Real, Real), angle: Real, max_range: Real) -> Option<Real> {
        let (dx, dy) = (angle.cos(), angle.sin());
        let mut best = max_range;
        let mut hit = false;
        for w in &self.walls {
            let (ex, ey) = (w.b.0 - w.a.0, w.b.1 - w.a.1);
            let denom = dx * ey - dy * ex;
            if denom.abs() < 1e-12 {
                continue;
            }
            let (ox, oy) = (w.a.0 - origin.0, w.a.1 - origin.1);
            let t = (ox * ey - oy * ex) / denom;
            let u = (ox * dy - oy * dx) / denom;
            if t > 1e-9 && t < best && (0.0..=1.0).contains(&u) {
                best = t;
                hit = true;
            }
        }
        hit.then_some(best)
    }

    /// Whether the straight path from `a` to `b` crosses no wall.
    pub fn clear(&self, a: (Real, Real), b: (Real, Real)) -> bool {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let length = dx.hypot(dy);
        length == 0.0 || self.cast(a, dy.atan2(dx), length).is_none()
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

    fn square() -> World {
        World::parse_linemap("sq", "0,0,4,0\n4,0 4,4\n4 4 0 4\n0,4,0,0\n1,1,1,1\n").unwrap()
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
    fn malformed_lines_name_file_and_line() {
        let e = World::parse_linemap("m.txt", "0,0,1,1\n0,0,1\n").unwrap_err();
        assert_eq!(e.to_string(), "m.txt:2: expected 4 numbers x1,y1,x2,y2, found 3");
        let e = World::parse_linemap("m.txt", "0,0,x,1\n").unwrap_err();
        assert_eq!(e.to_string(), "m.txt:1: expected a number, found \"x\"");
        assert!(matches!(World::parse_linemap("m.txt", "# nothing\n"), Err(WorldError::Empty(_))));
    }
}
