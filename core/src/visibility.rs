//! Observable scenes: the parts of a line map's walls visible from a
//! position (thesis Alg. 4.3). Each wall is trimmed by the walls already
//! accepted and trims them in turn; a trim removes the part of a wall that
//! another wall hides from the viewer — nothing (the other is behind),
//! everything (it is in front over the whole wall), one end, or the middle,
//! which splits the wall in two (the four cases of the thesis's Fig. 4.2).

use crate::geometry::{Real, normalize_angle, ray_line};
use crate::linemap::LineMap;

/// Pieces shorter than this (metres) are dropped.
const MIN_PIECE: Real = 1e-6;

/// A visible piece of map wall `line`, from `a` to `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Visible {
    /// Index of the wall in the map.
    pub line: u32,
    /// One end of the piece.
    pub a: (Real, Real),
    /// The other end.
    pub b: (Real, Real),
}

impl Visible {
    fn length(&self) -> Real {
        (self.b.0 - self.a.0).hypot(self.b.1 - self.a.1)
    }
}

/// Distance from `p` to the segment `a`–`b`.
pub fn distance_to_segment(p: (Real, Real), a: (Real, Real), b: (Real, Real)) -> Real {
    let (ex, ey) = (b.0 - a.0, b.1 - a.1);
    let len2 = ex * ex + ey * ey;
    let t = if len2 > 0.0 { (((p.0 - a.0) * ex + (p.1 - a.1) * ey) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p.0 - a.0 - t * ex).hypot(p.1 - a.1 - t * ey)
}

/// Where the ray from `x` at angle `phi` meets the line through `a` and
/// `b`: (distance along the ray, parameter along a→b), if it does ahead.
fn ray_at(x: (Real, Real), phi: Real, a: (Real, Real), b: (Real, Real)) -> Option<(Real, Real)> {
    ray_line(x, (phi.cos(), phi.sin()), a, b).filter(|&(r, _)| r > 0.0)
}

/// The angle of `p` seen from `x`.
fn bearing(x: (Real, Real), p: (Real, Real)) -> Real {
    (p.1 - x.1).atan2(p.0 - x.0)
}

/// `piece` ordered so that it runs counter-clockwise seen from `x`, with
/// its start bearing and angular width (0..π).
fn oriented(x: (Real, Real), piece: Visible) -> (Visible, Real, Real) {
    let (alpha, beta) = (bearing(x, piece.a), bearing(x, piece.b));
    let width = normalize_angle(beta - alpha);
    if width < 0.0 {
        (Visible { a: piece.b, b: piece.a, ..piece }, beta, -width)
    } else {
        (piece, alpha, width)
    }
}

/// `l1` without what `l2` hides from `x`: zero, one or two pieces.
pub fn trim_occlusion(x: (Real, Real), l1: Visible, l2: &Visible) -> Vec<Visible> {
    if l1.length() < MIN_PIECE || l2.length() < MIN_PIECE {
        return vec![l1];
    }
    let original = l1;
    let (l1, alpha, width) = oriented(x, l1);
    let (_, gamma, width2) = oriented(x, *l2);
    if width < 1e-12 || width2 < 1e-12 {
        // Seen edge-on: it hides nothing, and is kept as it is.
        return vec![original];
    }
    // l2's angular interval relative to l1's start.
    let c = normalize_angle(gamma - alpha);
    let (lo, hi) = (c.max(0.0), (c + width2).min(width));
    if hi - lo < 1e-12 {
        return vec![original];
    }
    // Split the overlap where the two walls cross, if they do.
    let mut cuts = vec![lo, hi];
    if let Some(phi) = crossing(l1.a, l1.b, l2.a, l2.b).map(|p| normalize_angle(bearing(x, p) - alpha))
        && phi > lo
        && phi < hi
    {
        cuts.insert(1, phi);
    }
    // The occluded part of [0, width]: sub-intervals where l2 is nearer.
    let mut hidden: Option<(Real, Real)> = None;
    for w in cuts.windows(2) {
        let mid = alpha + 0.5 * (w[0] + w[1]);
        let (Some((r1, _)), Some((r2, t2))) = (ray_at(x, mid, l1.a, l1.b), ray_at(x, mid, l2.a, l2.b)) else {
            continue;
        };
        if r2 < r1 && (-1e-9..=1.0 + 1e-9).contains(&t2) {
            hidden = Some(match hidden {
                None => (w[0], w[1]),
                Some((s, e)) => (s.min(w[0]), e.max(w[1])),
            });
        }
    }
    let Some((s, e)) = hidden else { return vec![original] };
    let point_at = |phi: Real| -> (Real, Real) {
        match ray_at(x, alpha + phi, l1.a, l1.b) {
            Some((_, t)) => {
                let t = t.clamp(0.0, 1.0);
                (l1.a.0 + t * (l1.b.0 - l1.a.0), l1.a.1 + t * (l1.b.1 - l1.a.1))
            }
            None if phi <= 0.0 => l1.a,
            None => l1.b,
        }
    };
    let mut out = Vec::with_capacity(2);
    for (from, to) in [(0.0, s), (e, width)] {
        if to - from > 1e-12 {
            let piece = Visible { line: l1.line, a: point_at(from), b: point_at(to) };
            if piece.length() >= MIN_PIECE {
                out.push(piece);
            }
        }
    }
    out
}

/// Where segments `a`–`b` and `c`–`d` cross, if they properly do.
fn crossing(a: (Real, Real), b: (Real, Real), c: (Real, Real), d: (Real, Real)) -> Option<(Real, Real)> {
    let (ex, ey) = (b.0 - a.0, b.1 - a.1);
    let (t, u) = ray_line(a, (ex, ey), c, d)?;
    (t > 1e-9 && t < 1.0 - 1e-9 && u > 1e-9 && u < 1.0 - 1e-9).then_some((a.0 + t * ex, a.1 + t * ey))
}

/// The walls (or parts of walls) of `map` visible from `x`, considering
/// walls that come within `range` metres (thesis Alg. 4.3, nearest walls
/// first so that most are trimmed before they trim others).
pub fn observable_scene(map: &LineMap, x: (Real, Real), range: Real) -> Vec<Visible> {
    let mut candidates: Vec<(Real, Visible)> = map
        .walls
        .iter()
        .enumerate()
        .map(|(i, w)| (distance_to_segment(x, w.a, w.b), Visible { line: i as u32, a: w.a, b: w.b }))
        .filter(|(d, v)| *d <= range && v.length() >= MIN_PIECE)
        .collect();
    candidates.sort_by(|p, q| p.0.total_cmp(&q.0));
    let mut scene: Vec<Visible> = Vec::new();
    for (_, line) in candidates {
        let mut pieces = vec![line];
        for other in &scene {
            pieces = pieces.into_iter().flat_map(|p| trim_occlusion(x, p, other)).collect();
            if pieces.is_empty() {
                break;
            }
        }
        if pieces.is_empty() {
            continue;
        }
        let mut trimmed = Vec::with_capacity(scene.len());
        for old in scene {
            let mut parts = vec![old];
            for p in &pieces {
                parts = parts.into_iter().flat_map(|o| trim_occlusion(x, o, p)).collect();
            }
            trimmed.extend(parts);
        }
        trimmed.extend(pieces);
        scene = trimmed;
    }
    scene
}

/// The first wall among `lines` of `map` that the ray from `x` through
/// `p` meets: (line index, distance along the ray), if any.
pub fn first_hit(
    map: &LineMap,
    lines: impl IntoIterator<Item = u32>,
    x: (Real, Real),
    p: (Real, Real),
) -> Option<(u32, Real)> {
    // The ray is not normalized (no square root per point): distances
    // along it are in units of |p − x| until the one returned.
    let (dx, dy) = (p.0 - x.0, p.1 - x.1);
    if dx == 0.0 && dy == 0.0 {
        return None;
    }
    let mut best: Option<(u32, Real)> = None;
    for i in lines {
        let w = &map.walls[i as usize];
        let Some((r, u)) = ray_line(x, (dx, dy), w.a, w.b) else { continue };
        if r > 0.0 && (0.0..=1.0).contains(&u) && best.is_none_or(|b| r < b.1) {
            best = Some((i, r));
        }
    }
    best.map(|(i, r)| (i, r * (dx * dx + dy * dy).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(line: u32, a: (Real, Real), b: (Real, Real)) -> Visible {
        Visible { line, a, b }
    }

    fn total_length(pieces: &[Visible]) -> Real {
        pieces.iter().map(Visible::length).sum()
    }

    const EYE: (Real, Real) = (0.0, 0.0);

    #[test]
    fn case_1_a_wall_behind_hides_nothing() {
        let l1 = v(0, (-1.0, 2.0), (1.0, 2.0));
        let l2 = v(1, (-0.5, 4.0), (0.5, 4.0));
        assert_eq!(trim_occlusion(EYE, l1, &l2), vec![l1]);
    }

    #[test]
    fn case_2_a_wall_in_front_hides_all() {
        let l1 = v(0, (-1.0, 4.0), (1.0, 4.0));
        let l2 = v(1, (-1.0, 2.0), (1.0, 2.0));
        assert!(trim_occlusion(EYE, l1, &l2).is_empty());
    }

    #[test]
    fn case_3_a_wall_in_front_of_one_end_trims_it() {
        let l1 = v(0, (-2.0, 4.0), (2.0, 4.0));
        let l2 = v(1, (0.0, 2.0), (2.0, 2.0));
        let out = trim_occlusion(EYE, l1, &l2);
        assert_eq!(out.len(), 1);
        // Seen from the origin, l2 covers x ≥ 0 at y = 4.
        let xs = [out[0].a.0, out[0].b.0];
        assert!((xs.iter().cloned().fold(Real::MIN, Real::max) - 0.0).abs() < 1e-9, "{out:?}");
        assert!((total_length(&out) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn case_4_a_wall_in_front_of_the_middle_splits_it() {
        let l1 = v(0, (-2.0, 4.0), (2.0, 4.0));
        let l2 = v(1, (-0.5, 2.0), (0.5, 2.0));
        let out = trim_occlusion(EYE, l1, &l2);
        assert_eq!(out.len(), 2, "{out:?}");
        // The shadow on y = 4 spans x in [-1, 1].
        assert!((total_length(&out) - 2.0).abs() < 1e-9, "{out:?}");
        assert!(out.iter().all(|p| p.line == 0));
    }

    #[test]
    fn crossing_walls_hide_each_other_on_either_side_of_the_crossing() {
        // An X: each wall is nearer on one side of the crossing point.
        let l1 = v(0, (-2.0, 2.0), (2.0, 4.0));
        let l2 = v(1, (-2.0, 4.0), (2.0, 2.0));
        let out = trim_occlusion(EYE, l1, &l2);
        assert_eq!(out.len(), 1, "{out:?}");
        // l1 stays visible where it is nearer: from (-2, 2) to the crossing (0, 3).
        let far_end = if out[0].a.0 > out[0].b.0 { out[0].a } else { out[0].b };
        assert!((far_end.0 - 0.0).abs() < 1e-9 && (far_end.1 - 3.0).abs() < 1e-9, "{out:?}");
    }

    #[test]
    fn a_room_with_a_pillar_shows_the_pillar_and_the_walls_around_its_shadow() {
        let map = LineMap::parse("room", "0,0,10,0\n10,0,10,10\n10,10,0,10\n0,10,0,0\n4,6,6,6\n").unwrap();
        let scene = observable_scene(&map, (5.0, 2.0), 20.0);
        let on = |line: u32| scene.iter().filter(|p| p.line == line).map(Visible::length).sum::<Real>();
        assert!((on(4) - 2.0).abs() < 1e-9, "the pillar is fully visible");
        assert!((on(0) - 10.0).abs() < 1e-9 && (on(1) - 10.0).abs() < 1e-9 && (on(3) - 10.0).abs() < 1e-9);
        // The pillar (y = 6, x 4..6) shadows the top wall (y = 10) over
        // x in [5 - 8/4, 5 + 8/4] = [3, 7].
        assert!((on(2) - 6.0).abs() < 1e-9, "top wall visible length {}", on(2));
        assert_eq!(scene.iter().filter(|p| p.line == 2).count(), 2, "split in two");
        // Every visible piece is what a ray through its middle hits first.
        for p in &scene {
            let mid = (0.5 * (p.a.0 + p.b.0), 0.5 * (p.a.1 + p.b.1));
            let (line, _) = first_hit(&map, 0..5, (5.0, 2.0), mid).unwrap();
            assert_eq!(line, p.line, "{p:?}");
        }
        assert!(observable_scene(&map, (5.0, 2.0), 1.0).is_empty(), "nothing within 1 m");
    }
}
