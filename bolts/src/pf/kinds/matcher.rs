//! `pf.matcher`: one task's share of the particles. Each task predicts and
//! corrects the particles it holds, reports (slot, pose, log-weight,
//! evaluations, state size) to the resampler — never states — and after
//! the resampler's decision sends the parents' states other tasks now need
//! straight to them (peer exchange), adopts the ones it is sent, and
//! updates its particles with the reading. The task holding the best
//! particle emits its snapshot (the map, for SLAM) every `map_interval`
//! corrections and at the end.
//!
//! A task that replaces one lost with its process (cluster mode) holds
//! nothing: it says so at once, reports every reading as merely predicted,
//! and joins when a decision gives it slots, with the states and the
//! reading its peers send.
//!
//! Metrics: `evaluations_per_particle`, `correct_us`, `update_us`,
//! `particles_received`, `map_bytes_per_reading` (the task's particles'
//! memory after every tenth update, shared tiles counted once), the gauge
//! `map_bytes` (the same value, last set; at the end, the final set's) and
//! at the end what the best particle learned of the robot
//! (`ParticleModel::learned`).

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, TaskContext, Tuple};

use crate::pf::assign::loads;
use crate::pf::kinds::HostedModel;
use crate::pf::kinds::messages::{Decision, Reading, Report, Settings, Transfer};
use crate::pf::shard::Shard;

/// `map_bytes_per_reading` is measured at the first update and every this
/// many after: counting distinct tiles over every particle's map and
/// snapshots took about 4% of a whole ACES run at every update (`perf`),
/// while the maps grow by a few tiles per reading.
const MEMORY_SAMPLE_INTERVAL: u64 = 10;

/// A correction waiting for its decision and transfers.
#[derive(Debug)]
struct Pending<I> {
    reading: Arc<Reading<I>>,
    /// The resampler's decision, once it has come and this task's
    /// transfers are sent.
    plan: Option<Plan>,
}

/// A decision as this task carries it out.
#[derive(Debug)]
struct Plan {
    parents: Vec<usize>,
    task_of: Vec<usize>,
    fresh: Vec<usize>,
    best: usize,
    /// States this task must receive before it can adopt the new set.
    expected: usize,
    /// New slots whose states were lost with another task (sorted).
    holes: Vec<usize>,
    started: Instant,
}

impl Plan {
    /// Has `shard` take up this plan's new set for reading `step`, with the
    /// states `received` from other tasks.
    fn adopt<M: HostedModel>(
        &self,
        model: &M,
        shard: &mut Shard<M>,
        step: u64,
        input: &M::Input,
        received: impl IntoIterator<Item = (usize, M::State)>,
    ) -> crate::Result<()> {
        shard.adopt(model, step, input, &self.parents, &self.task_of, &self.fresh, &self.holes, received)
    }
}

/// The matcher for model `M`.
pub struct Matcher<M: HostedModel> {
    model: M,
    map_interval: u64,
    task: usize,
    tasks: usize,
    seed: u64,
    shard: Option<Shard<M>>,
    gate: M::Gate,
    previous: Option<Arc<Reading<M::Input>>>,
    /// The run's first reading (what the model checks the others against).
    first: Option<Arc<Reading<M::Input>>>,
    /// The last correcting reading (task 0, for the model's measurement
    /// of each step between correcting readings).
    previous_corrected: Option<Arc<Reading<M::Input>>>,
    /// Readings that arrived while a correction was in progress.
    queued: VecDeque<Arc<Reading<M::Input>>>,
    pending: Option<Pending<M::Input>>,
    /// States received for the pending correction.
    received: Vec<(usize, M::State)>,
    best: usize,
    corrections: u64,
    /// Updates this task made with a reading (for the memory samples).
    updates: u64,
    /// A replacement for a task lost with its process, not yet joined.
    replacement: bool,
    /// Whether the replacement has said it holds nothing.
    announced: bool,
    /// A replacement's way into the filter: the decision's plan for it,
    /// and the reading that comes with the states.
    joining: Option<(u64, Plan)>,
    join_reading: Option<Arc<Reading<M::Input>>>,
    /// Transfers that reached a replacement before their decision.
    early: Vec<Transfer<M::State, M::Input>>,
}

impl<M: HostedModel> std::fmt::Debug for Matcher<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Matcher").field("task", &self.task).field("tasks", &self.tasks).finish()
    }
}

impl<M: HostedModel> Matcher<M> {
    /// Builds it: every model setting, plus `map_interval` (corrections
    /// between snapshots; 0, the default, only at the end).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let mut table = p.table().clone();
        table.remove("model");
        let map_interval = match table.remove("map_interval") {
            None => 0,
            Some(v) => v
                .as_integer()
                .and_then(|i| u64::try_from(i).ok())
                .ok_or_else(|| ParamError::new(format!("map_interval must be a count ≥ 0, got {v}")))?,
        };
        let model = M::from_table(table, p.budget()).map_err(ParamError::new)?;
        Ok(Matcher {
            model,
            map_interval,
            task: 0,
            tasks: 1,
            seed: 0,
            shard: None,
            gate: M::Gate::default(),
            previous: None,
            first: None,
            previous_corrected: None,
            queued: VecDeque::new(),
            pending: None,
            received: Vec::new(),
            updates: 0,
            best: 0,
            corrections: 0,
            replacement: false,
            announced: false,
            joining: None,
            join_reading: None,
            early: Vec::new(),
        })
    }

    /// A replacement says, once, that it holds nothing.
    async fn announce(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        if self.replacement && !self.announced {
            self.announced = true;
            let (task, tasks) = (self.task as u32, self.tasks as u32);
            out.emit("report", Report::Lost { task, tasks }).await?;
        }
        Ok(())
    }

    /// A replacement not yet joined takes a decision: it joins if the
    /// decision gives it slots, else it has nothing to update.
    async fn replacement_decision(&mut self, decision: &Decision, out: &mut Emitter) -> Result<(), BoxError> {
        let me = self.task as u32;
        if decision.lost.is_some() {
            return Ok(());
        }
        let early = std::mem::take(&mut self.early);
        let (now, later): (Vec<_>, Vec<_>) = early.into_iter().partition(|t| t.step == decision.step);
        self.early = later.into_iter().filter(|t| t.step > decision.step).collect();
        if !decision.joining.contains(&me) {
            let (step, task, tasks) = (decision.step, me, self.tasks as u32);
            let updated = Report::Updated { step, task, tasks, busy_us: 0, update_work: 0 };
            return Ok(out.emit("report", updated).await?);
        }
        let parents: Vec<usize> = decision.parents.iter().map(|&p| p as usize).collect();
        let task_of: Vec<usize> = decision.task_of.iter().map(|&t| t as usize).collect();
        let expected = task_of.iter().filter(|&&t| t == self.task).count();
        let fresh = decision.fresh.iter().map(|&j| j as usize).collect();
        let best = decision.best as usize;
        let plan =
            Plan { parents, task_of, fresh, best, expected, holes: Vec::new(), started: Instant::now() };
        self.joining = Some((decision.step, plan));
        self.received.clear();
        for transfer in now {
            self.join_reading = transfer.reading.or(self.join_reading.take());
            self.received.extend(transfer.states.into_iter().map(|(slot, s)| (slot as usize, s)));
        }
        self.join(out).await
    }

    /// Joins the filter once every state and the reading have come.
    async fn join(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let ready = matches!(&self.joining, Some((_, plan)) if self.received.len() >= plan.expected)
            && self.join_reading.is_some();
        if !ready {
            return Ok(());
        }
        let (Some((step, plan)), Some(reading)) = (self.joining.take(), self.join_reading.take()) else {
            return Ok(());
        };
        let mut shard = Shard::from_held(self.task, self.seed, Vec::new());
        plan.adopt(&self.model, &mut shard, step, &reading.input, self.received.drain(..))?;
        out.record("particles_received", plan.expected as u64);
        let update_work = shard.update(&self.model, &reading.input);
        self.shard = Some(shard);
        self.previous = Some(reading);
        self.gate = M::Gate::default();
        self.best = plan.best;
        self.replacement = false;
        let busy_us = plan.started.elapsed().as_micros() as u64;
        let (task, tasks) = (self.task as u32, self.tasks as u32);
        out.emit("report", Report::Updated { step, task, tasks, busy_us, update_work }).await?;
        self.corrected(out).await?;
        // Readings that came while it joined: those after the join's.
        self.queued.retain(|r| r.step > step);
        self.pump(out).await
    }

    fn settings(&self) -> Settings {
        Settings {
            smoothing: self.model.weight_smoothing(),
            threshold: self.model.resample_threshold(),
            scheme: self.model.resampling(),
            injection: self.model.injection(),
            trajectory: self.model.trajectory_output(),
            kld: self.model.kld(),
        }
    }

    /// Works through queued readings until one waits for a decision.
    async fn pump(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        while self.pending.is_none() {
            let Some(reading) = self.queued.pop_front() else { break };
            self.take_reading(reading, out).await?;
        }
        Ok(())
    }

    async fn take_reading(
        &mut self,
        reading: Arc<Reading<M::Input>>,
        out: &mut Emitter,
    ) -> Result<(), BoxError> {
        let (task, tasks) = (self.task as u32, self.tasks as u32);
        let mark = self.model.mark(&reading.input);
        if let Err(why) = self.model.admit(self.first.as_deref().map(|r| &*r.input), &reading.input) {
            return Err(format!("pf.matcher: reading {} (stamp {}): {why}", reading.step, mark.0).into());
        }
        self.first.get_or_insert_with(|| reading.clone());
        let Some(previous) = self.previous.replace(reading.clone()) else {
            let n = self.model.particles();
            let state = self.model.start(&reading.input);
            let load = loads(n, self.tasks);
            let first: usize = load[..self.task].iter().sum();
            // Equal lineage weights: the best is the last slot.
            self.best = n - 1;
            let slots = first..first + load[self.task];
            let shard = Shard::start(&self.model, self.task, self.seed, slots, &state, &reading.input);
            if self.task == 0 {
                self.previous_corrected = Some(reading.clone());
            }
            let poses = shard.poses(&self.model).into_iter().map(|(slot, p)| (slot as u32, p)).collect();
            self.shard = Some(shard);
            let (particles, settings) = (n as u32, self.settings());
            let started = Report::Started { task, tasks, mark, poses, particles, settings };
            out.emit("report", started).await?;
            // The start counts as the first correction (it maps the first
            // reading).
            return self.corrected(out).await;
        };
        let shard = self.shard.as_mut().ok_or("pf.matcher: no particles yet")?;
        let control = self.model.control(&previous.input, &reading.input);
        shard.predict(&self.model, reading.step, &control);
        let step = reading.step;
        if !self.model.gate(&mut self.gate, &control) {
            return Ok(out.emit("report", Report::Predicted { step, task, tasks, mark }).await?);
        }
        let started = Instant::now();
        let slots = shard.correct(&self.model, step, &reading.input, self.tasks > 1);
        let busy_us = started.elapsed().as_micros() as u64;
        out.record("correct_us", busy_us);
        for s in &slots {
            out.record("evaluations_per_particle", u64::from(s.evaluations));
        }
        // One task measures the step, so that the resampler hears it once
        // whatever the number of tasks.
        let measured = if task == 0 {
            let since = self.previous_corrected.replace(reading.clone());
            since.and_then(|from| self.model.measure_step(&from.input, &reading.input))
        } else {
            None
        };
        out.emit("report", Report::Corrected { step, task, tasks, mark, slots, busy_us, measured }).await?;
        self.pending = Some(Pending { reading, plan: None });
        Ok(())
    }

    /// Takes the resampler's decision for the pending correction: sends
    /// the parents' states other tasks need, straight to them.
    async fn plan(&mut self, decision: &Decision, out: &mut Emitter) -> Result<(), BoxError> {
        if decision.lost.is_some() {
            // Another task was lost after this decision: the states it was
            // to send will not come.
            if let Some(Pending { reading, plan: Some(plan) }) = &mut self.pending
                && reading.step == decision.step
            {
                let mine: Vec<usize> = decision
                    .holes
                    .iter()
                    .map(|&j| j as usize)
                    .filter(|&j| plan.task_of.get(j) == Some(&self.task))
                    .collect();
                plan.expected -= mine.len().min(plan.expected);
                plan.holes.extend(mine);
                plan.holes.sort_unstable();
            }
            return Ok(());
        }
        let pending = self.pending.as_mut().ok_or("pf.matcher: a decision with no correction pending")?;
        if decision.step != pending.reading.step {
            let (got, want) = (decision.step, pending.reading.step);
            return Err(format!("pf.matcher: decision for reading {got} while {want} is pending").into());
        }
        let shard = self.shard.as_ref().ok_or("pf.matcher: no particles yet")?;
        let started = Instant::now();
        let parents: Vec<usize> = decision.parents.iter().map(|&p| p as usize).collect();
        let task_of: Vec<usize> = decision.task_of.iter().map(|&t| t as usize).collect();
        let mut by_task: Vec<Vec<(u32, M::State)>> = (0..self.tasks).map(|_| Vec::new()).collect();
        for (to, slot, state) in shard.outgoing(&parents, &task_of) {
            by_task[to].push((slot as u32, state));
        }
        for (to, states) in by_task.into_iter().enumerate().filter(|(_, s)| !s.is_empty()) {
            // A joining task never got the reading: it comes with the states.
            let reading = decision.joining.contains(&(to as u32)).then(|| pending.reading.clone());
            out.send_peer(to, Transfer { step: decision.step, states, reading }).await?;
        }
        let expected = shard.expected_incoming(&parents, &task_of);
        let fresh = decision.fresh.iter().map(|&j| j as usize).collect();
        let best = decision.best as usize;
        pending.plan = Some(Plan { parents, task_of, fresh, best, expected, holes: Vec::new(), started });
        Ok(())
    }

    /// Finishes the pending correction once its decision is planned and
    /// every transfer it waits for has come: adopts the new set and
    /// updates it with the reading.
    async fn advance(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        let Some(Pending { plan: Some(plan), .. }) = &self.pending else { return Ok(()) };
        if self.received.len() < plan.expected {
            return Ok(());
        }
        let Some(Pending { reading, plan: Some(plan) }) = self.pending.take() else { return Ok(()) };
        let shard = self.shard.as_mut().ok_or("pf.matcher: no particles yet")?;
        out.record("particles_received", self.received.len() as u64);
        let step = reading.step;
        plan.adopt(&self.model, shard, step, &reading.input, self.received.drain(..))?;
        let update_work = shard.update(&self.model, &reading.input);
        let busy_us = plan.started.elapsed().as_micros() as u64;
        out.record("update_us", busy_us);
        self.best = plan.best;
        let (task, tasks) = (self.task as u32, self.tasks as u32);
        out.emit("report", Report::Updated { step, task, tasks, busy_us, update_work }).await?;
        // Once the report is out (the resampler need not wait for it): how
        // the maps grow, every MEMORY_SAMPLE_INTERVAL-th update.
        self.updates += 1;
        if let Some(shard) = &self.shard
            && (self.updates - 1).is_multiple_of(MEMORY_SAMPLE_INTERVAL)
        {
            let bytes = self.model.memory(shard.held().iter().map(|(_, s)| s));
            out.record("map_bytes_per_reading", bytes);
            out.gauge("map_bytes", bytes);
        }
        self.corrected(out).await
    }

    /// Counts a finished correction; every `map_interval`-th, the holder of
    /// the best particle emits its snapshot.
    async fn corrected(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        self.corrections += 1;
        if self.map_interval > 0 && self.corrections.is_multiple_of(self.map_interval) {
            self.emit_snapshot(out).await?;
        }
        Ok(())
    }

    async fn emit_snapshot(&self, out: &mut Emitter) -> Result<(), BoxError> {
        if let Some(state) = self.shard.as_ref().and_then(|s| s.state(self.best)) {
            out.emit("map", self.model.snapshot(state)).await?;
        }
        Ok(())
    }
}

impl<M: HostedModel> Bolt for Matcher<M> {
    fn declare(&self, d: &mut Declarer) {
        d.input::<Reading<M::Input>>()
            .input::<Decision>()
            .peer_message(M::transfer_message())
            .output::<Report>("report")
            .output::<M::Snapshot>("map")
            // Only a replacement does anything on a tick (it says it holds
            // nothing, even if no tuple comes).
            .tick(std::time::Duration::from_millis(200));
    }

    async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
        self.task = ctx.task_index();
        self.tasks = ctx.task_count();
        self.seed = ctx.seed();
        self.replacement = ctx.is_replacement();
        Ok(())
    }

    async fn tick(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        // A replacement may get no tuple while the others wait for it.
        self.announce(out).await
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        self.announce(out).await?;
        let input = match input.into_arc::<Reading<M::Input>>() {
            Ok(reading) if self.replacement && self.joining.is_some() => {
                // Joining: the reading waits for the states.
                self.queued.push_back(reading);
                return Ok(());
            }
            Ok(reading) if self.replacement => {
                // Nothing to move or correct until it joins.
                let (step, task, tasks) = (reading.step, self.task as u32, self.tasks as u32);
                let mark = self.model.mark(&reading.input);
                return Ok(out.emit("report", Report::Predicted { step, task, tasks, mark }).await?);
            }
            Ok(reading) => {
                self.queued.push_back(reading);
                return self.pump(out).await;
            }
            Err(input) => input,
        };
        let input = match input.into_arc::<Decision>() {
            Ok(decision) if self.replacement => return self.replacement_decision(&decision, out).await,
            Ok(decision) => {
                self.plan(&decision, out).await?;
                self.advance(out).await?;
                return self.pump(out).await;
            }
            Err(input) => input,
        };
        let transfer = input
            .into_arc::<Transfer<M::State, M::Input>>()
            .map_err(|_| "pf.matcher takes readings, decisions, transfers")?;
        let transfer = Arc::try_unwrap(transfer).unwrap_or_else(|shared| Transfer {
            step: shared.step,
            states: shared.states.clone(),
            reading: shared.reading.clone(),
        });
        if self.replacement {
            // A transfer may come before its decision: keep it until then.
            if !matches!(&self.joining, Some((step, _)) if *step == transfer.step) {
                self.early.push(transfer);
                return Ok(());
            }
            self.join_reading = transfer.reading.or(self.join_reading.take());
            self.received.extend(transfer.states.into_iter().map(|(slot, s)| (slot as usize, s)));
            return self.join(out).await;
        }
        self.received.extend(transfer.states.into_iter().map(|(slot, s)| (slot as usize, s)));
        self.advance(out).await?;
        self.pump(out).await
    }

    async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
        if self.pending.is_some() || !self.queued.is_empty() {
            return Err("pf.matcher: the run ended with a reading unfinished".into());
        }
        if let Some(shard) = &mut self.shard {
            // This task's particles' memory, shared map tiles counted once.
            out.gauge("map_bytes", self.model.memory(shard.held().iter().map(|(_, s)| s)));
            // What the best particle learned of the robot: only its holder
            // counts it, so the component's total is that particle's.
            if let Some(best) = shard.state(self.best) {
                for (name, value) in self.model.learned(best) {
                    out.count(name, value);
                }
            }
            shard.keep_only(self.best);
        }
        self.emit_snapshot(out).await
    }
}
