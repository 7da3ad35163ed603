//! A matcher task lost with its process: its particles weigh nothing, it
//! stands in as heard until its replacement reports for itself, the tasks
//! waiting for states it was to send go on without them, and the next
//! decision replaces what was lost.

use squall_core::geometry::Real;
use squall_topology::{BoxError, Emitter};

use super::tasks::{Holding, TaskState, lost_slot_report};
use super::{Deciding, Resampler};
use crate::pf::kinds::messages::Decision;
use crate::pf::shard::SlotReport;

impl Resampler {
    /// A replacement says task `task`'s particles were lost.
    pub(super) async fn lost(
        &mut self,
        task: usize,
        tasks: usize,
        out: &mut Emitter,
    ) -> Result<(), BoxError> {
        if self.tasks != Some(tasks) || task >= tasks || self.population.is_none() {
            return Err(format!("pf.resampler: task {task} of {tasks} lost before the filter started").into());
        }
        self.task_states.resize(tasks, TaskState::default());
        if self.task_states[task].holding != Holding::Share {
            return Ok(());
        }
        self.task_states[task] = TaskState { holding: Holding::StandingIn, replaced: true };
        if self.task_states.iter().all(|s| s.holding != Holding::Share) {
            return Err("pf.resampler: every matcher task lost its particles".into());
        }
        let population = self.population.as_mut().expect("checked");
        self.dead.resize(population.len(), false);
        let mut holes = Vec::new();
        if let Some(Deciding { step, parents, holders }) = &self.deciding {
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
    pub(super) fn count_lost_as_heard(&mut self, tasks: usize) -> bool {
        let in_progress = self.gathered.tasks_heard > 0 || self.deciding.is_some();
        if !in_progress {
            return false;
        }
        if self.gathered.tasks_heard == 0
            && let Some(Deciding { step, .. }) = &self.deciding
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

    /// Before a decision, once a task has been lost: a slot nobody reported
    /// is lost too (a state in flight to or from the lost task), and a task
    /// that reported none of its slots holds nothing (it joins with this
    /// decision).
    pub(super) fn lose_unreported_slots(&mut self, slots: &[SlotReport], out: &mut Emitter) {
        let Some(population) = self.population.as_mut() else { return };
        self.dead.resize(population.len(), false);
        if !self.task_states.iter().any(|s| s.replaced) {
            return;
        }
        let mut reported = vec![false; population.len()];
        for s in slots {
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
            for (t, state) in self.task_states.iter_mut().enumerate() {
                let held = self.task_of.iter().enumerate().filter(|&(_, &h)| h == t);
                if state.holding == Holding::Share
                    && held.clone().count() > 0
                    && held.clone().all(|(slot, _)| !reported[slot])
                {
                    state.holding = Holding::Nothing;
                }
            }
            tracing::warn!("pf.resampler: {newly} more particles were lost after a matcher task was");
        }
    }

    /// Adds a report that weighs nothing for every lost slot no task
    /// reported; `true` if any slot was lost (the decision then resamples
    /// whatever Neff).
    pub(super) fn report_dead_slots(&self, slots: &mut Vec<SlotReport>) -> bool {
        let Some(population) = &self.population else { return false };
        for (slot, _) in self.dead.iter().enumerate().filter(|(_, d)| **d) {
            if slots.iter().all(|s| s.slot != slot) {
                slots.push(lost_slot_report(slot, population.node(slot).pose));
            }
        }
        self.dead.iter().any(|&d| d)
    }
}

#[cfg(test)]
mod tests {
    use super::super::tasks::Gathered;
    use super::super::{Estimate, ModeSettings};
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
            measured: Vec::new(),
            gathered: Gathered::default(),
            modes: ModeSettings { keep: 3, radius: 0.5, turn: 0.5 },
            task_states: vec![TaskState::default(); tasks],
            dead: Vec::new(),
            deciding: Some(Deciding { step, parents: Vec::new(), holders: Vec::new() }),
            done: None,
            estimate: Estimate::Best,
            mode_at: None,
        }
    }

    /// Task `t` lost, its replacement not heard from yet.
    fn standing_in(r: &mut Resampler, t: usize) {
        r.task_states[t] = TaskState { holding: Holding::StandingIn, replaced: true };
    }

    #[test]
    fn a_task_lost_between_a_decision_and_the_first_update_stands_in_for_that_step() {
        let mut r = deciding(4034, 3);
        standing_in(&mut r, 1);
        assert!(!r.count_lost_as_heard(3));
        // The others' updates for the decided step complete it.
        assert!(!r.heard(4034, 0, 3).unwrap());
        assert!(r.heard(4034, 2, 3).unwrap());
        // A report for another step while gathering is still refused.
        let mut r = deciding(7, 3);
        standing_in(&mut r, 0);
        r.count_lost_as_heard(3);
        let wrong = r.heard(8, 1, 3).unwrap_err().to_string();
        assert!(wrong.contains("a report for reading 8 while gathering 7"), "{wrong}");
    }

    #[test]
    fn a_replacement_reporting_for_itself_no_longer_stands_in() {
        let mut r = deciding(3, 2);
        r.deciding = None;
        standing_in(&mut r, 1);
        // Its first own report is taken (it was counted as heard already).
        assert!(!r.heard(4, 1, 2).unwrap());
        assert_eq!(r.task_states[1], TaskState { holding: Holding::Nothing, replaced: true });
        assert!(r.heard(4, 0, 2).unwrap());
        // From then on it must report itself: a second report is refused.
        let twice = r.heard(4, 1, 2).unwrap_err().to_string();
        assert!(twice.contains("task 1 reported twice for reading 4"), "{twice}");
    }
}
