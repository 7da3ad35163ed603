//! People walking the floor: each walks from node to neighbouring node of
//! the roadmap at a steady pace of their own, choosing the next node at
//! random (not turning back where there is a choice). They are clutter
//! that moves, for sensors to see and filters to ignore.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use squall_core::depth_render::Person;
use squall_core::geometry::Real;

use super::office::Floor;
use crate::{Error, Result};
use squall_core::random::stream_for_purpose;

/// Slowest and fastest walking pace, m/s.
const PACE: (Real, Real) = (0.6, 1.4);

#[derive(Debug, Clone)]
struct Walker {
    from: usize,
    to: usize,
    /// Metres walked from `from` towards `to`.
    along: Real,
    pace: Real,
    radius: Real,
    height: Real,
}

/// The people on a floor and where they are.
#[derive(Debug, Clone)]
pub struct Crowd {
    walkers: Vec<Walker>,
    rng: ChaCha8Rng,
}

impl Crowd {
    /// `count` people at random nodes of `floor`, seeded by `seed`. A
    /// floor without edges has nowhere to walk; its people stand still. An
    /// error if the floor is malformed ([`Floor::check`]).
    pub fn new(floor: &Floor, count: usize, seed: u64) -> Result<Self> {
        floor.check()?;
        let mut rng = stream_for_purpose(seed, "people");
        let mut walkers = Vec::new();
        walkers.try_reserve_exact(count).map_err(|_| Error::TooMany { count, what: "people" })?;
        walkers.extend((0..count).map(|_| {
            let from = rng.random_range(0..floor.nodes.len());
            let to = floor.neighbours(from).next().unwrap_or(from);
            Walker {
                from,
                to,
                along: 0.0,
                pace: rng.random_range(PACE.0..PACE.1),
                radius: rng.random_range(0.2..0.3),
                height: rng.random_range(1.5..1.9),
            }
        }));
        Ok(Crowd { walkers, rng })
    }

    /// Moves everyone on by `dt` seconds.
    ///
    /// # Panics
    ///
    /// If `floor` is not the floor they were placed on and lacks their
    /// nodes: walking is per frame, and the floor never changes under them.
    pub fn advance(&mut self, floor: &Floor, dt: Real) {
        for w in &mut self.walkers {
            let mut left = w.pace * dt.max(0.0);
            loop {
                let length = distance(floor.nodes[w.from], floor.nodes[w.to]);
                if w.along + left < length || length == 0.0 && w.from == w.to {
                    w.along += left;
                    break;
                }
                left -= length - w.along;
                let options: Vec<usize> = floor.neighbours(w.to).filter(|&n| n != w.from).collect();
                let next = if options.is_empty() {
                    w.from
                } else {
                    options[self.rng.random_range(0..options.len())]
                };
                (w.from, w.to, w.along) = (w.to, next, 0.0);
            }
        }
    }

    /// Where everyone is now.
    ///
    /// # Panics
    ///
    /// As [`advance`](Self::advance), on another floor than theirs.
    pub fn people(&self, floor: &Floor) -> Vec<Person> {
        self.walkers
            .iter()
            .map(|w| {
                let (a, b) = (floor.nodes[w.from], floor.nodes[w.to]);
                let length = distance(a, b);
                let f = if length > 0.0 { w.along / length } else { 0.0 };
                Person {
                    centre: (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1)),
                    radius: w.radius,
                    height: w.height,
                }
            })
            .collect()
    }
}

fn distance(a: (Real, Real), b: (Real, Real)) -> Real {
    (b.0 - a.0).hypot(b.1 - a.1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::office::office;

    #[test]
    fn people_walk_the_roadmap_at_their_pace() {
        let floor = office(3, 3, 2);
        let mut crowd = Crowd::new(&floor, 6, 11).unwrap();
        let mut before = crowd.people(&floor);
        let mut moved = 0.0;
        for _ in 0..600 {
            crowd.advance(&floor, 0.1);
            let now = crowd.people(&floor);
            for (p, q) in before.iter().zip(&now) {
                let step = distance(p.centre, q.centre);
                // At most their pace for 0.1 s (a corner cuts it short).
                assert!(step <= PACE.1 * 0.1 + 1e-9, "{step}");
                moved += step;
                // On the roadmap: on an edge between two nodes.
                let on_edge = floor.edges.iter().any(|&(a, b)| {
                    let (a, b) = (floor.nodes[a], floor.nodes[b]);
                    (distance(a, q.centre) + distance(q.centre, b) - distance(a, b)).abs() < 1e-6
                });
                assert!(on_edge, "{:?} is off the roadmap", q.centre);
            }
            before = now;
        }
        // Six people for a minute at 0.6–1.4 m/s, less the corners.
        assert!(moved > 6.0 * 60.0 * PACE.0 * 0.8, "{moved} m walked");
    }

    #[test]
    fn the_same_seed_walks_the_same_way() {
        let floor = office(3, 3, 2);
        let walk = |seed| {
            let mut crowd = Crowd::new(&floor, 3, seed).unwrap();
            (0..200)
                .map(|_| {
                    crowd.advance(&floor, 0.1);
                    crowd.people(&floor)
                })
                .last()
                .unwrap()
        };
        assert_eq!(walk(5), walk(5));
        assert_ne!(walk(5), walk(6));
    }

    #[test]
    fn a_floor_without_nodes_is_an_error() {
        let floor = Floor { nodes: Vec::new(), edges: Vec::new(), ..office(3, 1, 1) };
        assert_eq!(Crowd::new(&floor, 2, 1).unwrap_err().to_string(), "the floor has no nodes");
        // Nowhere to walk: they stand still.
        let still = Floor { edges: Vec::new(), ..office(3, 1, 1) };
        let mut crowd = Crowd::new(&still, 2, 1).unwrap();
        let before = crowd.people(&still);
        crowd.advance(&still, 1.0);
        assert_eq!(crowd.people(&still), before);
    }
}
