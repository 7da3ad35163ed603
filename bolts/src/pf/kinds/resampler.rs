//! `pf.resampler`: gathers every matcher task's reports for a reading;
//! after a correction it normalizes the weights, computes Neff, resamples
//! selectively, assigns the new set to the tasks (Hungarian algorithm:
//! equal load, fewest bytes moved) and broadcasts the decision. It owns the
//! lineage tree, so it emits the best estimate for every reading on `pose`
//! and, at the end, the best particle's trajectory on `trajectory`; per
//! correction it emits the particle set's heaviest modes on `hypotheses`.
//! Metrics per correction: `neff_x100`, `resamplings`, `particles_moved`,
//! `bytes_moved`, `resample_us` (resampling and assignment),
//! `imbalance_us` (slowest matcher task's correction minus the mean: seed
//! 003's t_max − t_mean), `tiles_cloned` (in all) and
//! `tiles_cloned_per_reading` (every task's, per update), and
//! `bytes_moved_round_robin`: what placing new slot j on task j mod K
//! would have moved.
//!
//! A matcher task lost with its process (cluster mode) is replaced by one
//! that holds nothing and says so (`Report::Lost`). Its particles are then
//! lost: they weigh nothing, and until the replacement reports for itself
//! it counts as heard. If the loss comes after a decision, the tasks still
//! waiting for states the lost task was to send are told to go on without
//! them (those slots are lost too). The next correction resamples, whatever
//! Neff, from the particles left, and the replacement joins with its share
//! of the new set, sent by the others with the reading. Metric:
//! `particles_lost`.

use std::time::Instant;

use serde::Deserialize;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, TaskContext, Tuple};

use crate::pf::assign::{Placement, assign, loads, moved, round_robin};
use crate::pf::kinds::messages::{Decision, Ready, Report, Settings};
use crate::pf::modes::{Hypotheses, modes};
use crate::pf::population::Population;
use crate::pf::shard::SlotReport;
use crate::pf::trajectory;
use squall_core::geometry::{Pose2, Real};
use squall_core::sensor::PoseStamped;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ResamplerParams {
    #[allow(dead_code)]
    model: String,
    /// Modes reported on `hypotheses` per correction. The default is 3.
    #[serde(default = "default_keep")]
    hypotheses: usize,
    /// Particles within this distance (m) of a mode's seed join it. The
    /// default is 0.5.
    #[serde(default = "default_radius")]
    mode_radius: Real,
    /// ...and within this heading difference, radians. The default is 0.5.
    #[serde(default = "default_turn")]
    mode_turn: Real,
}

fn default_keep() -> usize {
    3
}
fn default_radius() -> Real {
    0.5
}
fn default_turn() -> Real {
    0.5
}

/// Reports gathered for the current reading.
#[derive(Debug, Default)]
struct Gathered {
    step: u64,
    tasks_heard: usize,
    /// Which tasks have been heard (or stand in as lost).
    heard_from: Vec<bool>,
    /// Whether a task corrected (rather than only predicted).
    corrected: bool,
    slots: Vec<SlotReport>,
    busy_us: Vec<u64>,
    update_work: u64,
    mark: Option<(f64, Pose2)>,
    /// (slot, pose) at the start.
    starts: Vec<(usize, Pose2)>,
}

/// The resampler.
#[derive(Debug)]
pub struct Resampler {
    seed: u64,
    tasks: Option<usize>,
    population: Option<Population>,
    settings: Option<Settings>,
    /// The task holding each slot.
    task_of: Vec<usize>,
    /// Every reading's stamp and odometry, for the trajectory.
    marks: Vec<(f64, Pose2)>,
    gathered: Gathered,
    /// (modes kept, radius, turn) for `hypotheses`.
    modes: (usize, Real, Real),
    /// Tasks whose replacement has not reported for itself yet: they count
    /// as heard.
    standing_in: Vec<bool>,
    /// Tasks that hold no particles until a decision has them join.
    empty: Vec<bool>,
    /// Slots whose states were lost, until the next decision replaces them.
    dead: Vec<bool>,
    /// After a decision, until every task has updated: (step, parents,
    /// the tasks that held the parents).
    deciding: Option<(u64, Vec<usize>, Vec<usize>)>,
    /// The last reading every task was heard for.
    done: Option<u64>,
    /// Tasks that were lost (their replacements' reports for readings
    /// already done are late, and dropped).
    replaced: Vec<bool>,
}

impl Resampler {
    /// Builds it (the `model` param names the model the run uses).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: ResamplerParams = p.parse()?;
        if !(params.mode_radius > 0.0 && params.mode_turn > 0.0) {
            return Err(ParamError::new("mode_radius and mode_turn must be > 0"));
        }
        if p.parallelism() != 1 {
            return Err(ParamError::new("pf.resampler runs as one task (it sees every weight)"));
        }
        Ok(Resampler {
            seed: 0,
            tasks: None,
            population: None,
            settings: None,
            task_of: Vec::new(),
            marks: Vec::new(),
            gathered: Gathered::default(),
            modes: (params.hypotheses, params.mode_radius, params.mode_turn),
            standing_in: Vec::new(),
            empty: Vec::new(),
            dead: Vec::new(),
            deciding: None,
            done: None,
            replaced: Vec::new(),
        })
    }

    /// Counts a report from a task; `true` once every task has reported.
    fn heard(&mut self, step: u64, task: u32, tasks: u32) -> Result<bool, BoxError> {
        let tasks = tasks as usize;
        if *self.tasks.get_or_insert(tasks) != tasks || task as usize >= tasks {
            return Err(format!(
                "pf.resampler: report from task {task} of {tasks}, expected {:?} tasks",
                self.tasks
            )
            .into());
        }
        if self.gathered.tasks_heard > 0 && self.gathered.step != step {
            let had = self.gathered.step;
            return Err(format!("pf.resampler: a report for reading {step} while gathering {had}").into());
        }
        self.gathered.step = step;
        if self.gathered.heard_from.len() != tasks {
            self.gathered.heard_from = vec![false; tasks];
        }
        let first_own = self.standing_in.get(task as usize).copied().unwrap_or(false);
        if first_own {
            // The replacement reports for itself from now on.
            self.standing_in[task as usize] = false;
        }
        if !std::mem::replace(&mut self.gathered.heard_from[task as usize], true) {
            self.gathered.tasks_heard += 1;
        } else if !first_own {
            return Err(format!("pf.resampler: task {task} reported twice for reading {step}").into());
        }
        self.stand_in();
        Ok(self.gathered.tasks_heard == tasks)
    }

    /// Counts the tasks that stand in as lost as heard.
    fn stand_in(&mut self) {
        let g = &mut self.gathered;
        for (t, &standing) in self.standing_in.iter().enumerate() {
            if standing && g.heard_from.get(t) == Some(&false) {
                g.heard_from[t] = true;
                g.tasks_heard += 1;
            }
        }
    }

    /// A replacement says task `task`'s particles were lost.
    async fn lost(&mut self, task: usize, tasks: usize, out: &mut Emitter) -> Result<(), BoxError> {
        if self.tasks != Some(tasks) || task >= tasks || self.population.is_none() {
            return Err(format!("pf.resampler: task {task} of {tasks} lost before the filter started").into());
        }
        self.standing_in.resize(tasks, false);
        self.empty.resize(tasks, false);
        if self.empty[task] {
            return Ok(());
        }
        self.standing_in[task] = true;
        self.empty[task] = true;
        self.replaced.resize(tasks, false);
        self.replaced[task] = true;
        if self.empty.iter().all(|&e| e) {
            return Err("pf.resampler: every matcher task lost its particles".into());
        }
        let population = self.population.as_mut().expect("checked");
        self.dead.resize(population.len(), false);
        let mut holes = Vec::new();
        if let Some((step, parents, holders)) = &self.deciding {
            // States the lost task was to send will not come.
            for (j, (&p, &to)) in parents.iter().zip(&self.task_of).enumerate() {
                if to != task && holders[p] == task {
                    holes.push(j as u32);
                    self.dead[j] = true;
                }
            }
            out.emit("decision", Decision::lost_notice(*step, task as u32, holes.clone())).await?;
        }
        for (slot, &t) in self.task_of.iter().enumerate() {
            if t == task {
                self.dead[slot] = true;
            }
        }
        // Count each slot once, however many losses named it.
        let mut lost = 0;
        for (slot, &dead) in self.dead.iter().enumerate() {
            if dead && population.lineage_weight(slot) != Real::NEG_INFINITY {
                population.lose(slot);
                lost += 1;
            }
        }
        out.count("particles_lost", lost);
        tracing::warn!("pf.resampler: matcher task {task} was lost; {lost} particles are gone");
        if self.count_lost_as_heard(tasks) {
            self.complete(out).await?;
        }
        Ok(())
    }

    /// After a loss, while a reading is being gathered or updated after a
    /// decision: the lost tasks count as heard for it. `true` if that
    /// completes it.
    fn count_lost_as_heard(&mut self, tasks: usize) -> bool {
        let in_progress = self.gathered.tasks_heard > 0 || self.deciding.is_some();
        if !in_progress {
            return false;
        }
        if self.gathered.tasks_heard == 0
            && let Some((step, _, _)) = &self.deciding
        {
            // No update heard yet: the stand-ins are for the decided step.
            self.gathered.step = *step;
        }
        if self.gathered.heard_from.len() != tasks {
            self.gathered.heard_from = vec![false; tasks];
        }
        self.stand_in();
        self.gathered.tasks_heard == tasks
    }

    /// Every task has been heard for the current reading: decide, or let
    /// the dispatcher go on.
    async fn complete(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        if let Some((step, _, _)) = self.deciding.take() {
            self.done = Some(step);
            out.count("tiles_cloned", self.gathered.update_work);
            out.record("tiles_cloned_per_reading", self.gathered.update_work);
            self.gathered = Gathered::default();
            out.emit("ready", Ready { step, corrected: true }).await?;
        } else if self.gathered.corrected {
            self.decide(out).await?;
        } else {
            let g = std::mem::take(&mut self.gathered);
            self.done = Some(g.step);
            let mark = g.mark.ok_or("pf.resampler: a reading without its mark")?;
            self.marks.push(mark);
            self.emit_estimate(mark, out).await?;
            out.emit("ready", Ready { step: g.step, corrected: false }).await?;
        }
        Ok(())
    }

    async fn emit_estimate(&self, mark: (f64, Pose2), out: &mut Emitter) -> Result<(), BoxError> {
        let Some(p) = &self.population else { return Ok(()) };
        let node = p.node(p.best());
        let pose = node.pose.compose(&mark.1.relative_to(&node.odometry));
        out.emit("pose", PoseStamped { stamp: mark.0, pose }).await?;
        Ok(())
    }

    async fn decide(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let g = std::mem::take(&mut self.gathered);
        let settings = self.settings.ok_or("pf.resampler: a correction before the start")?;
        let mark = g.mark.ok_or("pf.resampler: a correction without its reading")?;
        let population = self.population.as_mut().ok_or("pf.resampler: a correction before the start")?;
        let mut slots = g.slots;
        self.dead.resize(population.len(), false);
        if self.replaced.iter().any(|&r| r) {
            // After a loss, a slot nobody reported is lost too (a state in
            // flight to or from the lost task), and a task that reported
            // none of its slots holds nothing: it joins with this decision.
            let mut reported = vec![false; population.len()];
            for s in &slots {
                if let Some(r) = reported.get_mut(s.slot) {
                    *r = true;
                }
            }
            let mut newly = 0;
            for (slot, dead) in self.dead.iter_mut().enumerate() {
                if !reported[slot] && !*dead {
                    *dead = true;
                    population.lose(slot);
                    newly += 1;
                }
            }
            if newly > 0 {
                out.count("particles_lost", newly);
                for (t, empty) in self.empty.iter_mut().enumerate() {
                    let held = self.task_of.iter().enumerate().filter(|&(_, &h)| h == t);
                    if held.clone().count() > 0 && held.clone().all(|(slot, _)| !reported[slot]) {
                        *empty = true;
                    }
                }
                tracing::warn!("pf.resampler: {newly} more particles were lost after a matcher task was");
            }
        }
        for (slot, _) in self.dead.iter().enumerate().filter(|(_, d)| **d) {
            if slots.iter().all(|s| s.slot != slot) {
                let pose = population.node(slot).pose;
                let nothing = Real::NEG_INFINITY;
                slots.push(SlotReport {
                    slot,
                    pose,
                    log_likelihood: nothing,
                    evaluations: 0,
                    bytes: 0,
                    fit: nothing,
                });
            }
        }
        let any_dead = self.dead.iter().any(|&d| d);
        slots.sort_by_key(|s| s.slot);
        if slots.len() != population.len() || slots.iter().enumerate().any(|(i, s)| s.slot != i) {
            return Err(format!(
                "pf.resampler: {} slot reports for {} particles",
                slots.len(),
                population.len()
            )
            .into());
        }
        let started = Instant::now();
        let poses: Vec<(Pose2, Real)> = slots.iter().map(|s| (s.pose, s.log_likelihood)).collect();
        let fits: Vec<Real> = slots.iter().map(|s| s.fit).collect();
        let d = population.correct(
            g.step,
            mark,
            &poses,
            settings.smoothing,
            // Lost particles are replaced now, whatever Neff.
            if any_dead { Real::INFINITY } else { settings.threshold },
            settings.scheme,
            settings.injection.map(|i| (i, &fits[..])),
        );
        let tasks = self.tasks.unwrap_or(1);
        let holders = self.task_of.clone();
        if d.resampled {
            let placements: Vec<Placement> = d
                .parents
                .iter()
                .map(|&p| Placement { home: self.task_of[p], bytes: slots[p].bytes })
                .collect();
            let task_of = assign(&placements, tasks);
            let m = moved(&placements, &task_of);
            out.record("particles_moved", m.particles as u64);
            out.record("bytes_moved", m.bytes);
            // What the naive placement (new slot j to task j mod K) would
            // have moved, for comparison.
            let naive = moved(&placements, &round_robin(placements.len(), tasks));
            out.record("bytes_moved_round_robin", naive.bytes);
            // Without resampling every particle stays where it is.
            self.task_of = task_of;
        }
        out.record("resample_us", started.elapsed().as_micros() as u64);
        out.record("neff_x100", (d.neff * 100.0) as u64);
        out.count("resamplings", u64::from(d.resampled));
        let mean = g.busy_us.iter().sum::<u64>() as f64 / g.busy_us.len().max(1) as f64;
        let slowest = g.busy_us.iter().copied().max().unwrap_or(0);
        out.record("imbalance_us", (slowest as f64 - mean).max(0.0) as u64);
        self.empty.resize(tasks, false);
        let joining: Vec<u32> =
            (0..tasks).filter(|&t| self.empty[t] && self.task_of.contains(&t)).map(|t| t as u32).collect();
        self.standing_in.resize(tasks, false);
        for &t in &joining {
            // It holds its share from now on and reports for itself: the
            // update waits for it.
            self.empty[t as usize] = false;
            self.standing_in[t as usize] = false;
        }
        self.dead.iter_mut().for_each(|d| *d = false);
        self.deciding = Some((g.step, d.parents.clone(), holders));
        let decision = Decision {
            step: g.step,
            parents: d.parents.iter().map(|&p| p as u32).collect(),
            task_of: self.task_of.iter().map(|&t| t as u32).collect(),
            best: d.best as u32,
            fresh: d.fresh.iter().map(|&j| j as u32).collect(),
            joining,
            lost: None,
            holes: Vec::new(),
        };
        out.record("injected", d.fresh.len() as u64);
        self.marks.push(mark);
        out.emit("decision", decision).await?;
        let (keep, radius, turn) = self.modes;
        if keep > 0 {
            let poses: Vec<Pose2> = poses.iter().map(|p| p.0).collect();
            let found = modes(&poses, &d.weights, radius, turn, keep);
            out.emit("hypotheses", Hypotheses { stamp: mark.0, modes: found }).await?;
        }
        self.emit_estimate(mark, out).await
    }
}

impl Bolt for Resampler {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Report>()
            .output::<Decision>("decision")
            .output::<Ready>("ready")
            .output::<PoseStamped>("pose")
            .output::<PoseStamped>("trajectory")
            .output::<Hypotheses>("hypotheses");
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.seed = ctx.seed();
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let report = input.get::<Report>().ok_or("pf.resampler takes matcher reports")?;
        if let Some((step, task)) = report.step_and_task()
            && self.replaced.get(task as usize) == Some(&true)
        {
            let updated = matches!(report, Report::Updated { .. });
            let late = self.done.is_some_and(|done| step <= done)
                // A reading's report once its decision is out, or an update
                // when no decision is: its stand-in covered it.
                || (self.deciding.as_ref().is_some_and(|d| d.0 == step) != updated);
            if late {
                return Ok(());
            }
        }
        match report {
            Report::Started { task, tasks, mark, poses, particles, settings } => {
                self.gathered.starts.extend(poses.iter().map(|&(slot, p)| (slot as usize, p)));
                if !self.heard(0, *task, *tasks)? {
                    return Ok(());
                }
                let mut starts = std::mem::take(&mut self.gathered).starts;
                starts.sort_by_key(|s| s.0);
                let n = *particles as usize;
                if starts.len() != n || starts.iter().enumerate().any(|(i, s)| s.0 != i) {
                    return Err(
                        format!("pf.resampler: {} start poses for {n} particles", starts.len()).into()
                    );
                }
                self.settings = Some(*settings);
                let poses: Vec<Pose2> = starts.into_iter().map(|s| s.1).collect();
                self.population = Some(Population::start(&poses, self.seed, mark.0, mark.1));
                self.task_of =
                    loads(n, *tasks as usize).iter().enumerate().flat_map(|(t, &l)| vec![t; l]).collect();
                self.marks.push(*mark);
                self.emit_estimate(*mark, out).await?;
                out.emit("ready", Ready { step: 0, corrected: true }).await?;
            }
            Report::Predicted { step, task, tasks, mark } => {
                let all = self.heard(*step, *task, *tasks)?;
                self.gathered.mark = Some(*mark);
                if all {
                    self.complete(out).await?;
                }
            }
            Report::Corrected { step, task, tasks, mark, slots, busy_us } => {
                let all = self.heard(*step, *task, *tasks)?;
                let g = &mut self.gathered;
                g.slots.extend_from_slice(slots);
                g.busy_us.push(*busy_us);
                g.mark = Some(*mark);
                g.corrected = true;
                if all {
                    self.complete(out).await?;
                }
            }
            Report::Updated { step, task, tasks, update_work, .. } => {
                let all = self.heard(*step, *task, *tasks)?;
                self.gathered.update_work += update_work;
                if all {
                    self.complete(out).await?;
                }
            }
            Report::Lost { task, tasks } => self.lost(*task as usize, *tasks as usize, out).await?,
        }
        Ok(())
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let (Some(population), Some(settings)) = (&self.population, &self.settings) else {
            return Ok(());
        };
        out.count("processed_scans", population.best_trajectory().len() as u64);
        let poses =
            trajectory::fill(&population.best_trajectory(), &self.marks, settings.between, settings.noise);
        for (stamp, pose) in poses {
            out.emit("trajectory", PoseStamped { stamp, pose }).await?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A resampler of `tasks` matcher tasks that has decided for `step`
    /// and heard no update yet.
    fn deciding(step: u64, tasks: usize) -> Resampler {
        Resampler {
            seed: 0,
            tasks: Some(tasks),
            population: None,
            settings: None,
            task_of: Vec::new(),
            marks: Vec::new(),
            gathered: Gathered::default(),
            modes: (3, 0.5, 0.5),
            standing_in: vec![false; tasks],
            empty: vec![false; tasks],
            dead: Vec::new(),
            deciding: Some((step, Vec::new(), Vec::new())),
            done: None,
            replaced: vec![false; tasks],
        }
    }

    #[test]
    fn a_task_lost_between_a_decision_and_the_first_update_stands_in_for_that_step() {
        let mut r = deciding(4034, 3);
        r.standing_in[1] = true;
        assert!(!r.count_lost_as_heard(3));
        // The others' updates for the decided step complete it.
        assert!(!r.heard(4034, 0, 3).unwrap());
        assert!(r.heard(4034, 2, 3).unwrap());
        // A report for another step while gathering is still refused.
        let mut r = deciding(7, 3);
        r.standing_in[0] = true;
        r.count_lost_as_heard(3);
        let wrong = r.heard(8, 1, 3).unwrap_err().to_string();
        assert!(wrong.contains("a report for reading 8 while gathering 7"), "{wrong}");
    }
}
