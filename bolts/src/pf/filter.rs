//! The whole filter in one thread: K shards, the population and the
//! reassignment between them, exactly as the parallel topology runs them
//! but without messages. With K = 1 it is the serial filter; any K gives
//! the same particles, weights and lineage.

use crate::pf::assign::{Moved, Placement, assign, loads, moved};
use crate::pf::model::ParticleModel;
use crate::pf::population::Population;
use crate::pf::shard::Shard;
use crate::pf::trajectory::MeasuredStep;
use squall_core::geometry::{Pose2, Real};

/// What one correcting reading did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepReport {
    /// Work per particle (pose evaluations), in slot order.
    pub evaluations: Vec<u32>,
    /// Neff before resampling.
    pub neff: Real,
    /// Whether the set was resampled.
    pub resampled: bool,
    /// Work counted by the updates (map tiles cloned, for SLAM).
    pub update_work: u64,
    /// What the reassignment after resampling moved between tasks.
    pub moved: Moved,
    /// Particles redrawn at random (augmented MCL).
    pub injected: usize,
    /// Each particle's corrected pose and normalized weight before
    /// resampling, in slot order (for diagnostics against ground truth).
    pub weighed: Vec<(Pose2, Real)>,
}

/// A particle filter over `model`, its particles split over K shards.
pub struct Filter<M: ParticleModel> {
    model: M,
    seed: u64,
    tasks: usize,
    shards: Vec<Shard<M>>,
    /// The task holding each slot.
    task_of: Vec<usize>,
    population: Option<Population>,
    last: Option<M::Input>,
    /// The last correcting reading, and each correcting reading's stamp
    /// with the model's measurement of the step that reached it.
    last_corrected: Option<M::Input>,
    measured: Vec<(f64, Option<MeasuredStep>)>,
    gate: M::Gate,
    step: u64,
}

impl<M: ParticleModel> std::fmt::Debug for Filter<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Filter").field("tasks", &self.tasks).field("step", &self.step).finish()
    }
}

impl<M: ParticleModel> Filter<M>
where
    M::Input: Clone,
{
    /// A filter over `model` with its particles on `tasks` shards.
    pub fn new(model: M, seed: u64, tasks: usize) -> crate::Result<Self> {
        if tasks == 0 {
            return Err(crate::Error::NoShards);
        }
        Ok(Filter {
            model,
            seed,
            tasks,
            shards: Vec::new(),
            task_of: Vec::new(),
            population: None,
            last: None,
            last_corrected: None,
            measured: Vec::new(),
            gate: M::Gate::default(),
            step: 0,
        })
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// Feeds one reading; `Some` when it corrected the particles (the first
    /// reading always does: it starts the filter).
    pub fn process(&mut self, input: &M::Input) -> Option<StepReport> {
        let Some(last) = &self.last else {
            return Some(self.start(input));
        };
        self.step += 1;
        let control = self.model.control(last, input);
        for shard in &mut self.shards {
            shard.predict(&self.model, self.step, &control);
        }
        self.last = Some(input.clone());
        if !self.model.gate(&mut self.gate, &control) {
            return None;
        }
        Some(self.correct(input))
    }

    fn start(&mut self, first: &M::Input) -> StepReport {
        let n = self.model.particles();
        let state = self.model.start(first);
        self.task_of = loads(n, self.tasks).iter().enumerate().flat_map(|(t, &l)| vec![t; l]).collect();
        let model = &self.model;
        self.shards = (0..self.tasks)
            .map(|t| {
                Shard::start(model, t, self.seed, (0..n).filter(|&s| self.task_of[s] == t), &state, first)
            })
            .collect();
        let (stamp, odometry) = model.mark(first);
        let mut poses: Vec<(usize, Pose2)> = self.shards.iter().flat_map(|s| s.poses(model)).collect();
        poses.sort_by_key(|p| p.0);
        let poses: Vec<Pose2> = poses.into_iter().map(|p| p.1).collect();
        self.population = Some(Population::start(&poses, self.seed, stamp, odometry));
        self.last = Some(first.clone());
        self.last_corrected = Some(first.clone());
        StepReport { neff: n as Real, ..StepReport::default() }
    }

    fn correct(&mut self, input: &M::Input) -> StepReport {
        let measured =
            self.last_corrected.replace(input.clone()).and_then(|from| self.model.measure_step(&from, input));
        self.measured.push((self.model.mark(input).0, measured));
        let model = &self.model;
        let (step, sized) = (self.step, self.tasks > 1);
        let mut reports: Vec<_> =
            self.shards.iter_mut().flat_map(|s| s.correct(model, step, input, sized)).collect();
        reports.sort_by_key(|r| r.slot);
        let population = self.population.as_mut().expect("started");
        let poses: Vec<(Pose2, Real)> = reports.iter().map(|r| (r.pose, r.log_likelihood)).collect();
        let fits: Vec<Real> = reports.iter().map(|r| r.fit).collect();
        let decision = population
            .correct(
                self.step,
                model.mark(input),
                &poses,
                model.weight_smoothing(),
                model.resample_threshold(),
                model.resampling(),
                model.injection().map(|i| (i, &fits[..])),
                model.kld(),
            )
            .expect("the shards between them hold every slot once, so every particle reports");
        let parents = &decision.parents;
        // Without resampling every particle stays where it is.
        let (placed, moved_now) = if decision.resampled {
            let placements: Vec<Placement> = parents
                .iter()
                .map(|&p| Placement { home: self.task_of[p], bytes: reports[p].bytes })
                .collect();
            let task_of = assign(&placements, self.tasks);
            let m = moved(&placements, &task_of);
            (Some(task_of), m)
        } else {
            (None, Moved::default())
        };
        let task_of = placed.as_deref().unwrap_or(&self.task_of);
        // Peer exchange, in one thread: every shard's outgoing states go to
        // their task's inbox before anyone adopts.
        let mut inboxes: Vec<Vec<(usize, M::State)>> = vec![Vec::new(); self.tasks];
        for shard in &self.shards {
            for (to, slot, state) in shard.outgoing(parents, task_of) {
                inboxes[to].push((slot, state));
            }
        }
        for (shard, inbox) in self.shards.iter_mut().zip(inboxes) {
            shard
                .adopt(model, self.step, input, parents, task_of, &decision.fresh, &[], inbox)
                .expect("every parent is held by some shard");
        }
        if let Some(task_of) = placed {
            self.task_of = task_of;
        }
        let update_work = self.shards.iter_mut().map(|s| s.update(model, input)).sum();
        StepReport {
            evaluations: reports.iter().map(|r| r.evaluations).collect(),
            neff: decision.neff,
            resampled: decision.resampled,
            update_work,
            moved: moved_now,
            injected: decision.fresh.len(),
            weighed: reports.iter().zip(&decision.weights).map(|(r, &w)| (r.pose, w)).collect(),
        }
    }

    /// The model's measurement of each step of the best lineage (see
    /// [`crate::pf::ParticleModel::measure_step`]).
    pub fn measured_steps(&self) -> Vec<Option<MeasuredStep>> {
        let Some(population) = &self.population else { return Vec::new() };
        crate::pf::trajectory::measured_steps(&population.best_trajectory(), &self.measured)
    }

    /// The population (weights and lineage), once started.
    pub fn population(&self) -> Option<&Population> {
        self.population.as_ref()
    }

    /// Every particle's state, in slot order.
    pub fn states(&self) -> Vec<&M::State> {
        let mut all: Vec<(usize, &M::State)> =
            self.shards.iter().flat_map(|s| s.held().iter().map(|(slot, st)| (*slot, st))).collect();
        all.sort_by_key(|a| a.0);
        all.into_iter().map(|a| a.1).collect()
    }

    /// The best particle's state (highest lineage weight).
    pub fn best_state(&self) -> Option<&M::State> {
        let best = self.population.as_ref()?.best();
        self.shards[*self.task_of.get(best)?].state(best)
    }

    /// The best particle's pose at `odometry`: its last corrected pose moved
    /// by the odometry since then.
    pub fn estimate(&self, odometry: &Pose2) -> Option<Pose2> {
        let p = self.population.as_ref()?;
        let node = p.node(p.best());
        Some(node.pose.compose(&odometry.relative_to(&node.odometry)))
    }
}
