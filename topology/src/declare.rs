//! What a component declares about itself: output streams, accepted inputs,
//! a peer message type and a tick period.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use crate::message::{Message, MessageType};

/// The default stream name, used when a subscription names no stream.
pub const DEFAULT_STREAM: &str = "default";

/// One declared output stream.
#[derive(Debug, Clone)]
pub struct StreamDecl {
    /// The stream's name, unique within the component.
    pub name: String,
    /// The one type it carries.
    pub message: MessageType,
}

/// The input types a bolt accepts.
#[derive(Debug, Clone, Default)]
pub enum Accepts {
    /// Only these types.
    #[default]
    Nothing,
    /// Only these types.
    Types(Vec<MessageType>),
    /// Any type (sinks, counters, loggers).
    Any,
}

impl Accepts {
    /// Whether a stream of type `t` may feed this component.
    pub fn accepts(&self, t: &MessageType) -> bool {
        match self {
            Accepts::Nothing => false,
            Accepts::Types(ts) => ts.contains(t),
            Accepts::Any => true,
        }
    }

    /// A readable list for error messages.
    pub fn describe(&self) -> String {
        match self {
            Accepts::Nothing => "no input".to_string(),
            Accepts::Any => "any type".to_string(),
            Accepts::Types(ts) => ts.iter().map(|t| t.name()).collect::<Vec<_>>().join(", "),
        }
    }
}

/// Collects a component's declarations; passed to `declare`.
#[derive(Debug, Clone, Default)]
pub struct Declarer {
    pub(crate) outputs: Vec<StreamDecl>,
    pub(crate) accepts: Accepts,
    pub(crate) peer: Option<MessageType>,
    pub(crate) tick: Option<Duration>,
    pub(crate) reads: Vec<PathBuf>,
    pub(crate) writes: Vec<PathBuf>,
    pub(crate) input_checks: Vec<InputCheck>,
    pub(crate) warnings: Vec<String>,
    pub(crate) exposures: Vec<String>,
}

/// A check of a component's inputs beyond readability (see
/// [`Declarer::check_inputs`]).
#[derive(Clone)]
pub(crate) struct InputCheck(pub(crate) Arc<dyn Fn() -> Result<(), String> + Send + Sync>);

impl std::fmt::Debug for InputCheck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("InputCheck")
    }
}

impl Declarer {
    /// Declares an output stream `name` carrying `T`. Declaring a name twice
    /// keeps the last declaration.
    pub fn output<T: Message>(&mut self, name: &str) -> &mut Self {
        self.outputs.retain(|s| s.name != name);
        self.outputs.push(StreamDecl { name: name.to_string(), message: MessageType::of::<T>() });
        self
    }

    /// Accepts input streams carrying `T` (bolts only).
    pub fn input<T: Message>(&mut self) -> &mut Self {
        let t = MessageType::of::<T>();
        match &mut self.accepts {
            Accepts::Types(ts) => {
                if !ts.contains(&t) {
                    ts.push(t);
                }
            }
            Accepts::Nothing => self.accepts = Accepts::Types(vec![t]),
            Accepts::Any => {}
        }
        self
    }

    /// Accepts input streams of any type (bolts only).
    pub fn any_input(&mut self) -> &mut Self {
        self.accepts = Accepts::Any;
        self
    }

    /// Declares the type tasks of this component send each other by index
    /// (peer exchange).
    pub fn peer<T: Message>(&mut self) -> &mut Self {
        self.peer_message(MessageType::of::<T>())
    }

    /// Declares the peer message type by its description (for a type that
    /// crosses processes incrementally: [`MessageType::incremental`]).
    pub fn peer_message(&mut self, message: MessageType) -> &mut Self {
        self.peer = Some(message);
        self
    }

    /// Declares a file or folder this component reads (a log, a bag, a
    /// map). A run in this process checks it can be read before any task
    /// starts ([`crate::Topology::unreadable_inputs`]): a missing file is
    /// invalid input, reported with the rest, not a run that fails later.
    pub fn reads(&mut self, path: impl Into<PathBuf>) -> &mut Self {
        self.reads.push(path.into());
        self
    }

    /// Declares a file or folder this component writes outside the run's
    /// output folder (a cache). A confined worker refuses a plan whose
    /// components write outside its `--out` before any task starts
    /// ([`crate::confine`]).
    pub fn writes(&mut self, path: impl Into<PathBuf>) -> &mut Self {
        self.writes.push(path.into());
        self
    }

    /// Declares a check of what this component reads beyond being readable
    /// (a bag's storage and topics): run where the files are, with the
    /// readability checks, before a run in this process starts, once every
    /// file the component [`reads`](Self::reads) can be read. An `Err` is
    /// invalid input, reported at the component's params.
    pub fn check_inputs(
        &mut self,
        check: impl Fn() -> Result<(), String> + Send + Sync + 'static,
    ) -> &mut Self {
        self.input_checks.push(InputCheck(Arc::new(check)));
        self
    }

    /// Declares a warning about how this component is configured (a
    /// network link without authentication, say): logged when a run
    /// starts and listed in the run's `warnings` in metrics.json.
    pub fn warn(&mut self, message: impl Into<String>) -> &mut Self {
        self.warnings.push(message.into());
        self
    }

    /// Declares that this component talks over the network beyond
    /// loopback without authentication (`what` says where: a live link
    /// on plain `tcp/` allowed by `insecure = true`). It is warned of as
    /// [`warn`](Self::warn) does, and a worker hosts such a component
    /// only if it was itself started with `--insecure`.
    pub fn exposes(&mut self, what: impl Into<String>) -> &mut Self {
        let what = what.into();
        self.warnings.push(what.clone());
        self.exposures.push(what);
        self
    }

    /// Asks for a tick every `period`. A topology file's `tick_secs`
    /// overrides it.
    pub fn tick(&mut self, period: Duration) -> &mut Self {
        self.tick = Some(period);
        self
    }

    /// The declared output streams.
    pub fn outputs(&self) -> &[StreamDecl] {
        &self.outputs
    }

    /// The accepted input types.
    pub fn accepts(&self) -> &Accepts {
        &self.accepts
    }

    /// The declared peer type, if any.
    pub fn peer_type(&self) -> Option<MessageType> {
        self.peer
    }

    /// The stream called `name`, if declared.
    pub fn stream(&self, name: &str) -> Option<&StreamDecl> {
        self.outputs.iter().find(|s| s.name == name)
    }
}
