//! One bolt task alone, for unit tests: [`BoltHarness`] drives a bolt as
//! the runtime drives one of its tasks — its own [`TaskContext`] (task
//! index, task count, seed), `prepare` first, tuples from a named
//! component, stream and task or from a peer task, `tick` and `finish` when
//! the test says — and captures what the bolt emits instead of routing it:
//! the stream (or peer), the task it went to where the bolt named one, and
//! the message. Each call runs to completion on the caller's thread; there
//! are no other tasks, queues between them or coordinator.
//!
//! The emitter is the runtime's own, with one unbounded capturing queue per
//! destination, so emits are checked as in a run: an undeclared stream, a
//! wrong type, a peer task out of range or (on a stream made
//! [`direct`](BoltHarness::direct)) a missing task fails the emit.
//!
//! ```
//! use squall_topology::testing::BoltHarness;
//! use squall_topology::{Bolt, BoxError, Declarer, Emitter, Tuple};
//!
//! /// Doubles every number.
//! struct Double;
//!
//! impl Bolt for Double {
//!     fn declare(&self, d: &mut Declarer) {
//!         d.input::<u64>().output::<u64>("doubled");
//!     }
//!
//!     async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
//!         let n = *input.get::<u64>().ok_or("numbers only")?;
//!         out.count("seen", 1);
//!         Ok(out.emit("doubled", 2 * n).await?)
//!     }
//! }
//!
//! let mut h = BoltHarness::new(Double, 0, 1, 42);
//! h.prepare().unwrap();
//! let out = h.execute("numbers", "default", 0, 21_u64).unwrap();
//! assert_eq!(out.on::<u64>("doubled"), [&42]);
//! assert_eq!(h.counter("seen"), Some(1));
//! ```

use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use crate::component::Bolt;
use crate::context::TaskContext;
use crate::declare::Declarer;
use crate::error::{BoxError, ParamError};
use crate::grouping::OverflowPolicy;
use crate::message::{Message, MessageType, Payload};
use crate::metrics::{CustomMetric, summarize_custom};
use crate::params::Params;
use crate::runtime::control::TaskSignal;
use crate::runtime::emitter::{Emitter, PeerRoute, Route, StreamRoute, Subscription};
use crate::runtime::queue::EdgeQueue;
use crate::runtime::target::Target;
use crate::tuple::{Source, Tuple};

/// One message a bolt emitted.
#[derive(Debug, Clone)]
pub struct Emitted {
    /// The stream, or `None` for a message to a peer task.
    pub stream: Option<String>,
    /// The receiving task: the peer task, or the task named on a stream
    /// made [`direct`](BoltHarness::direct); `None` for other emits.
    pub task: Option<usize>,
    /// The message.
    pub payload: Payload,
}

impl Emitted {
    /// The message as `T`, if it is one.
    pub fn get<T: 'static>(&self) -> Option<&T> {
        self.payload.downcast_ref::<T>()
    }

    /// The shared message as `T`, if it is one: to deliver it to another
    /// harness as the runtime would, without a copy.
    pub fn shared<T: Send + Sync + 'static>(&self) -> Option<Arc<T>> {
        self.payload.clone().downcast::<T>().ok()
    }
}

/// What one call of the bolt emitted: grouped by stream in the order the
/// bolt declared them (each stream's by receiving task), then peer
/// messages by receiving task; in the order emitted within each group.
#[derive(Debug, Clone, Default)]
pub struct Emits(pub Vec<Emitted>);

impl Emits {
    /// The messages on `stream`, as `T`. Panics if one is not a `T`.
    pub fn on<T: 'static>(&self, stream: &str) -> Vec<&T> {
        let on_stream = self.0.iter().filter(|e| e.stream.as_deref() == Some(stream));
        on_stream.map(|e| expect::<T>(e, stream)).collect()
    }

    /// The messages sent to peer task `task`, as `T`. Panics if one is not
    /// a `T`.
    pub fn to_peer<T: 'static>(&self, task: usize) -> Vec<&T> {
        let to_task = self.0.iter().filter(|e| e.stream.is_none() && e.task == Some(task));
        to_task.map(|e| expect::<T>(e, "<peer>")).collect()
    }

    /// Whether nothing was emitted.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

fn expect<'a, T: 'static>(e: &'a Emitted, stream: &str) -> &'a T {
    e.get::<T>().unwrap_or_else(|| panic!("a message on {stream} is not a {}", std::any::type_name::<T>()))
}

/// Where one stream's (or the peers') messages are captured: one queue per
/// receiving task.
#[derive(Debug)]
struct Capture {
    stream: Option<String>,
    /// Whether the queue index is the receiving task (direct and peers).
    by_task: bool,
    queues: Vec<Arc<EdgeQueue>>,
}

/// One task of a bolt, driven by a test. See the [module](self) docs.
#[derive(Debug)]
pub struct BoltHarness<B> {
    bolt: B,
    ctx: TaskContext,
    declared: Declarer,
    /// Streams made direct, with their subscriber's task count.
    direct: BTreeMap<String, usize>,
    /// Built by `prepare`.
    emitter: Option<Emitter>,
    captures: Vec<Capture>,
    runtime: tokio::runtime::Runtime,
}

impl<B: Bolt> BoltHarness<B> {
    /// `bolt` as task `task` of `tasks`, in a run with seed `seed`. The
    /// component is called `bolt` and its topology `test`; it is not a
    /// replacement and has no output directory. Call
    /// [`prepare`](Self::prepare) before anything else, as the runtime
    /// does.
    ///
    /// # Panics
    ///
    /// If `task` is not below `tasks`.
    pub fn new(bolt: B, task: usize, tasks: usize, seed: u64) -> Self {
        assert!(task < tasks, "task {task} of {tasks}");
        let mut declared = Declarer::default();
        bolt.declare(&mut declared);
        let ctx = TaskContext {
            topology: "test".into(),
            component: "bolt".into(),
            task_index: task,
            task_count: tasks,
            seed,
            out_dir: None,
            progress: None,
            replacement: false,
            stop: Default::default(),
        };
        let runtime =
            tokio::runtime::Builder::new_current_thread().enable_time().build().expect("a tokio runtime");
        BoltHarness {
            bolt,
            ctx,
            declared,
            direct: BTreeMap::new(),
            emitter: None,
            captures: Vec::new(),
            runtime,
        }
    }

    /// The bolt `factory` builds from `params` (a TOML document: the
    /// component's `params` table) for task `task` of `tasks` with seed
    /// `seed`, as the runtime builds each task's instance.
    pub fn from_factory<F>(
        factory: F,
        params: &str,
        task: usize,
        tasks: usize,
        seed: u64,
    ) -> Result<Self, ParamError>
    where
        F: FnOnce(&Params) -> Result<B, ParamError>,
    {
        let table: toml::Table = params.parse().map_err(|e: toml::de::Error| ParamError::new(e.message()))?;
        let bolt = factory(&Params::new(table, seed, tasks))?;
        Ok(Self::new(bolt, task, tasks, seed))
    }

    /// Names the component (what `TaskContext::component` says). The
    /// default is `bolt`.
    pub fn component(&mut self, name: &str) -> &mut Self {
        self.ctx.component = name.into();
        self
    }

    /// Makes this task a replacement for one lost with its process
    /// (`TaskContext::is_replacement`). The default is not.
    pub fn replacement(&mut self) -> &mut Self {
        self.ctx.replacement = true;
        self
    }

    /// Gives the run an output directory. The default is none.
    pub fn out_dir(&mut self, dir: impl Into<PathBuf>) -> &mut Self {
        self.ctx.out_dir = Some(Arc::new(dir.into()));
        self
    }

    /// Gives `stream` a `direct` subscriber of `tasks` tasks: emits on it
    /// must name a task below `tasks`, which [`Emitted::task`] then holds.
    /// By default a stream has one ordinary subscriber.
    ///
    /// # Panics
    ///
    /// After [`prepare`](Self::prepare).
    pub fn direct(&mut self, stream: &str, tasks: usize) -> &mut Self {
        assert!(self.emitter.is_none(), "make streams direct before prepare");
        self.direct.insert(stream.to_string(), tasks);
        self
    }

    /// What the bolt declared.
    pub fn declared(&self) -> &Declarer {
        &self.declared
    }

    /// The bolt.
    pub fn bolt(&self) -> &B {
        &self.bolt
    }

    /// Wires the emitter (once) and calls the bolt's `prepare`.
    pub fn prepare(&mut self) -> Result<(), BoxError> {
        if self.emitter.is_none() {
            self.wire();
        }
        self.runtime.block_on(self.bolt.prepare(&self.ctx))
    }

    /// Delivers `value` as the runtime delivers a tuple of task `task` of
    /// component `from` on its stream `stream`, and executes it; what the
    /// bolt emitted.
    ///
    /// # Panics
    ///
    /// Before [`prepare`](Self::prepare), or if the bolt does not accept
    /// a `T` (a topology with such an input would not validate).
    pub fn execute<T: Message>(
        &mut self,
        from: &str,
        stream: &str,
        task: usize,
        value: T,
    ) -> Result<Emits, BoxError> {
        self.execute_shared(from, stream, task, Arc::new(value))
    }

    /// [`execute`](Self::execute) with a shared value (as a producer that
    /// forwards without copying sends it).
    pub fn execute_shared<T: Message>(
        &mut self,
        from: &str,
        stream: &str,
        task: usize,
        value: Arc<T>,
    ) -> Result<Emits, BoxError> {
        let t = MessageType::of::<T>();
        assert!(self.declared.accepts.accepts(&t), "the bolt does not accept {}", t.name());
        let source = Source::Stream { component: from.into(), stream: stream.into(), task };
        self.deliver(Tuple { source: source.interned(), payload: value, anchor: None })
    }

    /// Delivers `value` from peer task `task` and executes it.
    ///
    /// # Panics
    ///
    /// Before [`prepare`](Self::prepare), or if `T` is not the bolt's
    /// declared peer type.
    pub fn execute_peer<T: Message>(&mut self, task: usize, value: T) -> Result<Emits, BoxError> {
        self.execute_peer_shared(task, Arc::new(value))
    }

    /// [`execute_peer`](Self::execute_peer) with a shared value (what a
    /// peer's harness emitted, say: [`Emitted::shared`]).
    pub fn execute_peer_shared<T: Message>(&mut self, task: usize, value: Arc<T>) -> Result<Emits, BoxError> {
        let declared = self.declared.peer.is_some_and(|p| p.is::<T>());
        assert!(declared, "the bolt's peers do not send a {}", std::any::type_name::<T>());
        let source = Source::Peer { task }.interned();
        self.deliver(Tuple { source, payload: value, anchor: None })
    }

    /// Calls the bolt's `tick`.
    pub fn tick(&mut self) -> Result<Emits, BoxError> {
        let out = self.emitter.as_mut().expect("call prepare first");
        let result = self.runtime.block_on(self.bolt.tick(out));
        self.emitted(result)
    }

    /// Calls the bolt's `finish` (the runtime's end of the run).
    pub fn finish(&mut self) -> Result<Emits, BoxError> {
        let out = self.emitter.as_mut().expect("call prepare first");
        let result = self.runtime.block_on(self.bolt.finish(out));
        self.emitted(result)
    }

    /// Whether the bolt holds back its inputs (`Emitter::hold_inputs`):
    /// the runtime would then give it only feedback and peer tuples.
    pub fn holding_inputs(&self) -> bool {
        self.emitter.as_ref().is_some_and(|e| e.holding)
    }

    /// Whether the bolt failed the last tuple it executed
    /// (`Emitter::fail`).
    pub fn failed_input(&self) -> bool {
        self.emitter.as_ref().is_some_and(|e| e.input_failed)
    }

    /// The bolt's own metrics so far (`Emitter::count`, `Emitter::record`),
    /// as metrics.json reports a task's.
    pub fn metrics(&self) -> BTreeMap<String, CustomMetric> {
        self.emitter.as_ref().map(|e| summarize_custom(&e.stats.custom)).unwrap_or_default()
    }

    /// The bolt's counter `name`, if it has counted it.
    pub fn counter(&self, name: &str) -> Option<u64> {
        match self.metrics().get(name)? {
            CustomMetric::Counter(c) => Some(*c),
            CustomMetric::Values { .. } | CustomMetric::Gauge(_) | CustomMetric::Measured(_) => None,
        }
    }

    /// The bolt's gauge `name` as last set, if it has set it.
    pub fn gauge(&self, name: &str) -> Option<u64> {
        match self.metrics().get(name)? {
            CustomMetric::Gauge(gauge) => Some(*gauge),
            CustomMetric::Values { .. } | CustomMetric::Counter(_) | CustomMetric::Measured(_) => None,
        }
    }

    /// How many values the bolt recorded in its value metric `name`.
    pub fn recorded(&self, name: &str) -> u64 {
        match self.metrics().get(name) {
            Some(CustomMetric::Values { count, .. }) => *count,
            _ => 0,
        }
    }

    fn deliver(&mut self, tuple: Tuple) -> Result<Emits, BoxError> {
        let out = self.emitter.as_mut().expect("call prepare first");
        out.input_failed = false;
        let result = self.runtime.block_on(self.bolt.execute(tuple, out));
        out.stats.received += 1;
        self.emitted(result)
    }

    /// The emitter, its streams and peers each captured by unbounded
    /// queues.
    fn wire(&mut self) {
        let queue =
            || Arc::new(EdgeQueue::new(usize::MAX, OverflowPolicy::Block, Arc::new(TaskSignal::default())));
        let task = self.ctx.task_index;
        let mut streams = Vec::new();
        for decl in &self.declared.outputs {
            let direct = self.direct.get(&decl.name).copied();
            let queues: Vec<_> = (0..direct.unwrap_or(1)).map(|_| queue()).collect();
            let route = if direct.is_some() { Route::Direct } else { Route::Global };
            let targets = queues.iter().cloned().map(Target::Local).collect();
            let source = Source::Stream {
                component: self.ctx.component.clone(),
                stream: decl.name.as_str().into(),
                task,
            };
            streams.push(StreamRoute {
                name: decl.name.as_str().into(),
                message: decl.message,
                source: source.interned(),
                // Unbatched: the harness sees each emit as it is made.
                subscriptions: vec![Subscription::new(
                    route,
                    targets,
                    0,
                    crate::spec::BatchSpec { max: 1, linger: std::time::Duration::ZERO },
                )],
                has_direct: direct.is_some(),
                held_only: false,
            });
            self.captures.push(Capture {
                stream: Some(decl.name.clone()),
                by_task: direct.is_some(),
                queues,
            });
        }
        let peers = self.declared.peer.map(|message| {
            let queues: Vec<_> = (0..self.ctx.task_count).map(|_| queue()).collect();
            let targets = queues.iter().cloned().map(Target::Local).collect();
            self.captures.push(Capture { stream: None, by_task: true, queues });
            PeerRoute { message, source: Source::Peer { task }.interned(), targets }
        });
        self.emitter = Some(Emitter::new(task, streams, peers, None, Arc::new(AtomicBool::new(false))));
    }

    /// What the call that returned `result` emitted, or its error (what
    /// it emitted before failing is dropped).
    fn emitted(&mut self, result: Result<(), BoxError>) -> Result<Emits, BoxError> {
        let emits = self.drain();
        result.map(|()| emits)
    }

    /// Everything captured since the last call.
    fn drain(&mut self) -> Emits {
        let mut emitted = Vec::new();
        let mut taken = VecDeque::new();
        for c in &self.captures {
            for (i, q) in c.queues.iter().enumerate() {
                let n = q.take(&mut taken, usize::MAX);
                q.release(n);
                emitted.extend(taken.drain(..).map(|t| Emitted {
                    stream: c.stream.clone(),
                    task: c.by_task.then_some(i),
                    payload: t.payload,
                }));
            }
        }
        Emits(emitted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Emitter;

    /// Sends each number to the peer `n % tasks`, and on `direct` to task
    /// `n % 3`; counts ticks; emits how many it saw when it finishes.
    #[derive(Debug, Default)]
    struct Spread {
        seen: u64,
        tasks: usize,
    }

    impl Bolt for Spread {
        fn declare(&self, d: &mut Declarer) {
            d.input::<u64>()
                .peer::<u64>()
                .output::<u64>("direct")
                .output::<String>("log")
                .output::<u64>("seen");
        }

        async fn prepare(&mut self, ctx: &TaskContext) -> Result<(), BoxError> {
            self.tasks = ctx.task_count();
            Ok(())
        }

        async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
            let n = *input.get::<u64>().ok_or("numbers only")?;
            self.seen += 1;
            if input.source_component().is_none() {
                out.emit("log", format!("from peer {}", input.source_task())).await?;
                return Ok(());
            }
            if n == 13 {
                out.fail();
            }
            out.emit("log", format!("{} {}", input.source_component().unwrap(), input.stream().unwrap()))
                .await?;
            out.send_peer(n as usize % self.tasks, n).await?;
            out.emit_direct("direct", n as usize % 3, n).await?;
            out.hold_inputs(n % 2 == 1);
            Ok(())
        }

        async fn tick(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
            out.count("ticks", 1);
            Ok(())
        }

        async fn finish(&mut self, out: &mut Emitter) -> Result<(), BoxError> {
            out.record("seen_at_end", self.seen);
            Ok(out.emit("seen", self.seen).await?)
        }
    }

    #[test]
    fn captures_streams_direct_targets_and_peers_and_reads_metrics() {
        let mut h = BoltHarness::new(Spread::default(), 1, 4, 7);
        h.direct("direct", 3).prepare().unwrap();
        let out = h.execute("numbers", "evens", 2, 5_u64).unwrap();
        assert_eq!(out.on::<String>("log"), ["numbers evens"]);
        assert_eq!(out.to_peer::<u64>(1), [&5]);
        let direct: Vec<_> = out.0.iter().filter(|e| e.stream.as_deref() == Some("direct")).collect();
        assert_eq!((direct.len(), direct[0].task, direct[0].get::<u64>()), (1, Some(2), Some(&5)));
        assert!(h.holding_inputs() && !h.failed_input());
        let out = h.execute("numbers", "odds", 0, 13_u64).unwrap();
        assert_eq!(out.to_peer::<u64>(1), [&13], "13 % 4 tasks");
        assert!(h.failed_input());
        let out = h.execute_peer(3, 8_u64).unwrap();
        assert_eq!(out.on::<String>("log"), ["from peer 3"]);
        assert!(!h.failed_input(), "each tuple starts unfailed");
        assert!(h.tick().unwrap().is_empty());
        assert!(h.tick().unwrap().is_empty());
        assert_eq!(h.counter("ticks"), Some(2));
        assert_eq!(h.finish().unwrap().on::<u64>("seen"), [&3]);
        assert_eq!(h.recorded("seen_at_end"), 1);
        assert_eq!(h.counter("seen_at_end"), None, "a value metric is not a counter");
    }

    #[test]
    fn emits_are_checked_as_in_a_run() {
        let mut h = BoltHarness::new(Spread::default(), 0, 2, 0);
        h.prepare().unwrap();
        // "direct" has an ordinary subscriber here: the task is ignored.
        let out = h.execute("numbers", "default", 0, 4_u64).unwrap();
        assert_eq!(out.0.iter().find(|e| e.stream.as_deref() == Some("direct")).unwrap().task, None);
        let mut h = BoltHarness::new(Spread::default(), 0, 2, 0);
        h.direct("direct", 2).prepare().unwrap();
        let err = h.execute("numbers", "default", 0, 5_u64).unwrap_err().to_string();
        assert_eq!(err, "task 2 does not exist (the component has 2 tasks)");
    }

    #[test]
    fn a_factory_builds_the_bolt_from_params() {
        let factory = |p: &Params| -> Result<Spread, ParamError> {
            let tasks =
                p.table().get("tasks").and_then(|v| v.as_integer()).ok_or(ParamError::new("tasks?"))?;
            assert_eq!((p.seed(), p.parallelism()), (9, 3));
            Ok(Spread { seen: 0, tasks: tasks as usize })
        };
        let h = BoltHarness::from_factory(factory, "tasks = 5", 2, 3, 9).unwrap();
        assert_eq!(h.bolt().tasks, 5);
        let err = BoltHarness::from_factory(factory, "", 0, 3, 9).unwrap_err();
        assert_eq!(err.to_string(), "tasks?");
        assert!(BoltHarness::from_factory(factory, "tasks = ", 0, 3, 9).is_err());
    }
}
