//! One task's share of the particles: the matcher side of the filter.
//!
//! A shard holds some slots' states. It predicts and corrects them, reports
//! (slot, pose, log-likelihood, work) — never states — and after the
//! resampler's decision hands the states it holds to the tasks that need
//! them and adopts the ones it is sent. Random draws are keyed by the run
//! seed, the reading and the slot, never by the task, so a particle evolves
//! identically wherever it lives.

use serde::{Deserialize, Serialize};

use crate::pf::model::{Correction, ParticleModel};
use crate::pf::population::{CORRECTION_STREAM, INJECTION_STREAM};
use squall_core::geometry::{Pose2, Real};
use squall_core::random::stream_for_step;

/// One slot's correction, as sent to the resampler.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SlotReport {
    /// The particle's slot.
    pub slot: usize,
    /// Its refined pose.
    pub pose: Pose2,
    /// The reading's log-likelihood there.
    pub log_likelihood: Real,
    /// Work spent (pose evaluations).
    pub evaluations: u32,
    /// Bytes of its state (what moves if a child is placed elsewhere);
    /// 0 when one task holds every particle, where nothing can move and
    /// the assignment weighs no sizes.
    pub bytes: u64,
    /// The model's size-independent fit (see [`Correction::fit`]).
    pub fit: Real,
}

/// The states one task holds, by slot.
pub struct Shard<M: ParticleModel> {
    task: usize,
    seed: u64,
    /// (slot, state), in slot order.
    held: Vec<(usize, M::State)>,
    scratch: M::Scratch,
}

impl<M: ParticleModel> std::fmt::Debug for Shard<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let slots: Vec<usize> = self.held.iter().map(|h| h.0).collect();
        f.debug_struct("Shard").field("task", &self.task).field("slots", &slots).finish()
    }
}

impl<M: ParticleModel> Shard<M> {
    /// Task `task`'s shard holding `slots`, each a copy of `start` spread
    /// by the model's `scatter` given the `first` reading, with the slot's
    /// draws for reading 0.
    pub fn start(
        model: &M,
        task: usize,
        seed: u64,
        slots: impl IntoIterator<Item = usize>,
        start: &M::State,
        first: &M::Input,
    ) -> Self {
        let held = slots
            .into_iter()
            .map(|slot| {
                let mut state = start.clone();
                model.scatter(&mut state, first, &mut stream_for_step(seed, 0, slot as u64));
                (slot, state)
            })
            .collect();
        Shard { task, seed, held, scratch: M::Scratch::default() }
    }

    /// Task `task`'s shard holding `held` (slot, state): a task that
    /// joins the filter with states sent to it.
    pub fn from_held(task: usize, seed: u64, mut held: Vec<(usize, M::State)>) -> Self {
        held.sort_by_key(|h| h.0);
        Shard { task, seed, held, scratch: M::Scratch::default() }
    }

    /// The (slot, pose) of every particle held.
    pub fn poses(&self, model: &M) -> Vec<(usize, Pose2)> {
        self.held.iter().map(|(slot, s)| (*slot, model.pose(s))).collect()
    }

    /// This shard's task.
    pub fn task(&self) -> usize {
        self.task
    }

    /// The slots held, in order.
    pub fn slots(&self) -> impl Iterator<Item = usize> + '_ {
        self.held.iter().map(|h| h.0)
    }

    /// The state of `slot`, if held here.
    pub fn state(&self, slot: usize) -> Option<&M::State> {
        self.held.binary_search_by_key(&slot, |h| h.0).ok().map(|i| &self.held[i].1)
    }

    /// Moves every held particle by the control of reading `step`.
    pub fn predict(&mut self, model: &M, step: u64, control: &M::Control) {
        for (slot, state) in &mut self.held {
            let mut rng = stream_for_step(self.seed, step, *slot as u64);
            model.predict(state, control, &mut rng);
        }
    }

    /// Corrects every held particle against reading `step`, measuring
    /// each state's bytes if `sized` (only an assignment over several
    /// tasks weighs them; with SLAM's maps, measuring took about 4% of a
    /// whole ACES run, `perf`).
    pub fn correct(&mut self, model: &M, step: u64, input: &M::Input, sized: bool) -> Vec<SlotReport> {
        let scratch = &mut self.scratch;
        model.prepare(input, scratch);
        let seed = self.seed;
        self.held
            .iter_mut()
            .map(|(slot, state)| {
                let mut rng = stream_for_step(seed, step, CORRECTION_STREAM + *slot as u64);
                let Correction { log_likelihood, evaluations, fit } =
                    model.correct(state, input, scratch, &mut rng);
                let (pose, bytes) = (model.pose(state), if sized { model.state_bytes(state) } else { 0 });
                SlotReport { slot: *slot, pose, log_likelihood, evaluations, bytes, fit }
            })
            .collect()
    }

    /// The states this shard must send after a decision: for every new
    /// slot j placed on another task whose parent `parents[j]` is held
    /// here, (task, j, parent's state), in new-slot order.
    pub fn outgoing(&self, parents: &[usize], task_of: &[usize]) -> Vec<(usize, usize, M::State)> {
        parents
            .iter()
            .zip(task_of)
            .enumerate()
            .filter(|&(_, (_, &to))| to != self.task)
            .filter_map(|(j, (&p, &to))| self.state(p).map(|s| (to, j, s.clone())))
            .collect()
    }

    /// How many states this shard must receive after a decision.
    pub fn expected_incoming(&self, parents: &[usize], task_of: &[usize]) -> usize {
        parents.iter().zip(task_of).filter(|&(&p, &to)| to == self.task && self.state(p).is_none()).count()
    }

    /// Takes up the new set after the decision for reading `step`: the new
    /// slots placed on this task, copied from local parents or taken from
    /// `incoming` (new slot, state), and the `fresh` ones (sorted) redrawn
    /// by the model given `reading`, the reading just corrected. New slots
    /// in `holes` (sorted; their parents were lost) are left out. Fails,
    /// naming the slot, if another state is missing.
    #[allow(clippy::too_many_arguments)]
    pub fn adopt(
        &mut self,
        model: &M,
        step: u64,
        reading: &M::Input,
        parents: &[usize],
        task_of: &[usize],
        fresh: &[usize],
        holes: &[usize],
        incoming: impl IntoIterator<Item = (usize, M::State)>,
    ) -> crate::Result<()> {
        let mut received: Vec<(usize, Option<M::State>)> =
            incoming.into_iter().map(|(j, s)| (j, Some(s))).collect();
        received.sort_by_key(|r| r.0);
        let local = |p: usize| self.held.binary_search_by_key(&p, |h| h.0).ok();
        // Every state must be at hand before anything moves; and local
        // parents' children are counted, so that a parent's state moves to
        // its last child and is cloned only for the others (without
        // resampling nothing is cloned).
        let mut children = vec![0usize; self.held.len()];
        let hole = |j: usize| holes.binary_search(&j).is_ok();
        for (j, (&p, &to)) in parents.iter().zip(task_of).enumerate() {
            if to != self.task || hole(j) {
                continue;
            }
            match local(p) {
                Some(i) => children[i] += 1,
                None if received.binary_search_by_key(&j, |r| r.0).is_ok() => {}
                None => return Err(crate::Error::MissingState { task: self.task, slot: j, parent: p }),
            }
        }
        let (slots, mut old): (Vec<usize>, Vec<Option<M::State>>) =
            std::mem::take(&mut self.held).into_iter().map(|(slot, s)| (slot, Some(s))).unzip();
        let mut held = Vec::with_capacity(task_of.iter().filter(|&&t| t == self.task).count());
        for (j, (&p, &to)) in parents.iter().zip(task_of).enumerate() {
            if to != self.task || hole(j) {
                continue;
            }
            let state = match slots.binary_search(&p).ok() {
                Some(i) => {
                    children[i] -= 1;
                    if children[i] == 0 { old[i].take() } else { old[i].clone() }
                }
                None => received.binary_search_by_key(&j, |r| r.0).ok().and_then(|i| received[i].1.take()),
            };
            held.push((j, state.expect("checked above")));
        }
        for (slot, state) in &mut held {
            if fresh.binary_search(slot).is_ok() {
                model.inject(
                    state,
                    reading,
                    &mut stream_for_step(self.seed, step, INJECTION_STREAM + *slot as u64),
                );
            }
        }
        self.held = held;
        Ok(())
    }

    /// Adds a correcting reading to every held particle; returns the work
    /// counted.
    pub fn update(&mut self, model: &M, input: &M::Input) -> u64 {
        self.held.iter_mut().map(|(_, s)| model.update(s, input)).sum()
    }

    /// The states held, by slot.
    pub fn held(&self) -> &[(usize, M::State)] {
        &self.held
    }

    /// Drops every state but `slot`'s: once the run has ended only the best
    /// particle's snapshot is still wanted, and building it (a whole map,
    /// for SLAM) should reuse the others' memory, not add to it.
    pub fn keep_only(&mut self, slot: usize) {
        self.held.retain(|h| h.0 == slot);
        self.held.shrink_to_fit();
    }
}

#[cfg(test)]
mod tests {
    use rand::RngExt;

    use super::*;

    /// A model whose state records where it has been.
    struct Walk;

    impl ParticleModel for Walk {
        type Input = f64;
        type Control = f64;
        type State = Vec<f64>;
        type Scratch = ();
        type Gate = ();

        fn particles(&self) -> usize {
            6
        }
        fn start(&self, first: &f64) -> Vec<f64> {
            vec![*first]
        }
        fn mark(&self, input: &f64) -> (f64, Pose2) {
            (*input, Pose2::IDENTITY)
        }
        fn control(&self, previous: &f64, input: &f64) -> f64 {
            input - previous
        }
        fn gate(&self, (): &mut (), _: &f64) -> bool {
            true
        }
        fn predict(&self, s: &mut Vec<f64>, c: &f64, rng: &mut rand_chacha::ChaCha8Rng) {
            s.push(s.last().unwrap() + c + rng.random::<f64>());
        }
        fn correct(
            &self,
            s: &mut Vec<f64>,
            input: &f64,
            (): &mut (),
            _: &mut rand_chacha::ChaCha8Rng,
        ) -> Correction {
            let log_likelihood = -(s.last().unwrap() - input).powi(2);
            Correction { log_likelihood, evaluations: 1, fit: log_likelihood }
        }
        fn pose(&self, s: &Vec<f64>) -> Pose2 {
            Pose2::new(*s.last().unwrap(), 0.0, 0.0)
        }
        fn state_bytes(&self, s: &Vec<f64>) -> u64 {
            8 * s.len() as u64
        }
        fn weight_smoothing(&self) -> Real {
            1.0
        }
        fn inject(&self, s: &mut Vec<f64>, reading: &f64, _: &mut rand_chacha::ChaCha8Rng) {
            *s = vec![-*reading];
        }
        fn resample_threshold(&self) -> Real {
            0.5
        }
    }

    #[test]
    fn a_transfer_delivers_exactly_the_parents_state() {
        let mut shards: Vec<Shard<Walk>> = (0..2)
            .map(|t| Shard::start(&Walk, t, 9, (0..6).filter(move |s| s % 2 == t), &vec![0.0], &0.0))
            .collect();
        for (step, shard) in shards.iter_mut().enumerate() {
            shard.predict(&Walk, step as u64 + 1, &1.0);
        }
        let before: Vec<Vec<f64>> = (0..6).map(|s| shards[s % 2].state(s).unwrap().clone()).collect();
        // New slots 0..6 descend from 5, 5, 0, 1, 2, 2 and go to tasks 0, 0, 0, 1, 1, 1.
        let parents = [5, 5, 0, 1, 2, 2];
        let task_of = [0, 0, 0, 1, 1, 1];
        let sent: Vec<Vec<(usize, usize, Vec<f64>)>> =
            shards.iter().map(|s| s.outgoing(&parents, &task_of)).collect();
        assert_eq!(sent[1].iter().map(|t| (t.0, t.1)).collect::<Vec<_>>(), vec![(0, 0), (0, 1)]);
        assert_eq!(sent[0].iter().map(|t| (t.0, t.1)).collect::<Vec<_>>(), vec![(1, 4), (1, 5)]);
        assert_eq!(shards[0].expected_incoming(&parents, &task_of), 2);
        assert_eq!(shards[1].expected_incoming(&parents, &task_of), 2);
        let to = |t: usize| sent.iter().flatten().filter(move |s| s.0 == t).map(|s| (s.1, s.2.clone()));
        let (in0, in1): (Vec<_>, Vec<_>) = (to(0).collect(), to(1).collect());
        shards[0].adopt(&Walk, 1, &1.0, &parents, &task_of, &[], &[], in0).unwrap();
        shards[1].adopt(&Walk, 1, &1.0, &parents, &task_of, &[], &[], in1).unwrap();
        for (j, &p) in parents.iter().enumerate() {
            assert_eq!(shards[task_of[j]].state(j), Some(&before[p]), "new slot {j}");
        }
        assert_eq!(shards[0].slots().collect::<Vec<_>>(), vec![0, 1, 2]);
    }

    #[test]
    fn fresh_slots_are_redrawn_and_the_others_copied() {
        let mut shard: Shard<Walk> = Shard::start(&Walk, 0, 9, [0, 1, 2], &vec![0.5], &0.0);
        shard.adopt(&Walk, 1, &1.0, &[2, 2, 0], &[0, 0, 0], &[1], &[], Vec::new()).unwrap();
        assert_eq!(
            shard.held().iter().map(|h| h.1.clone()).collect::<Vec<_>>(),
            vec![vec![0.5], vec![-1.0], vec![0.5]]
        );
    }

    #[test]
    fn keeping_one_slot_drops_the_others_and_keeps_its_state() {
        let mut shard: Shard<Walk> = Shard::start(&Walk, 0, 9, [0, 1, 2], &vec![0.5], &0.0);
        let kept = shard.state(1).cloned();
        shard.keep_only(1);
        assert_eq!(shard.slots().collect::<Vec<_>>(), vec![1]);
        assert_eq!(shard.state(1).cloned(), kept);
        shard.keep_only(7);
        assert!(shard.held().is_empty(), "a slot not held keeps nothing");
    }

    #[test]
    fn a_missing_transfer_is_an_error_naming_the_slot() {
        let mut shard: Shard<Walk> = Shard::start(&Walk, 0, 9, [0, 1], &vec![0.0], &0.0);
        let e = shard.adopt(&Walk, 1, &1.0, &[0, 3], &[0, 0], &[], &[], Vec::new()).unwrap_err().to_string();
        assert!(e.contains("new slot 1") && e.contains("parent 3"), "{e}");
    }

    #[test]
    fn a_hole_is_left_out_and_the_rest_adopted() {
        // New slot 1's parent was on a task that was lost: the shard goes
        // on without it rather than waiting for it.
        let mut shard: Shard<Walk> = Shard::start(&Walk, 0, 9, [0, 1], &vec![0.0], &0.0);
        shard.adopt(&Walk, 1, &1.0, &[0, 3], &[0, 0], &[], &[1], Vec::new()).unwrap();
        assert_eq!(shard.slots().collect::<Vec<_>>(), vec![0]);
        let joined: Shard<Walk> = Shard::from_held(1, 9, vec![(4, vec![2.0]), (2, vec![1.0])]);
        assert_eq!(joined.slots().collect::<Vec<_>>(), vec![2, 4]);
    }
}
