//! K parfil matcher tasks and the resampler, wired as the runtime wires
//! them (every report to the resampler, every decision to every matcher
//! task, each transfer to its peer), one tuple at a time in a fixed order.
//! Reports and decisions wait until [`Filter::settle`] or
//! [`Filter::deliver_reports`] delivers them, so a test can step in
//! between: lose a task after a decision, say.

use std::collections::VecDeque;
use std::sync::Arc;

use squall_bolts::parfil::{ParfilModel, ParfilReading};
use squall_bolts::pf::kinds::matcher::Matcher;
use squall_bolts::pf::kinds::messages::{Decision, Reading, Ready, Report, Transfer};
use squall_bolts::pf::kinds::resampler::Resampler;
use squall_core::geometry::Pose2;
use squall_topology::testing::{BoltHarness, Emits};

use super::SEED;

/// A matcher task for parfil.
pub(crate) type ParfilMatcher = BoltHarness<Matcher<ParfilModel>>;
/// What parfil matcher tasks send each other.
pub(crate) type ParfilTransfer = Transfer<Pose2, ParfilReading>;

/// Matcher task `task` of `tasks` with `particles`, prepared; a
/// replacement for a lost one if `replacement`.
pub(crate) fn matcher(particles: usize, task: usize, tasks: usize, replacement: bool) -> ParfilMatcher {
    let params = format!("model = \"parfil\"\nparticles = {particles}");
    let mut h = BoltHarness::from_factory(Matcher::from_params, &params, task, tasks, SEED).unwrap();
    h.component("matcher");
    if replacement {
        h.replacement();
    }
    h.prepare().unwrap();
    h
}

/// The filter's matcher tasks and resampler.
pub(crate) struct Filter {
    particles: usize,
    pub(crate) matchers: Vec<ParfilMatcher>,
    pub(crate) resampler: BoltHarness<Resampler>,
    /// Reports on their way to the resampler, with their task.
    reports: VecDeque<(usize, Report)>,
    /// Decisions on their way, with the tasks still to get them.
    decisions: VecDeque<(Decision, Vec<usize>)>,
    /// Everything the resampler emitted on `decision` and `ready`.
    pub(crate) decided: Vec<Decision>,
    pub(crate) ready: Vec<Ready>,
    /// Every report the matchers emitted, with their task.
    pub(crate) reported: Vec<(usize, Report)>,
}

impl Filter {
    pub(crate) fn new(particles: usize, tasks: usize) -> Self {
        let mut resampler =
            BoltHarness::from_factory(Resampler::from_params, "model = \"parfil\"", 0, 1, SEED).unwrap();
        resampler.prepare().unwrap();
        Filter {
            particles,
            matchers: (0..tasks).map(|t| matcher(particles, t, tasks, false)).collect(),
            resampler,
            reports: VecDeque::new(),
            decisions: VecDeque::new(),
            decided: Vec::new(),
            ready: Vec::new(),
            reported: Vec::new(),
        }
    }

    /// Hands reading `step` to every matcher task (the dispatcher's `all`
    /// grouping: one shared reading).
    pub(crate) fn reading(&mut self, step: u64, input: &Arc<ParfilReading>) {
        let reading = Arc::new(Reading { step, input: input.clone() });
        for t in 0..self.matchers.len() {
            let out = self.matchers[t].execute_shared("dispatcher", "reading", 0, reading.clone());
            let out = out.unwrap_or_else(|e| panic!("matcher {t}, reading {step}: {e}"));
            self.route(t, out);
        }
    }

    /// Delivers everything on its way, decisions first, until nothing is.
    pub(crate) fn settle(&mut self) {
        loop {
            if let Some((decision, to)) = self.decisions.pop_front() {
                for t in to {
                    let out = self.matchers[t].execute("resampler", "decision", 0, decision.clone());
                    let out = out.unwrap_or_else(|e| panic!("matcher {t}, {decision:?}: {e}"));
                    self.route(t, out);
                }
            } else if !self.reports.is_empty() {
                self.deliver_reports();
            } else {
                return;
            }
        }
    }

    /// Delivers the reports on their way (not the decisions they lead to).
    pub(crate) fn deliver_reports(&mut self) {
        while let Some((task, report)) = self.reports.pop_front() {
            let out = self.resampler.execute("matcher", "report", task, report.clone());
            let out = out.unwrap_or_else(|e| panic!("resampler, {report:?} from task {task}: {e}"));
            for d in out.on::<Decision>("decision") {
                self.decided.push(d.clone());
                self.decisions.push_back((d.clone(), (0..self.matchers.len()).collect()));
            }
            self.ready.extend(out.on::<Ready>("ready").into_iter().copied());
        }
    }

    /// Loses matcher task `task` with its process: what was on its way to
    /// it is gone, and a replacement that holds nothing takes its place
    /// and says so on its first tick.
    pub(crate) fn lose(&mut self, task: usize) {
        for (_, to) in &mut self.decisions {
            to.retain(|&t| t != task);
        }
        let tasks = self.matchers.len();
        self.matchers[task] = matcher(self.particles, task, tasks, true);
        let out = self.matchers[task].tick().unwrap();
        assert_eq!(out.on::<Report>("report"), [&Report::Lost { task: task as u32, tasks: tasks as u32 }]);
        self.route(task, out);
    }

    /// Routes what matcher task `from` emitted: transfers to their peers
    /// at once, reports onto the resampler's queue.
    fn route(&mut self, from: usize, out: Emits) {
        for r in out.on::<Report>("report") {
            self.reported.push((from, r.clone()));
            self.reports.push_back((from, r.clone()));
        }
        for e in out.0.iter().filter(|e| e.stream.is_none()) {
            let (to, transfer) = (e.task.unwrap(), e.shared::<ParfilTransfer>().unwrap());
            let step = transfer.step;
            let out = self.matchers[to].execute_peer_shared(from, transfer);
            let out = out.unwrap_or_else(|e| panic!("matcher {to}, transfer for {step} from {from}: {e}"));
            self.route(to, out);
        }
    }

    /// The reports the matchers emitted for reading `step`, by task.
    pub(crate) fn reports_for(&self, step: u64) -> Vec<(usize, &Report)> {
        let for_step = |r: &Report| match r {
            Report::Started { .. } => step == 0,
            other => other.step_and_task().is_some_and(|(s, _)| s == step),
        };
        self.reported.iter().filter(|(_, r)| for_step(r)).map(|(t, r)| (*t, r)).collect()
    }
}
