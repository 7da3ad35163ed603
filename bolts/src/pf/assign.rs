//! Which task holds each particle after resampling: an equal load per task
//! (±1) and as few bytes of particle state moved as possible.
//!
//! A new particle costs nothing where its parent already lives and the
//! parent's state size anywhere else. The assignment is the Hungarian
//! algorithm (`pathfinding`'s Kuhn–Munkres) over particles × task slots.
//! For this cost the problem splits by task — each task should keep the
//! children of its own particles with the largest parents, up to its
//! load — so beyond [`HUNGARIAN_LIMIT`] particles (the Hungarian algorithm
//! is cubic) that exact greedy answer is used instead; the tests check the
//! two agree.

use pathfinding::prelude::{Matrix, kuhn_munkres_min};

/// Above this many particles the cubic Hungarian algorithm gives way to
/// the equivalent greedy assignment.
pub(crate) const HUNGARIAN_LIMIT: usize = 256;

/// The load of each of `tasks` tasks sharing `particles` particles: equal,
/// the first `particles % tasks` one more.
pub(crate) fn loads(particles: usize, tasks: usize) -> Vec<usize> {
    assert!(tasks > 0, "at least one task");
    (0..tasks).map(|t| particles / tasks + usize::from(t < particles % tasks)).collect()
}

/// A new particle to place: the task holding its parent and the parent's
/// state size in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Placement {
    /// The task that holds the parent.
    pub home: usize,
    /// Bytes that move if the particle goes anywhere else.
    pub bytes: u64,
}

/// What an assignment moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Moved {
    /// Particles placed away from their parent.
    pub particles: usize,
    /// Their parents' bytes.
    pub bytes: u64,
}

/// The task of each new particle (same order as `placements`), with the
/// loads of [`loads`], moving as few bytes as possible.
pub(crate) fn assign(placements: &[Placement], tasks: usize) -> Vec<usize> {
    if placements.len() <= HUNGARIAN_LIMIT { hungarian(placements, tasks) } else { greedy(placements, tasks) }
}

/// The naive placement to compare with: new particle j to task j mod K.
pub(crate) fn round_robin(particles: usize, tasks: usize) -> Vec<usize> {
    (0..particles).map(|j| j % tasks).collect()
}

/// What placing the particles on `task_of` moves.
pub(crate) fn moved(placements: &[Placement], task_of: &[usize]) -> Moved {
    placements
        .iter()
        .zip(task_of)
        .filter(|&(p, &t)| p.home != t)
        .fold(Moved::default(), |m, (p, _)| Moved { particles: m.particles + 1, bytes: m.bytes + p.bytes })
}

/// Kuhn–Munkres over particles × task slots (task t repeated load(t)
/// times).
fn hungarian(placements: &[Placement], tasks: usize) -> Vec<usize> {
    let n = placements.len();
    if n == 0 {
        return Vec::new();
    }
    let slot_task: Vec<usize> = loads(n, tasks).iter().enumerate().flat_map(|(t, &l)| vec![t; l]).collect();
    // Costs as i64: state sizes are far below 2^63 / n.
    let costs: Vec<i64> = placements
        .iter()
        .flat_map(|p| slot_task.iter().map(move |&t| if t == p.home { 0 } else { p.bytes as i64 }))
        .collect();
    let matrix = Matrix::from_vec(n, n, costs).expect("n × n costs");
    let (_, columns) = kuhn_munkres_min(&matrix);
    columns.into_iter().map(|c| slot_task[c]).collect()
}

/// The exact answer for this cost without the cubic search: each task
/// keeps its own children with the largest parents up to its load; the
/// rest fill the remaining room in order.
fn greedy(placements: &[Placement], tasks: usize) -> Vec<usize> {
    let mut room = loads(placements.len(), tasks);
    let mut task_of = vec![usize::MAX; placements.len()];
    let mut by_size: Vec<usize> = (0..placements.len()).collect();
    // Largest first; ties by index, so the result is deterministic.
    by_size.sort_by(|&a, &b| placements[b].bytes.cmp(&placements[a].bytes).then(a.cmp(&b)));
    for &j in &by_size {
        let home = placements[j].home;
        if home < tasks && room[home] > 0 {
            room[home] -= 1;
            task_of[j] = home;
        }
    }
    let mut t = 0;
    for slot in task_of.iter_mut().filter(|s| **s == usize::MAX) {
        while room[t] == 0 {
            t += 1;
        }
        room[t] -= 1;
        *slot = t;
    }
    task_of
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    fn random_placements(rng: &mut ChaCha8Rng, n: usize, tasks: usize) -> Vec<Placement> {
        // Resampling piles children on a few parents: skew the homes.
        (0..n)
            .map(|_| {
                let home = (rng.random_range(0..tasks * tasks) as f64).sqrt() as usize;
                Placement { home, bytes: rng.random_range(1..1_000_000) }
            })
            .collect()
    }

    fn per_task(task_of: &[usize], tasks: usize) -> Vec<usize> {
        (0..tasks).map(|t| task_of.iter().filter(|&&x| x == t).count()).collect()
    }

    #[test]
    fn loads_differ_by_at_most_one_and_sum_to_the_particles() {
        assert_eq!(loads(10, 4), vec![3, 3, 2, 2]);
        assert_eq!(loads(3, 5), vec![1, 1, 1, 0, 0]);
        assert_eq!(loads(100, 1), vec![100]);
    }

    #[test]
    fn the_assignment_balances_the_load() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for (n, tasks) in [(30, 2), (30, 4), (100, 3), (7, 8), (1000, 5)] {
            let p = random_placements(&mut rng, n, tasks);
            assert_eq!(per_task(&assign(&p, tasks), tasks), loads(n, tasks), "n {n} K {tasks}");
        }
    }

    #[test]
    fn a_task_keeps_as_many_of_its_own_children_as_its_load_allows() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for tasks in 1..=6 {
            let p = random_placements(&mut rng, 60, tasks);
            let task_of = assign(&p, tasks);
            let load = loads(60, tasks);
            for (t, &load) in load.iter().enumerate() {
                let children = p.iter().filter(|x| x.home == t).count();
                let kept = p.iter().zip(&task_of).filter(|&(x, &to)| x.home == t && to == t).count();
                assert_eq!(kept, children.min(load), "task {t} of {tasks}");
            }
        }
    }

    #[test]
    fn nothing_moves_when_every_parent_is_already_in_place() {
        let p: Vec<Placement> = (0..12).map(|j| Placement { home: j % 3, bytes: 100 }).collect();
        let task_of = assign(&p, 3);
        assert_eq!(moved(&p, &task_of), Moved::default());
    }

    #[test]
    fn the_greedy_shortcut_is_as_cheap_as_the_hungarian_algorithm() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..40 {
            let n = rng.random_range(1..80);
            let tasks = rng.random_range(1..9);
            let p = random_placements(&mut rng, n, tasks);
            let (h, g) = (hungarian(&p, tasks), greedy(&p, tasks));
            assert_eq!(moved(&p, &h).bytes, moved(&p, &g).bytes, "n {n} K {tasks}");
            assert_eq!(per_task(&g, tasks), loads(n, tasks));
        }
    }

    #[test]
    fn the_assignment_moves_no_more_than_round_robin() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let p = random_placements(&mut rng, 100, 4);
        let smart = moved(&p, &assign(&p, 4));
        let naive = moved(&p, &round_robin(100, 4));
        assert!(smart.bytes < naive.bytes, "{smart:?} vs {naive:?}");
    }
}
