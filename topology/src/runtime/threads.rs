//! Task threads: one OS thread per task (compute never starves the async
//! executor), started for the tasks a host runs and joined at the end, and
//! the one-thread tokio runtime their async code blocks on.

use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::metrics::TaskOutcome;
use crate::plan::{Factory, Topology};
use crate::runtime::RunOptions;
use crate::runtime::control;
use crate::runtime::task::{self, BoltTask, SpoutTask, TaskCommon};
use crate::runtime::wiring::Wiring;

/// The runtime that drives every task's async code (one thread: tasks run
/// on their own threads and only block on it).
pub(crate) fn io_runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("squall-io")
        .enable_all()
        .build()
}

/// A thread per task that `here` says runs in this process (`None` for the
/// others).
pub(crate) type TaskThreads = Vec<Vec<Option<JoinHandle<TaskOutcome>>>>;

/// Starts the threads of the tasks for which `here(component, task)` holds.
pub(crate) fn spawn_tasks(
    topology: &Topology,
    wiring: &mut Wiring,
    options: &RunOptions,
    runtime: &tokio::runtime::Handle,
    events: &mpsc::Sender<control::Event>,
    here: &dyn Fn(usize, usize) -> bool,
) -> std::io::Result<TaskThreads> {
    let mut threads: TaskThreads = Vec::new();
    let live = options.live.as_ref().map(|l| l.attach(topology, &wiring.inboxes));
    for (c, planned) in topology.components.iter().enumerate() {
        let mut handles = Vec::new();
        for t in 0..planned.spec.parallelism {
            if !here(c, t) {
                handles.push(None);
                continue;
            }
            let common = TaskCommon {
                ctx: wiring.context(topology, c, t),
                component: c,
                control: wiring.controls[c][t].clone(),
                emitter: wiring.emitters[c][t].take().expect("each emitter used once"),
                events: events.clone(),
                finished: false,
                live: live.as_ref().map(|slots| slots[c][t].clone()),
                next_detail: Instant::now(),
                detail_stale: false,
            };
            let handle = runtime.clone();
            let params = planned.params.clone();
            let restarts = planned.spec.max_restarts;
            let name = format!("{}#{t}", planned.spec.name);
            let spawned = match &planned.factory {
                Factory::Spout(f) => {
                    let acking =
                        planned.spec.ack.map(|p| (wiring.trackers[c][t].clone().expect("acking"), p));
                    let task = SpoutTask::new(common, acking, options.progress.clone(), options.stop.clone());
                    let f = f.clone();
                    std::thread::Builder::new()
                        .name(name)
                        .spawn(move || task::spout_thread(f, params, task, handle, restarts))
                }
                Factory::Bolt(f) => {
                    let tick = planned.spec.tick.or(planned.declared.tick);
                    let inbox = wiring.inboxes[c][t].clone();
                    // Inputs in file order, then the peer queue: only the
                    // non-feedback inputs wait while the bolt holds them.
                    let mut holdable: Vec<bool> = planned.spec.inputs.iter().map(|i| !i.feedback).collect();
                    holdable.resize(inbox.len(), false);
                    let mut task = BoltTask::new(common, inbox, holdable, tick);
                    task.execute_sample = topology.spec.execute_sample;
                    let f = f.clone();
                    std::thread::Builder::new()
                        .name(name)
                        .spawn(move || task::bolt_thread(f, params, task, handle, restarts))
                }
            };
            handles.push(Some(spawned?));
        }
        threads.push(handles);
    }
    Ok(threads)
}

/// How long, after a failure, joining waits for a task thread that has
/// not yet ended. The coordinator has already waited out the abort's
/// grace for every task to report its exit; a task reports just before
/// its thread returns, so a thread that reported ends within this.
const LAST_STEPS: Duration = Duration::from_millis(500);

/// Joins the task threads. After a failure, threads that have not ended
/// shortly after the abort's grace are left behind and give no outcome.
pub(crate) fn join_tasks(threads: TaskThreads, clean: bool) -> Vec<Vec<Option<TaskOutcome>>> {
    let deadline = Instant::now() + LAST_STEPS;
    let ended = |h: &JoinHandle<TaskOutcome>| {
        while !h.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(1));
        }
        h.is_finished()
    };
    threads
        .into_iter()
        .map(|handles| {
            handles
                .into_iter()
                .map(|h| match h {
                    Some(h) if clean || ended(&h) => Some(h.join().unwrap_or_else(|_| lost_outcome())),
                    Some(_) => Some(lost_outcome()),
                    None => None,
                })
                .collect()
        })
        .collect()
}

/// The outcome of a task whose thread never returned (or whose host was
/// lost): nothing known, and marked so.
pub(crate) fn lost_outcome() -> TaskOutcome {
    TaskOutcome { stats: Default::default(), dropped: 0, undelivered: 0, queue_depth_max: 0, lost: true }
}
