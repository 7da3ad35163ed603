//! `pf.resampler`: gathers every matcher task's reports for a reading;
//! after a correction it normalizes the weights, computes Neff, resamples
//! selectively, assigns the new set to the tasks (Hungarian algorithm:
//! equal load, fewest bytes moved) and broadcasts the decision. It owns the
//! lineage tree, so it emits the estimate for every reading on `pose` (the
//! best particle's, or with `estimate = "mode"` the heaviest mode's
//! weighted mean) and, at the end, the best particle's trajectory on
//! `trajectory`; per correction it emits the particle set's heaviest modes
//! on `hypotheses`.
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

mod loss;
mod tasks;

use std::time::Instant;

use serde::Deserialize;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, TaskContext, Tuple};

use crate::pf::assign::{Placement, assign, loads, moved, round_robin};
use crate::pf::kinds::messages::{Decision, Ready, Report, Settings};
use crate::pf::modes::{Hypotheses, modes};
use crate::pf::particle_set::ParticleSet;
use crate::pf::population::Population;
use crate::pf::shard::SlotReport;
use crate::pf::trajectory::{self, MeasuredStep};
use squall_core::geometry::{Pose2, Real};
use squall_core::sensor::PoseStamped;
use tasks::{Gathered, Holding, TaskState};

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
    /// The pose emitted on `pose`: `"best"` (the default), the best
    /// particle's; or `"mode"`, the weighted mean of the heaviest mode.
    #[serde(default)]
    estimate: Estimate,
}

/// Which pose the resampler emits as the estimate.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimate {
    /// The best particle's pose (its lineage's: GMapping's estimate, right
    /// for SLAM, whose map is the best particle's).
    #[default]
    Best,
    /// The weighted mean of the heaviest mode (see `hypotheses`): for a
    /// localizer, a pose that does not jump from particle to particle when
    /// the weights say little, and that is the place most weight is in.
    Mode,
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

/// How the particle set's modes are reported on `hypotheses`.
#[derive(Debug, Clone, Copy)]
struct ModeSettings {
    /// Modes reported per correction.
    keep: usize,
    /// Particles within this distance (m) of a mode's seed join it.
    radius: Real,
    /// ...and within this heading difference, radians.
    turn: Real,
}

/// A decision out, until every task has updated.
#[derive(Debug, Clone)]
struct Deciding {
    /// The reading decided.
    step: u64,
    /// Each new slot's parent.
    parents: Vec<usize>,
    /// The task that held each parent (the slots' tasks before the
    /// decision).
    holders: Vec<usize>,
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
    /// Each correcting reading's stamp and the model's measurement of the
    /// step that reached it, for the trajectory's smoother.
    measured: Vec<(f64, Option<MeasuredStep>)>,
    gathered: Gathered,
    /// How modes are reported on `hypotheses`.
    modes: ModeSettings,
    /// What each matcher task holds and whether it was replaced (empty
    /// until a task is lost: every task then holds its share).
    task_states: Vec<TaskState>,
    /// Slots whose states were lost, until the next decision replaces them.
    dead: Vec<bool>,
    /// After a decision, until every task has updated.
    deciding: Option<Deciding>,
    /// The last reading every task was heard for.
    done: Option<u64>,
    /// Which pose is emitted as the estimate.
    estimate: Estimate,
    /// With [`Estimate::Mode`]: the heaviest mode's pose at the last
    /// correction, and the odometry there.
    mode_at: Option<(Pose2, Pose2)>,
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
            measured: Vec::new(),
            gathered: Gathered::default(),
            modes: ModeSettings {
                keep: params.hypotheses,
                radius: params.mode_radius,
                turn: params.mode_turn,
            },
            task_states: Vec::new(),
            dead: Vec::new(),
            deciding: None,
            done: None,
            estimate: params.estimate,
            mode_at: None,
        })
    }

    /// Every task has been heard for the current reading: decide, or let
    /// the dispatcher go on.
    async fn complete(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        if let Some(Deciding { step, .. }) = self.deciding.take() {
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
        // Moved by the odometry since the correction it was taken at.
        let (at, odometry) = match (self.estimate, self.mode_at) {
            (Estimate::Mode, Some(mode_at)) => mode_at,
            _ => {
                let node = p.node(p.best());
                (node.pose, node.odometry)
            }
        };
        let pose = at.compose(&mark.1.relative_to(&odometry));
        out.emit("pose", PoseStamped { stamp: mark.0, pose }).await?;
        Ok(())
    }

    /// Every task has reported its correction: resample selectively,
    /// reassign the new set to the tasks and broadcast the decision, in
    /// named steps.
    async fn decide(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let g = std::mem::take(&mut self.gathered);
        let settings = self.settings.ok_or("pf.resampler: a correction before the start")?;
        let mark = g.mark.ok_or("pf.resampler: a correction without its reading")?;
        if self.population.is_none() {
            return Err("pf.resampler: a correction before the start".into());
        }
        let mut slots = g.slots;
        self.lose_unreported_slots(&slots, out);
        let any_dead = self.report_dead_slots(&mut slots);
        let population = self.population.as_mut().expect("checked");
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
            settings.kld,
        )?;
        let holders = self.task_of.clone();
        if d.resampled {
            self.reassign(&d.parents, &slots, out);
        }
        out.record("resample_us", started.elapsed().as_micros() as u64);
        out.record("neff_x100", (d.neff * 100.0) as u64);
        out.record("particles", d.parents.len() as u64);
        out.count("resamplings", u64::from(d.resampled));
        let mean = g.busy_us.iter().sum::<u64>() as f64 / g.busy_us.len().max(1) as f64;
        let slowest = g.busy_us.iter().copied().max().unwrap_or(0);
        out.record("imbalance_us", (slowest as f64 - mean).max(0.0) as u64);
        let joining = self.join_empty_tasks();
        self.dead.iter_mut().for_each(|d| *d = false);
        self.deciding = Some(Deciding { step: g.step, parents: d.parents.clone(), holders });
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
        self.measured.push((mark.0, g.measured));
        out.emit("decision", decision).await?;
        if out.is_subscribed("particles") {
            let set = ParticleSet {
                stamp: mark.0,
                poses: poses.iter().map(|p| p.0).collect(),
                weights: d.weights.clone(),
            };
            out.emit("particles", set).await?;
        }
        let ModeSettings { keep, radius, turn } = self.modes;
        let by_mode = self.estimate == Estimate::Mode;
        if keep > 0 || by_mode {
            let poses: Vec<Pose2> = poses.iter().map(|p| p.0).collect();
            let mut found = modes(&poses, &d.weights, radius, turn, keep.max(1));
            if by_mode {
                self.mode_at = found.first().map(|m| (m.pose, mark.1));
            }
            if keep > 0 {
                found.truncate(keep);
                out.emit("hypotheses", Hypotheses { stamp: mark.0, modes: found }).await?;
            }
        }
        self.emit_estimate(mark, out).await
    }

    /// Places the resampled set on the tasks (Hungarian: equal load, fewest
    /// bytes moved; `parents[j]` is new slot j's parent) and records what
    /// moved, and what placing slot j on task j mod K would have moved.
    fn reassign(&mut self, parents: &[usize], slots: &[SlotReport], out: &mut Emitter) {
        let tasks = self.tasks.unwrap_or(1);
        let placements: Vec<Placement> =
            parents.iter().map(|&p| Placement { home: self.task_of[p], bytes: slots[p].bytes }).collect();
        let task_of = assign(&placements, tasks);
        let m = moved(&placements, &task_of);
        out.record("particles_moved", m.particles as u64);
        out.record("bytes_moved", m.bytes);
        let naive = moved(&placements, &round_robin(placements.len(), tasks));
        out.record("bytes_moved_round_robin", naive.bytes);
        // Without resampling every particle stays where it is.
        self.task_of = task_of;
    }

    /// The tasks that held nothing and are given slots by the new
    /// placement: they hold their share from now on and report for
    /// themselves (the update waits for them).
    fn join_empty_tasks(&mut self) -> Vec<u32> {
        let tasks = self.tasks.unwrap_or(1);
        self.task_states.resize(tasks, TaskState::default());
        let mut joining = Vec::new();
        for (t, state) in self.task_states.iter_mut().enumerate() {
            if state.holding != Holding::Share && self.task_of.contains(&t) {
                state.holding = Holding::Share;
                joining.push(t as u32);
            }
        }
        joining
    }
}

impl Bolt for Resampler {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Report>()
            .output::<Decision>("decision")
            .output::<Ready>("ready")
            .output::<PoseStamped>("pose")
            .output::<PoseStamped>("trajectory")
            .output::<Hypotheses>("hypotheses")
            .output::<ParticleSet>("particles");
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.seed = ctx.seed();
        Ok(())
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let report = input.get::<Report>().ok_or("pf.resampler takes matcher reports")?;
        if let Some((step, task)) = report.step_and_task()
            && self.task_states.get(task as usize).is_some_and(|s| s.replaced)
        {
            let updated = matches!(report, Report::Updated { .. });
            let late = self.done.is_some_and(|done| step <= done)
                // A reading's report once its decision is out, or an update
                // when no decision is: its stand-in covered it.
                || (self.deciding.as_ref().is_some_and(|d| d.step == step) != updated);
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
            Report::Corrected { step, task, tasks, mark, slots, busy_us, measured } => {
                let all = self.heard(*step, *task, *tasks)?;
                let g = &mut self.gathered;
                g.measured = g.measured.or(*measured);
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
            // Nothing to estimate from is a failed run, not an empty
            // success: an empty log, a log of odometry alone, a topic
            // that matches nothing.
            return Err("pf.resampler: no reading arrived, so nothing was estimated (a source without \
                        scans: an empty log, odometry alone, or a topic or stream that matches none)"
                .into());
        };
        let lineage = population.best_trajectory();
        out.count("processed_scans", lineage.len() as u64);
        let measured = trajectory::measured_steps(&lineage, &self.measured);
        out.count("measured_steps", measured.iter().flatten().count() as u64);
        let poses = trajectory::fill(&lineage, &self.marks, settings.trajectory, &measured);
        for (stamp, pose) in poses {
            out.emit("trajectory", PoseStamped { stamp, pose }).await?;
        }
        Ok(())
    }
}
