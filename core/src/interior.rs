//! A building's inside, derived from its line map: where a robot on the
//! map can be.
//!
//! A line map draws walls, not rooms, and its outline has gaps: doors to
//! the outside, and breaks where the drawing's segments do not meet. The
//! inside is found by a morphological closing of the outside: the free
//! space more than half an `opening` from every wall is flooded from the
//! map's border (so no gap narrower than `opening` lets the flood in), and
//! the flooded region is then grown back by the same half opening, up to
//! the walls. What the grown flood does not reach is inside, less enclosed
//! regions no robot fits in (a pillar drawn as an outline). Gaps narrower
//! than `opening` are closed; wider ones count as open to the outside.
//!
//! A localizer's pose prior given the map is zero where the robot cannot
//! be (Thrun, Burgard and Fox, *Probabilistic Robotics*, ch. 8: the map
//! prior of Monte Carlo localization): outside the building's outer walls,
//! or within a wall drawn with a thickness.

use rand::RngExt;

use crate::geometry::Real;
use crate::linemap::LineMap;

/// Metres per cell of the inside's grid, for a building up to
/// [`MAX_CELLS`] of them; larger maps get larger cells.
pub const RESOLUTION: Real = 0.1;

/// Cells of the inside's grid at most (the simulated campus, 70 400 m²
/// at 0.1 m, fits): while it is built a cell takes two 8-byte distances
/// and a few flags, after it one flag.
pub const MAX_CELLS: usize = 8 << 20;

/// The default widest gap in a building's outline that is closed, metres:
/// doors and breaks in the drawing are narrower; a region joined to the
/// outside by an opening wider than this counts as outside. The real
/// building maps of `../shared/data/linemaps` need more than 1.5 m
/// (GHC7's outline has gaps that wide); a wider closing errs on the safe side, since a
/// part of the building taken for the outside would lose a robot there,
/// while a bit of the outside taken for the inside (a concave outer corner
/// the grown flood cannot fill) only keeps today's freedom there.
pub const DEFAULT_OPENING: Real = 3.0;

/// The least distance from every wall, metres, that some point of an
/// enclosed region must have to be a place: regions narrower than 0.9 m
/// (a pillar or a duct drawn as an outline, a wall drawn as two lines)
/// are not rooms a robot drives into.
pub const CLEARANCE: Real = 0.45;

/// How close to a place a pose still counts as one, metres: a drawn line
/// has no thickness, and the simulated robot cuts a door's corner by more
/// than a decimetre (through a wall drawn 0.12 m thick on CVAP6).
pub const TOLERANCE: Real = 0.25;

/// (1 − 1/√2): the farthest a point of a right-angled corner left by the
/// closing lies from its walls, as a share of the closing's radius.
const CORNER_SHARE: Real = 0.2929;

/// Where a robot can be on a line map: the cells inside the building, less
/// enclosed regions too small to hold a robot, on a grid of [`RESOLUTION`] (or coarser, for a very large
/// map) over the map's bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct Interior {
    /// World position of cell (0, 0)'s corner.
    origin: (Real, Real),
    /// Metres per cell.
    resolution: Real,
    width: usize,
    height: usize,
    /// Row-major: cell (x, y) is inside.
    inside: Vec<bool>,
    /// Cells inside, off the walls.
    count: usize,
}

impl Interior {
    /// The inside of `map`, closing gaps narrower than `opening` metres;
    /// an error unless `opening` is a finite number of metres ≥ 0.
    pub fn of(map: &LineMap, opening: Real) -> crate::Result<Interior> {
        if !(opening.is_finite() && opening >= 0.0) {
            return Err(crate::Error::Interior(format!(
                "the opening must be a finite number of metres ≥ 0, got {opening}"
            )));
        }
        let (x0, y0, x1, y1) = map.bounds();
        let finite = [x0, y0, x1, y1, opening].iter().all(|v| v.is_finite());
        if map.walls.is_empty() || !finite {
            return Err(crate::Error::Interior("the map has no walls to find an inside in".into()));
        }
        // A border of free cells around the walls, wider than the half
        // opening, from which the flood starts; cells coarser than
        // RESOLUTION where the grid would exceed MAX_CELLS.
        let spans = (x1 - x0 + opening + 1.0, y1 - y0 + opening + 1.0);
        let resolution = RESOLUTION.max((spans.0 * spans.1 / MAX_CELLS as Real).sqrt() * 1.01);
        let half = 0.5 * opening / resolution;
        let margin = half.ceil() + 2.0;
        let origin = (x0 - margin * resolution, y0 - margin * resolution);
        let cells = |extent: Real| (extent / resolution + 2.0 * margin).ceil() as usize + 1;
        let (width, height) = (cells(x1 - x0), cells(y1 - y0));
        if width.saturating_mul(height) > MAX_CELLS {
            return Err(crate::Error::Interior(format!(
                "a grid of {width} × {height} cells for a map of {:.0} × {:.0} m is too large",
                x1 - x0,
                y1 - y0
            )));
        }
        let wall = rasterize(map, origin, resolution, width, height);
        let near_wall = squared_distances(&wall, width, height);
        // The flood: from the border, through cells farther than the half
        // opening from every wall.
        let mut flooded = vec![false; width * height];
        let border = (0..width)
            .flat_map(|x| [x, (height - 1) * width + x])
            .chain((0..height).flat_map(|y| [y * width, y * width + width - 1]));
        let passable = |i: usize| near_wall[i] > half * half;
        fill(border, passable, &mut flooded, width, height, |_| {});
        // Grown back by the half opening: up to the walls, never across
        // one (a cell beyond a wall is farther than that from the flood).
        let near_flood = squared_distances(&flooded, width, height);
        let enclosed: Vec<bool> = near_flood.iter().map(|&d| d > half * half).collect();
        drop(near_flood);
        // Enclosed regions no robot fits in (a pillar drawn as a closed
        // outline, a wall drawn as two lines) are not places, nor are the
        // corners of the outside the grown flood cannot fill: a disc of
        // radius r rolled into a right-angled corner leaves no point
        // farther than (1 − 1/√2)·r from the walls (on the grid, r is up to
        // a cell more than the half opening, and a cell is added for the
        // cells' own size).
        let clearance = (CLEARANCE / resolution).max(CORNER_SHARE * (half + 1.0) + 1.0);
        let roomy = regions_holding(&enclosed, &wall, &near_wall, clearance * clearance, width, height);
        // Widened by a tolerance: a pose that close to a place is one.
        let count = roomy.iter().filter(|&&c| c).count();
        let near_roomy = squared_distances(&roomy, width, height);
        let reach = TOLERANCE / resolution;
        let inside: Vec<bool> = near_roomy.iter().map(|&d| d <= reach * reach).collect();
        Ok(Interior { origin, resolution, width, height, inside, count })
    }

    /// Whether a robot can be at (`x`, `y`): inside the building, not on a
    /// wall.
    pub fn contains(&self, x: Real, y: Real) -> bool {
        self.cell(x, y).is_some_and(|i| self.inside[i])
    }

    /// The area inside, off the walls, square metres.
    pub fn area(&self) -> Real {
        self.count as Real * self.resolution * self.resolution
    }

    /// Whether nothing is inside: a map whose walls enclose no region
    /// wider than the opening (an open site), where the inside says
    /// nothing.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// A position drawn uniformly over the inside (within its cell), or
    /// `None` if nothing is inside.
    pub fn sample(&self, rng: &mut impl rand::Rng) -> Option<(Real, Real)> {
        if self.count == 0 {
            return None;
        }
        // Rejection over the grid: the inside is a fair share of its
        // bounding box for a building, so few draws miss; a thin inside
        // falls back to counting cells.
        for _ in 0..64 {
            let i = rng.random_range(0..self.inside.len());
            if self.inside[i] {
                return Some(self.point_in(i, rng));
            }
        }
        let k = rng.random_range(0..self.count);
        let i = self.inside.iter().enumerate().filter(|(_, c)| **c).nth(k).map(|(i, _)| i)?;
        Some(self.point_in(i, rng))
    }

    fn point_in(&self, i: usize, rng: &mut impl rand::Rng) -> (Real, Real) {
        let (x, y) = ((i % self.width) as Real, (i / self.width) as Real);
        (
            self.origin.0 + (x + rng.random::<Real>()) * self.resolution,
            self.origin.1 + (y + rng.random::<Real>()) * self.resolution,
        )
    }

    /// The index of the cell holding (`x`, `y`), if on the grid.
    fn cell(&self, x: Real, y: Real) -> Option<usize> {
        let (fx, fy) = ((x - self.origin.0) / self.resolution, (y - self.origin.1) / self.resolution);
        let on = fx >= 0.0 && fy >= 0.0 && fx < self.width as Real && fy < self.height as Real;
        on.then(|| fy as usize * self.width + fx as usize)
    }
}

/// Of the `enclosed` cells off the walls, those whose 4-connected region
/// holds a cell farther than √`clearance²` cells from every wall
/// (`near_wall`: squared distances).
fn regions_holding(
    enclosed: &[bool],
    wall: &[bool],
    near_wall: &[Real],
    clearance_squared: Real,
    width: usize,
    height: usize,
) -> Vec<bool> {
    let open = |i: usize| enclosed[i] && !wall[i];
    let mut reached = vec![false; width * height];
    let mut keep = vec![false; width * height];
    let mut members = Vec::new();
    for start in 0..width * height {
        if reached[start] || !open(start) {
            continue;
        }
        // One region, walked from `start`.
        members.clear();
        let mut roomy = false;
        fill([start], open, &mut reached, width, height, |i| {
            members.push(i);
            roomy |= near_wall[i] >= clearance_squared;
        });
        if roomy {
            members.iter().for_each(|&i| keep[i] = true);
        }
    }
    keep
}

/// The 4-connected fill of a `width` × `height` grid from `seeds` through
/// the cells `open` admits and `reached` does not hold yet: marks each in
/// `reached` and hands it to `each`. A cell is marked as it is found, so
/// the stack never holds more cells than the grid.
fn fill(
    seeds: impl IntoIterator<Item = usize>,
    open: impl Fn(usize) -> bool,
    reached: &mut [bool],
    width: usize,
    height: usize,
    mut each: impl FnMut(usize),
) {
    let mut stack = Vec::new();
    for seed in seeds {
        if !reached[seed] && open(seed) {
            reached[seed] = true;
            stack.push(seed);
        }
    }
    while let Some(i) = stack.pop() {
        each(i);
        let (x, y) = (i % width, i / width);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < width).then(|| i + 1),
            (y > 0).then(|| i - width),
            (y + 1 < height).then(|| i + width),
        ];
        for n in neighbours.into_iter().flatten() {
            if !reached[n] && open(n) {
                reached[n] = true;
                stack.push(n);
            }
        }
    }
}

/// The cells the map's walls pass through (each wall sampled every half
/// cell, so no cell it crosses is skipped by more than a corner).
fn rasterize(
    map: &LineMap,
    origin: (Real, Real),
    resolution: Real,
    width: usize,
    height: usize,
) -> Vec<bool> {
    let mut wall = vec![false; width * height];
    for w in &map.walls {
        let (dx, dy) = (w.b.0 - w.a.0, w.b.1 - w.a.1);
        let steps = (dx.abs().max(dy.abs()) / (0.5 * resolution)).ceil() as usize + 1;
        for k in 0..=steps {
            let t = k as Real / steps as Real;
            let (x, y) = ((w.a.0 + t * dx - origin.0) / resolution, (w.a.1 + t * dy - origin.1) / resolution);
            if x >= 0.0 && y >= 0.0 && (x as usize) < width && (y as usize) < height {
                wall[y as usize * width + x as usize] = true;
            }
        }
    }
    wall
}

/// For every cell, the squared distance in cells to the nearest cell set
/// in `mask` (infinite if none): the exact Euclidean distance transform of
/// Felzenszwalb and Huttenlocher ("Distance transforms of sampled
/// functions", 2012), a 1-D pass along rows, then along columns.
fn squared_distances(mask: &[bool], width: usize, height: usize) -> Vec<Real> {
    let mut d: Vec<Real> = mask.iter().map(|&m| if m { 0.0 } else { Real::INFINITY }).collect();
    let mut scratch = Scratch::new(width.max(height));
    for y in 0..height {
        scratch.transform(&mut d[y * width..(y + 1) * width]);
    }
    let mut column = vec![0.0; height];
    for x in 0..width {
        for y in 0..height {
            column[y] = d[y * width + x];
        }
        scratch.transform(&mut column);
        for y in 0..height {
            d[y * width + x] = column[y];
        }
    }
    d
}

/// The 1-D transform's working memory: the lower envelope's parabolas.
struct Scratch {
    /// Vertex of each parabola of the envelope.
    vertex: Vec<usize>,
    /// Where each parabola starts being the lowest.
    from: Vec<Real>,
    out: Vec<Real>,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Scratch { vertex: vec![0; n], from: vec![0.0; n + 1], out: vec![0.0; n] }
    }

    /// f(q) ← min over p of (q − p)² + f(p), in place.
    fn transform(&mut self, f: &mut [Real]) {
        let Some(first) = f.iter().position(|v| v.is_finite()) else { return };
        let n = f.len();
        let (vertex, from) = (&mut self.vertex, &mut self.from);
        let mut k = 0;
        vertex[0] = first;
        from[0] = Real::NEG_INFINITY;
        from[1] = Real::INFINITY;
        let meet = |q: usize, p: usize, f: &[Real]| {
            let (q, p) = (q as Real, p as Real);
            ((f[q as usize] + q * q) - (f[p as usize] + p * p)) / (2.0 * (q - p))
        };
        for q in first + 1..n {
            if !f[q].is_finite() {
                continue;
            }
            let mut s = meet(q, vertex[k], f);
            while s <= from[k] {
                k -= 1;
                s = meet(q, vertex[k], f);
            }
            k += 1;
            vertex[k] = q;
            from[k] = s;
            from[k + 1] = Real::INFINITY;
        }
        k = 0;
        for q in 0..n {
            while from[k + 1] < q as Real {
                k += 1;
            }
            let p = vertex[k];
            self.out[q] = (q as Real - p as Real).powi(2) + f[p];
        }
        f.copy_from_slice(&self.out[..n]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linemap::Segment;
    use rand::SeedableRng;

    /// A 10 × 6 m room from (0, 0), with a door of `door` metres in its
    /// south wall at x = 4.
    fn room(door: Real) -> LineMap {
        let s = |a: (Real, Real), b: (Real, Real)| Segment { a, b };
        LineMap {
            walls: vec![
                s((0.0, 0.0), (4.0, 0.0)),
                s((4.0 + door, 0.0), (10.0, 0.0)),
                s((10.0, 0.0), (10.0, 6.0)),
                s((10.0, 6.0), (0.0, 6.0)),
                s((0.0, 6.0), (0.0, 0.0)),
            ],
        }
    }

    #[test]
    fn a_room_with_a_door_is_inside_and_the_world_around_it_is_not() {
        let inside = Interior::of(&room(1.0), DEFAULT_OPENING).unwrap();
        for (x, y) in [(5.0, 3.0), (0.3, 0.3), (9.7, 5.7), (4.5, 0.2)] {
            assert!(inside.contains(x, y), "({x}, {y}) is in the room");
        }
        for (x, y) in [(5.0, -0.5), (-0.4, 3.0), (10.4, 3.0), (5.0, 6.4), (40.0, 3.0), (4.5, -0.4)] {
            assert!(!inside.contains(x, y), "({x}, {y}) is outside");
        }
        // The outline is inside (a drawn line has no thickness); the area is
        // the room's 60 m², less the cells the walls cross.
        assert!(inside.contains(10.0, 3.0) && inside.contains(2.0, 0.0));
        assert!((55.0..60.0).contains(&inside.area()), "{}", inside.area());
    }

    #[test]
    fn an_opening_wider_than_the_closing_lets_the_outside_in() {
        let inside = Interior::of(&room(5.0), 3.0).unwrap();
        // Not even the corners the grown flood cannot reach stay: no robot
        // place is that close to its walls everywhere.
        assert!(inside.is_empty() && !inside.contains(0.1, 5.9) && !inside.contains(0.0, 3.0));
        assert!(!inside.contains(5.0, 3.0), "an empty inside holds nothing");
        // A wider closing shuts it again.
        assert!(Interior::of(&room(5.0), 6.0).unwrap().contains(5.0, 3.0));
        // Without closing, only a sealed outline has an inside.
        assert!(Interior::of(&room(0.0), 0.0).unwrap().contains(5.0, 3.0));
        assert!(Interior::of(&room(1.0), 0.0).unwrap().is_empty());
    }

    #[test]
    fn a_pillar_or_a_thick_wall_is_not_a_place() {
        let s = |a: (Real, Real), b: (Real, Real)| Segment { a, b };
        let square = |x: Real, y: Real, side: Real| {
            [
                s((x, y), (x + side, y)),
                s((x + side, y), (x + side, y + side)),
                s((x + side, y + side), (x, y + side)),
                s((x, y + side), (x, y)),
            ]
        };
        let mut map = room(1.0);
        // A 0.8 m pillar, and a 1.2 m box a robot could stand in.
        map.walls.extend(square(3.0, 3.0, 0.8));
        map.walls.extend(square(6.0, 2.0, 1.2));
        // The north wall drawn thick: a second line 0.8 m above it, closed.
        map.walls.extend([
            s((0.0, 6.8), (10.0, 6.8)),
            s((0.0, 6.0), (0.0, 6.8)),
            s((10.0, 6.0), (10.0, 6.8)),
        ]);
        let inside = Interior::of(&map, 1.0).unwrap();
        assert!(!inside.contains(3.4, 3.4), "within the pillar");
        assert!(!inside.contains(5.0, 6.4), "within the thick wall");
        // A pose brushing the pillar or the wall still counts.
        assert!(inside.contains(3.1, 3.4) && inside.contains(5.0, 6.1));
        assert!(inside.contains(6.6, 2.6), "a box a robot fits in is a place");
        assert!(inside.contains(2.5, 2.5) && inside.contains(5.0, 5.8), "the room around them");
    }

    #[test]
    fn draws_land_inside_and_cover_it() {
        let inside = Interior::of(&room(1.0), DEFAULT_OPENING).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let draws: Vec<(Real, Real)> = (0..2000).map(|_| inside.sample(&mut rng).unwrap()).collect();
        assert!(draws.iter().all(|&(x, y)| inside.contains(x, y)));
        let west = draws.iter().filter(|p| p.0 < 5.0).count();
        assert!((900..1100).contains(&west), "uniform over the room: {west} of 2000 in its west half");
        let empty = Interior::of(&room(1.0), 0.0).unwrap();
        assert!(empty.is_empty());
        assert_eq!(empty.sample(&mut rng), None);
    }

    #[test]
    fn the_distance_transform_is_exact() {
        let (w, h) = (7, 5);
        let mut mask = vec![false; w * h];
        for &(x, y) in &[(1, 1), (5, 3)] {
            mask[y * w + x] = true;
        }
        let d = squared_distances(&mask, w, h);
        for y in 0..h {
            for x in 0..w {
                let brute = [(1i64, 1i64), (5, 3)]
                    .iter()
                    .map(|&(px, py)| ((x as i64 - px).pow(2) + (y as i64 - py).pow(2)) as Real)
                    .fold(Real::INFINITY, Real::min);
                assert_eq!(d[y * w + x], brute, "({x}, {y})");
            }
        }
        assert!(squared_distances(&[false; 6], 3, 2).iter().all(|v| v.is_infinite()));
    }

    #[test]
    fn a_bad_opening_is_an_error() {
        for bad in [-1.0, Real::NAN, Real::INFINITY] {
            let e = Interior::of(&room(1.0), bad).unwrap_err().to_string();
            assert!(e.contains("opening must be a finite number"), "{bad}: {e}");
        }
        assert!(Interior::of(&LineMap::default(), 1.0).is_err(), "no walls");
    }

    #[test]
    fn a_huge_map_gets_coarser_cells_not_an_exhausted_memory() {
        // Two rooms 100 km apart: at 0.1 m that would be 10¹² cells.
        let mut map = room(1.0);
        let far = room(1.0)
            .walls
            .into_iter()
            .map(|w| Segment { a: (w.a.0 + 1e5, w.a.1 + 1e5), b: (w.b.0 + 1e5, w.b.1 + 1e5) });
        map.walls.extend(far);
        let inside = Interior::of(&map, DEFAULT_OPENING).unwrap();
        assert!(inside.width * inside.height <= MAX_CELLS);
        assert!(!inside.contains(-5e4, -5e4) && !inside.contains(5e4, 5e4));
    }
}
