//! What the resampler knows of the matcher tasks: what each holds, and
//! which have been heard for the reading being gathered.

use squall_core::geometry::{Pose2, Real};
use squall_topology::BoxError;

use super::Resampler;
use crate::pf::shard::SlotReport;
use crate::pf::trajectory::MeasuredStep;

/// What one matcher task holds, as the resampler sees it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) enum Holding {
    /// Its share of the particles; it reports for itself.
    #[default]
    Share,
    /// Nothing (its states were lost on their way), until a decision has it
    /// join; it reports for itself.
    Nothing,
    /// Nothing: it was lost, and its replacement has not reported for
    /// itself yet, so it counts as heard for every reading.
    StandingIn,
}

/// One matcher task's state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct TaskState {
    pub(super) holding: Holding,
    /// Whether the task was lost and replaced: its replacement's reports
    /// for readings its stand-in already covered are late, and dropped.
    pub(super) replaced: bool,
}

/// Reports gathered for the current reading.
#[derive(Debug, Default)]
pub(super) struct Gathered {
    pub(super) step: u64,
    pub(super) tasks_heard: usize,
    /// Which tasks have been heard (or stand in as lost).
    pub(super) heard_from: Vec<bool>,
    /// Whether a task corrected (rather than only predicted).
    pub(super) corrected: bool,
    pub(super) slots: Vec<SlotReport>,
    pub(super) busy_us: Vec<u64>,
    pub(super) update_work: u64,
    /// The reading's stamp and odometry.
    pub(super) mark: Option<(f64, Pose2)>,
    /// The model's measurement of the step, from task 0.
    pub(super) measured: Option<MeasuredStep>,
    /// (slot, pose) at the start.
    pub(super) starts: Vec<(usize, Pose2)>,
}

impl Resampler {
    /// Counts a report from a task; `true` once every task has reported.
    pub(super) fn heard(&mut self, step: u64, task: u32, tasks: u32) -> Result<bool, BoxError> {
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
        let first_own = self.task_states.get(task as usize).is_some_and(|s| s.holding == Holding::StandingIn);
        if first_own {
            // The replacement reports for itself from now on.
            self.task_states[task as usize].holding = Holding::Nothing;
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
    pub(super) fn stand_in(&mut self) {
        let g = &mut self.gathered;
        for (t, state) in self.task_states.iter().enumerate() {
            if state.holding == Holding::StandingIn && g.heard_from.get(t) == Some(&false) {
                g.heard_from[t] = true;
                g.tasks_heard += 1;
            }
        }
    }
}

/// A slot report for a slot whose state was lost: it weighs nothing.
pub(super) fn lost_slot_report(slot: usize, pose: Pose2) -> SlotReport {
    let nothing = Real::NEG_INFINITY;
    SlotReport { slot, pose, log_likelihood: nothing, evaluations: 0, bytes: 0, fit: nothing }
}
