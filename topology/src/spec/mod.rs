//! Topology files: parsing, structural checks and `--set` overrides.
//!
//! The key names here are the file-format contract (see DESIGN.md). Unknown
//! keys are rejected; every problem is reported with its file and line. Checks
//! that need the components themselves (kinds, streams, types) happen in
//! the plan (`Topology::validate`).

mod error;
mod overrides;
mod raw;

use std::path::Path;
use std::time::Duration;

use toml::Spanned;

pub(crate) use error::SourceText;
pub use error::{Role, SpecError, SpecErrors};
pub use overrides::{Misfit, Override, OverrideError};

use crate::declare::DEFAULT_STREAM;
use crate::grouping::{Grouping, OverflowPolicy};
use raw::{RawComponent, RawFile, RawInput};

/// Default bound of an input queue, in tuples.
pub const DEFAULT_QUEUE: usize = 1024;
/// Default bound of a producer's batch to one consumer task: emits are
/// handed over together once this many wait (or sooner, see
/// [`BatchSpec`]).
pub const DEFAULT_BATCH_MAX: usize = 256;
/// The longest a batch may be held back, µs: a second.
pub const MAX_LINGER_US: u64 = 1_000_000;
/// Default sampling of execute times: the first tuple of every batch a
/// task takes and one in this many of the rest are timed alone.
pub const DEFAULT_EXECUTE_SAMPLE: usize = 16;
/// Default acking timeout.
pub const DEFAULT_ACK_TIMEOUT: Duration = Duration::from_secs(30);
/// Default cap on a spout's un-acked tuples.
pub const DEFAULT_MAX_PENDING: usize = 1024;
/// Default replays of one failed tuple before it is abandoned (and counted).
pub const DEFAULT_MAX_RETRIES: u32 = 3;

/// The most tasks one component may have. Each task is a runtime task
/// with its own queues and state; far past the cores of any one machine,
/// and past what a cluster of them runs well, a larger count is a typo.
pub const MAX_PARALLELISM: usize = 1024;
/// The most tasks a topology may have in all.
pub const MAX_TASKS: usize = 4096;
/// The largest input or peer queue, in tuples: a bounded queue reserves
/// its slots when it is made, so a bound past this asks for gigabytes
/// before the first tuple.
pub const MAX_QUEUE: usize = 1 << 20;
/// The most un-acked tuples a spout may keep.
pub const MAX_PENDING: usize = 1 << 20;
/// The longest tick period or ack timeout, seconds (a week): longer ones
/// cannot be timed on every platform's clock ([`crate::bounds::MAX_WAIT_SECS`]).
pub const MAX_PERIOD_SECS: f64 = crate::bounds::MAX_WAIT_SECS;
/// How long a bolt may stay inside one call without progress before the
/// run fails: 5 minutes, a thousand times a slow scan match.
pub const DEFAULT_STALL: Duration = Duration::from_secs(300);
/// The largest topology file read: 1 MiB, hundreds of times the largest
/// real one. Parsing holds several times a file's size in memory (a 20 MB
/// params array took 1.5 GB to refuse); data belongs in files that
/// components read.
pub const MAX_FILE_BYTES: usize = 1 << 20;

/// A number as a person reads it in a message: huge or tiny ones in
/// exponent form (`1e300`), not their three hundred digits.
pub fn readable_number(v: f64) -> String {
    if v != 0.0 && !(1e-6..1e12).contains(&v.abs()) { format!("{v:e}") } else { format!("{v}") }
}

/// A period in seconds, in (0, [`MAX_PERIOD_SECS`]].
fn period(secs: f64) -> Option<Duration> {
    (secs > 0.0 && secs <= MAX_PERIOD_SECS).then(|| Duration::from_secs_f64(secs))
}

/// A parsed, structurally valid topology.
#[derive(Debug, Clone)]
pub struct TopologySpec {
    /// `[topology] name`.
    pub name: String,
    /// `[topology] seed` (default 0).
    pub seed: u64,
    /// `[topology] stall_secs`: a bolt inside one `execute` or `tick`
    /// this long without progress (waits for queue space aside) fails the
    /// run, naming it (default [`DEFAULT_STALL`]).
    pub stall: Duration,
    /// `[topology] memory_limit_mb`, in bytes: the process's resident
    /// memory above it fails the run, naming the limit. `None`: 90% of
    /// what the machine (or its cgroup) allows.
    pub memory_limit: Option<u64>,
    /// `[topology] execute_sample`: the first tuple of every batch a task
    /// takes, and one in this many of the rest, are timed alone for the
    /// execute-latency percentiles (1: every tuple; default
    /// [`DEFAULT_EXECUTE_SAMPLE`]). Busy time is measured over whole
    /// batches either way.
    pub execute_sample: usize,
    /// Spouts then bolts, in file order.
    pub components: Vec<ComponentSpec>,
    pub(crate) source: SourceText,
    /// The text this was parsed from, overrides applied.
    text: std::sync::Arc<str>,
}

/// One `[[spout]]` or `[[bolt]]`.
#[derive(Debug, Clone)]
pub struct ComponentSpec {
    /// Unique name.
    pub name: String,
    /// Registry kind.
    pub kind: String,
    /// Spout or bolt.
    pub role: Role,
    /// Tasks (default 1).
    pub parallelism: usize,
    /// The component's own parameters.
    pub params: toml::Table,
    /// Subscriptions (bolts only).
    pub inputs: Vec<InputSpec>,
    /// `tick_secs`: overrides the component's declared tick.
    pub tick: Option<Duration>,
    /// Restarts allowed after a panic (default 0: a panic fails the run).
    pub max_restarts: u32,
    /// Acking (spouts only; off by default).
    pub ack: Option<AckPolicy>,
    /// Bound of the peer-exchange queue of each task.
    pub peer_queue: usize,
    pub(crate) line: usize,
    pub(crate) params_line: usize,
}

/// One entry of a bolt's `inputs`.
#[derive(Debug, Clone)]
pub struct InputSpec {
    /// Producing component.
    pub from: String,
    /// Stream name (default `"default"`).
    pub stream: String,
    /// Grouping (default shuffle).
    pub grouping: Grouping,
    /// Queue bound per consumer task (default 1024).
    pub queue: usize,
    /// Full-queue policy (default block).
    pub policy: OverflowPolicy,
    /// Whether this edge closes a cycle on purpose.
    pub feedback: bool,
    /// How emits to each consumer task are batched.
    pub batch: BatchSpec,
    pub(crate) line: usize,
}

/// How a producer task batches its emits to one consumer task of an edge
/// (`batch = { max = 256, linger_us = 0 }` on the input).
///
/// Emits wait in the producer's buffer for that task and are handed over
/// together: when `max` of them wait, when the producer has finished the
/// input batch (or `next` call) it emitted them in and they have waited
/// `linger` or longer, when the producer is about to wait (no input, a
/// full queue downstream), on a tick, at `finish` and at shutdown. So with
/// the default `linger_us = 0` a tuple waits at most for the rest of the
/// batch its producer is executing; a busy producer hands over batches as
/// large as the batches it takes, an idle one single tuples. `max = 1`
/// turns batching off: every emit is handed over at once. Queue bounds,
/// drop policies, counters and per-edge order are per tuple either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchSpec {
    /// Most tuples held for one consumer task.
    pub max: usize,
    /// How long a held tuple may wait past the batch it was emitted in.
    pub linger: Duration,
}

impl Default for BatchSpec {
    fn default() -> Self {
        BatchSpec { max: DEFAULT_BATCH_MAX, linger: Duration::ZERO }
    }
}

impl BatchSpec {
    /// Whether emits are handed over one by one.
    pub fn is_off(&self) -> bool {
        self.max <= 1
    }
}

/// At-least-once settings of a spout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AckPolicy {
    /// A tuple tree not completed within this is failed and replayed.
    pub timeout: Duration,
    /// The spout is not polled while this many tuples are un-acked.
    pub max_pending: usize,
    /// Replays of one tuple before it is abandoned.
    pub max_retries: u32,
}

impl ComponentSpec {
    /// The 1-based line of the component in its file.
    pub fn line(&self) -> usize {
        self.line
    }
}

impl InputSpec {
    /// The 1-based line of the subscription in its file.
    pub fn line(&self) -> usize {
        self.line
    }
}

impl TopologySpec {
    /// Reads and parses a topology file, applying `overrides` first.
    pub fn load(path: &Path, overrides: &[Override]) -> Result<Self, SpecErrors> {
        let (file, text) = read_file(path)?;
        Self::parse_with(&file, &text, overrides)
    }

    /// Parses topology text; `file` names it in errors.
    pub fn parse(file: &str, text: &str) -> Result<Self, SpecErrors> {
        Self::parse_with(file, text, &[])
    }

    /// Parses topology text after applying `overrides`.
    pub fn parse_with(file: &str, text: &str, overrides: &[Override]) -> Result<Self, SpecErrors> {
        let (spec, errors) = Self::parse_partial(file, text, overrides)?;
        if errors.is_empty() { Ok(spec) } else { Err(SpecErrors(errors)) }
    }

    /// Parses topology text after applying `overrides`, as far as it
    /// goes: the spec with every component that parsed, and the problems
    /// found (so that validation can add its own and report them all at
    /// once). An error only when there is no spec at all: the text is not
    /// TOML, or an override does not apply.
    pub(crate) fn parse_partial(
        file: &str,
        text: &str,
        overrides: &[Override],
    ) -> Result<(Self, Vec<SpecError>), SpecErrors> {
        if let Some(message) = too_large(text.len() as u64) {
            return Err(SpecErrors(vec![SpecError { file: file.into(), line: 0, component: None, message }]));
        }
        let source = SourceText::new(file, text);
        let edited;
        let text = if overrides.is_empty() {
            text
        } else {
            edited = overrides::apply(text, overrides).map_err(|e| SpecError {
                file: file.into(),
                line: 0,
                component: None,
                message: e.to_string(),
            })?;
            edited.as_str()
        };
        let raw: RawFile = toml::from_str(text).map_err(|e| {
            let line = e.span().map_or(0, |s| source.line(s.start));
            // toml's message says what the value should have been, not
            // whose value it is: the key is the text before `=` on the
            // line of the value.
            let key = e
                .span()
                .and_then(|s| text.get(..s.start))
                .and_then(|before| before.rsplit('\n').next())
                .and_then(|l| l.split_once('='))
                .map(|(k, _)| k.trim().trim_matches('"'))
                .filter(|k| !k.is_empty() && !k.contains(['[', '{', ',']));
            let message = e.message().trim();
            let message = match key {
                Some(key) => format!("{key}: {message}"),
                None => message.to_string(),
            };
            source.error_at_line(line, None, message)
        })?;
        Ok(convert(raw, source, text.into()))
    }

    /// The component called `name`.
    pub fn component(&self, name: &str) -> Option<&ComponentSpec> {
        self.components.iter().find(|c| c.name == name)
    }

    /// The topology's text with every override applied: parsing it again
    /// gives this topology (cluster mode ships it to workers).
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The file the topology came from, as given.
    pub fn file(&self) -> &str {
        &self.source.file
    }
}

/// Why a topology of `size` bytes is refused, if it is larger than
/// [`MAX_FILE_BYTES`].
fn too_large(size: u64) -> Option<String> {
    (size > MAX_FILE_BYTES as u64).then(|| {
        format!("{size} bytes; a topology file is at most {MAX_FILE_BYTES} (large data belongs in a file a component reads)")
    })
}

/// A topology file's name (as errors give it) and text; an error if it
/// cannot be read or is larger than [`MAX_FILE_BYTES`] (checked before
/// reading it).
pub(crate) fn read_file(path: &Path) -> Result<(String, String), SpecErrors> {
    let file = path.display().to_string();
    let error = |message: String| {
        SpecErrors(vec![SpecError { file: file.as_str().into(), line: 0, component: None, message }])
    };
    let size =
        std::fs::metadata(path).map_err(|e| error(format!("cannot read the topology file: {e}")))?.len();
    if let Some(message) = too_large(size) {
        return Err(error(message));
    }
    let text =
        std::fs::read_to_string(path).map_err(|e| error(format!("cannot read the topology file: {e}")))?;
    Ok((file, text))
}

/// The spec of `raw`, with every component that converts, and the
/// problems found.
fn convert(raw: RawFile, source: SourceText, text: std::sync::Arc<str>) -> (TopologySpec, Vec<SpecError>) {
    let mut errors = Vec::new();
    let topology = raw.topology.into_inner();
    let seed = match topology.seed {
        None => 0,
        Some(s) if *s.get_ref() >= 0 => *s.get_ref() as u64,
        Some(s) => {
            errors.push(source.error(s.span().start, None, "seed must be a non-negative integer"));
            0
        }
    };
    let name = topology.name.into_inner();
    let stall = match &topology.stall_secs {
        None => DEFAULT_STALL,
        Some(t) => period(*t.get_ref()).unwrap_or_else(|| {
            let got = readable_number(*t.get_ref());
            errors.push(source.error(
                t.span().start,
                None,
                format!("stall_secs must be in (0, {MAX_PERIOD_SECS}] (a week), got {got}"),
            ));
            DEFAULT_STALL
        }),
    };
    let memory_limit = topology.memory_limit_mb.as_ref().and_then(|m| {
        let mb = *m.get_ref();
        let bytes = u64::try_from(mb).ok().filter(|&mb| mb > 0).and_then(|mb| mb.checked_mul(1 << 20));
        if bytes.is_none() {
            errors.push(source.error(
                m.span().start,
                None,
                format!("memory_limit_mb must be a positive number of MiB, got {mb}"),
            ));
        }
        bytes
    });
    let execute_sample = match &topology.execute_sample {
        None => DEFAULT_EXECUTE_SAMPLE,
        Some(n) => positive(n, "execute_sample", 1 << 20, None, &source, &mut errors).unwrap_or(1),
    };
    if raw.spout.is_empty() {
        errors.push(source.error_at_line(1, None, "a topology needs at least one [[spout]]"));
    }
    let mut components = Vec::new();
    let all =
        raw.spout.into_iter().map(|c| (Role::Spout, c)).chain(raw.bolt.into_iter().map(|c| (Role::Bolt, c)));
    for (role, comp) in all {
        let line = source.line(comp.span().start);
        let comp = comp.into_inner();
        let cname = comp.name.get_ref().clone();
        if let Some(first) = components.iter().find(|c: &&ComponentSpec| c.name == cname) {
            errors.push(source.error(
                comp.name.span().start,
                Some((role, &cname)),
                format!("duplicate component name (first defined at line {})", first.line),
            ));
            continue;
        }
        if let Err(why) = check_name(&cname) {
            errors.push(source.error(comp.name.span().start, Some((role, &cname)), why));
        }
        if let Some(c) = convert_component(role, comp, line, &source, &mut errors) {
            components.push(c);
        }
    }
    let tasks: usize = components.iter().map(|c| c.parallelism).sum();
    if tasks > MAX_TASKS {
        errors.push(source.error_at_line(
            1,
            None,
            format!("the components' parallelism adds up to {tasks} tasks; at most {MAX_TASKS} run in one topology"),
        ));
    }
    (TopologySpec { name, seed, stall, memory_limit, execute_sample, components, source, text }, errors)
}

/// Whether `name` can name a component: `--set NAME.key=value`, metrics
/// keys and cluster addresses all take it as one word. Letters, digits,
/// `_` and `-`, starting with a letter or `_`, not `topology` (the
/// `[topology]` table's own `--set` prefix).
fn check_name(name: &str) -> Result<(), String> {
    let mut chars = name.chars();
    let Some(first) = chars.next() else { return Err("a component name must not be empty".into()) };
    if !(first.is_ascii_alphabetic() || first == '_')
        || !chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Err(format!(
            "component name {name:?} must be letters, digits, '_' and '-', starting with a letter or '_'"
        ));
    }
    if name == "topology" {
        return Err(
            "\"topology\" names the [topology] table (as in --set topology.seed=1); pick another name".into(),
        );
    }
    Ok(())
}

/// An integer setting in [1, `max`]; an error naming it otherwise.
fn positive(
    value: &Spanned<i64>,
    what: &str,
    max: usize,
    at: Option<(Role, &str)>,
    source: &SourceText,
    errors: &mut Vec<SpecError>,
) -> Option<usize> {
    let v = *value.get_ref();
    match usize::try_from(v) {
        Ok(n) if (1..=max).contains(&n) => Some(n),
        _ => {
            errors.push(source.error(
                value.span().start,
                at,
                format!("{what} must be in 1..={max}, got {v}"),
            ));
            None
        }
    }
}

fn convert_component(
    role: Role,
    comp: RawComponent,
    line: usize,
    source: &SourceText,
    errors: &mut Vec<SpecError>,
) -> Option<ComponentSpec> {
    let name = comp.name.into_inner();
    let at = Some((role, name.as_str()));
    let before = errors.len();
    let parallelism = match &comp.parallelism {
        None => 1,
        Some(p) => positive(p, "parallelism", MAX_PARALLELISM, at, source, errors).unwrap_or(1),
    };
    let peer_queue = match &comp.peer_queue {
        None => DEFAULT_QUEUE,
        Some(q) => positive(q, "peer_queue", MAX_QUEUE, at, source, errors).unwrap_or(1),
    };
    let tick = comp.tick_secs.as_ref().and_then(|t| {
        if role == Role::Spout {
            errors.push(source.error(t.span().start, at, "tick_secs is a bolt setting (spouts are polled)"));
            return None;
        }
        let secs = *t.get_ref();
        let tick = period(secs);
        if tick.is_none() {
            errors.push(source.error(
                t.span().start,
                at,
                format!(
                    "tick_secs must be in (0, {MAX_PERIOD_SECS}] (a week), got {}",
                    readable_number(secs)
                ),
            ));
        }
        tick
    });
    let max_restarts = match &comp.restart {
        None => 0,
        Some(r) => u32::try_from(r.get_ref().max_restarts).unwrap_or_else(|_| {
            let found = r.get_ref().max_restarts;
            errors.push(source.error(
                r.span().start,
                at,
                format!("restart.max_restarts must be in 0..={}, got {found}", u32::MAX),
            ));
            0
        }),
    };
    let ack = comp.ack.as_ref().and_then(|a| {
        if role == Role::Bolt {
            errors.push(source.error(a.span().start, at, "ack is a spout setting (bolts ack automatically)"));
            return None;
        }
        let r = a.get_ref();
        let timeout = r.timeout_secs.map_or(Some(DEFAULT_ACK_TIMEOUT), period);
        let max_pending = r.max_pending.map_or(Some(DEFAULT_MAX_PENDING), |p| {
            usize::try_from(p).ok().filter(|p| (1..=MAX_PENDING).contains(p))
        });
        let max_retries = r.max_retries.map_or(Some(DEFAULT_MAX_RETRIES), |p| u32::try_from(p).ok());
        match (timeout, max_pending, max_retries) {
            (Some(timeout), Some(max_pending), Some(max_retries)) => {
                Some(AckPolicy { timeout, max_pending, max_retries })
            }
            _ => {
                errors.push(source.error(
                    a.span().start,
                    at,
                    format!(
                        "ack expects timeout_secs in (0, {MAX_PERIOD_SECS}], max_pending in 1..={MAX_PENDING}, \
                         max_retries in 0..={}",
                        u32::MAX
                    ),
                ));
                None
            }
        }
    });
    let params_line = comp.params.as_ref().map_or(line, |p| source.line(p.span().start));
    let params = comp.params.map(Spanned::into_inner).unwrap_or_default();
    let mut inputs = Vec::new();
    if let Some(raw_inputs) = comp.inputs {
        if role == Role::Spout {
            errors.push(source.error(raw_inputs.span().start, at, "a spout cannot have inputs"));
        } else {
            for input in raw_inputs.into_inner() {
                let line = source.line(input.span().start);
                if let Some(i) = convert_input(input.into_inner(), line, at, source, errors) {
                    inputs.push(i);
                }
            }
        }
    }
    (errors.len() == before).then(|| ComponentSpec {
        name: name.clone(),
        kind: comp.kind.into_inner(),
        role,
        parallelism,
        params,
        inputs,
        tick,
        max_restarts,
        ack,
        peer_queue,
        line,
        params_line,
    })
}

fn convert_input(
    input: RawInput,
    line: usize,
    at: Option<(Role, &str)>,
    source: &SourceText,
    errors: &mut Vec<SpecError>,
) -> Option<InputSpec> {
    let before = errors.len();
    let grouping_name = input.grouping.as_ref().map_or("shuffle", |g| g.get_ref().as_str());
    let grouping_at = input.grouping.as_ref().map_or(line, |g| source.line(g.span().start));
    let grouping = match (grouping_name, &input.fields) {
        ("fields", Some(fields)) if !fields.get_ref().is_empty() => {
            Grouping::Fields(fields.get_ref().clone())
        }
        ("fields", _) => {
            errors.push(source.error_at_line(
                grouping_at,
                at,
                "grouping \"fields\" needs a non-empty `fields = [...]` list",
            ));
            Grouping::Shuffle
        }
        (other, Some(fields)) => {
            errors.push(source.error(
                fields.span().start,
                at,
                format!("`fields` is only valid with grouping \"fields\", not \"{other}\""),
            ));
            Grouping::Shuffle
        }
        ("shuffle", None) => Grouping::Shuffle,
        ("all", None) => Grouping::All,
        ("global", None) => Grouping::Global,
        ("direct", None) => Grouping::Direct,
        ("local_or_shuffle", None) => Grouping::LocalOrShuffle,
        (other, None) => {
            errors.push(source.error_at_line(
                grouping_at,
                at,
                format!("unknown grouping \"{other}\" (expected one of {})", Grouping::NAMES.join(", ")),
            ));
            Grouping::Shuffle
        }
    };
    let policy = match &input.policy {
        None => OverflowPolicy::Block,
        Some(p) => OverflowPolicy::from_name(p.get_ref()).unwrap_or_else(|| {
            errors.push(source.error(
                p.span().start,
                at,
                format!(
                    "unknown queue policy \"{}\" (expected one of {})",
                    p.get_ref(),
                    OverflowPolicy::NAMES.join(", ")
                ),
            ));
            OverflowPolicy::Block
        }),
    };
    let queue = match &input.queue {
        None => DEFAULT_QUEUE,
        Some(q) => positive(q, "queue", MAX_QUEUE, at, source, errors).unwrap_or(1),
    };
    let mut batch = BatchSpec::default();
    if let Some(b) = &input.batch {
        let b = b.get_ref();
        if let Some(max) = &b.max {
            batch.max = positive(max, "batch.max", MAX_QUEUE, at, source, errors).unwrap_or(1);
        }
        if let Some(linger) = &b.linger_us {
            let us = *linger.get_ref();
            match u64::try_from(us) {
                Ok(us) if us <= MAX_LINGER_US => batch.linger = Duration::from_micros(us),
                _ => errors.push(source.error(
                    linger.span().start,
                    at,
                    format!("batch.linger_us must be in 0..={MAX_LINGER_US} (a second), got {us}"),
                )),
            }
        }
    }
    (errors.len() == before).then(|| InputSpec {
        from: input.from.into_inner(),
        stream: input.stream.map_or_else(|| DEFAULT_STREAM.to_string(), Spanned::into_inner),
        grouping,
        queue,
        policy,
        feedback: input.feedback,
        batch,
        line,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[topology]
name = "t"
seed = 7

[[spout]]
name = "src"
kind = "k.src"
params = { count = 10 }

[[bolt]]
name = "b"
kind = "k.bolt"
parallelism = 3
inputs = [ { from = "src", grouping = "fields", fields = ["key"], queue = 8, policy = "drop_oldest" } ]
"#;

    #[test]
    fn batching_is_on_by_default_and_set_per_input() {
        let t = TopologySpec::parse("t.toml", GOOD).unwrap();
        assert_eq!(t.component("b").unwrap().inputs[0].batch, BatchSpec::default());
        assert_eq!(t.execute_sample, DEFAULT_EXECUTE_SAMPLE);
        let set = GOOD.replace("queue = 8", "queue = 8, batch = { max = 32, linger_us = 250 }");
        let t = TopologySpec::parse("t.toml", &set).unwrap();
        let batch = t.component("b").unwrap().inputs[0].batch;
        assert_eq!(batch, BatchSpec { max: 32, linger: Duration::from_micros(250) });
        assert!(!batch.is_off());
        let off = GOOD.replace("queue = 8", "queue = 8, batch = { max = 1 }");
        assert!(
            TopologySpec::parse("t.toml", &off).unwrap().component("b").unwrap().inputs[0].batch.is_off()
        );
        let unknown = GOOD.replace("queue = 8", "queue = 8, batch = { size = 3 }");
        let err = TopologySpec::parse("t.toml", &unknown).unwrap_err().to_string();
        assert!(err.contains("unknown field `size`"), "{err}");
    }

    #[test]
    fn parses_the_contract_keys() {
        let t = TopologySpec::parse("t.toml", GOOD).unwrap();
        assert_eq!(t.name, "t");
        assert_eq!(t.seed, 7);
        let b = t.component("b").unwrap();
        assert_eq!(b.parallelism, 3);
        assert_eq!(b.line, 11);
        let i = &b.inputs[0];
        assert_eq!(i.grouping, Grouping::Fields(vec!["key".into()]));
        assert_eq!((i.queue, i.policy, i.stream.as_str()), (8, OverflowPolicy::DropOldest, "default"));
        assert_eq!(t.component("src").unwrap().params["count"].as_integer(), Some(10));
    }

    #[test]
    fn reports_line_and_component() {
        let bad = GOOD.replace("\"fields\", fields = [\"key\"]", "\"broadcast\"");
        let err = TopologySpec::parse("t.toml", &bad).unwrap_err().to_string();
        assert!(err.starts_with("t.toml:15: bolt \"b\": unknown grouping \"broadcast\""), "{err}");
    }

    #[test]
    fn settings_past_what_can_be_timed_or_held_are_errors_with_their_line() {
        // (replaced text, expected message start); each was accepted, or
        // panicked, or wrapped before.
        let cases = [
            (
                "parallelism = 3",
                "parallelism = 3\ntick_secs = 1e300",
                "t.toml:15: bolt \"b\": tick_secs must be in (0, 604800]",
            ),
            (
                "parallelism = 3",
                "parallelism = 3\ntick_secs = 1e20",
                "t.toml:15: bolt \"b\": tick_secs must be in",
            ),
            (
                "parallelism = 3",
                "parallelism = 1000000001",
                "t.toml:14: bolt \"b\": parallelism must be in 1..=1024",
            ),
            ("queue = 8", "queue = 4000000000", "t.toml:15: bolt \"b\": queue must be in 1..=1048576"),
            (
                "queue = 8",
                "queue = 8, batch = { max = 0 }",
                "t.toml:15: bolt \"b\": batch.max must be in 1..=1048576",
            ),
            (
                "queue = 8",
                "queue = 8, batch = { linger_us = -1 }",
                "t.toml:15: bolt \"b\": batch.linger_us must be in 0..=1000000 (a second), got -1",
            ),
            (
                "queue = 8",
                "queue = 8, batch = { linger_us = 5000000 }",
                "t.toml:15: bolt \"b\": batch.linger_us must be in 0..=1000000",
            ),
            ("seed = 7", "seed = 7\nexecute_sample = 0", "t.toml:5: execute_sample must be in 1..=1048576"),
            (
                "parallelism = 3",
                "parallelism = 3\nrestart = { max_restarts = 4294967296 }",
                "t.toml:15: bolt \"b\": restart.max_restarts must be in 0..=4294967295",
            ),
            (
                "params = { count = 10 }",
                "params = { count = 10 }\nack = { timeout_secs = 1e20 }",
                "t.toml:10: spout \"src\": ack expects timeout_secs in (0, 604800]",
            ),
        ];
        for (from, to, expected) in cases {
            let bad = GOOD.replace(from, to);
            let err = TopologySpec::parse("t.toml", &bad).unwrap_err().to_string();
            assert!(err.starts_with(expected), "{to}: {err}");
        }
        let many = GOOD.replace("parallelism = 3", "parallelism = 1024")
            + "\n[[bolt]]\nname = \"c\"\nkind = \"k\"\nparallelism = 1024\ninputs = [ { from = \"b\" } ]\n"
                .repeat(4)
                .as_str();
        let many = many
            .replacen("name = \"c\"", "name = \"c1\"", 1)
            .replacen("name = \"c\"", "name = \"c2\"", 1)
            .replacen("name = \"c\"", "name = \"c3\"", 1)
            .replacen("name = \"c\"", "name = \"c4\"", 1);
        let err = TopologySpec::parse("t.toml", &many).unwrap_err().to_string();
        assert!(err.contains("adds up to 5121 tasks; at most 4096"), "{err}");
    }

    #[test]
    fn names_that_other_features_cannot_address_are_errors() {
        for (name, expected) in [
            ("", "must not be empty"),
            ("topology", "names the [topology] table"),
            ("a.b", "must be letters, digits"),
            ("9lives", "must be letters, digits"),
        ] {
            let bad = GOOD.replace("name = \"b\"", &format!("name = {name:?}"));
            let err = TopologySpec::parse("t.toml", &bad).unwrap_err().to_string();
            assert!(err.starts_with("t.toml:12:") && err.contains(expected), "{name:?}: {err}");
        }
        let good = GOOD.replace("name = \"b\"", "name = \"_scan-matcher2\"");
        assert!(TopologySpec::parse("t.toml", &good).is_ok());
        // A name near a megabyte long (the most a file holds) is cut in the
        // message, not echoed whole.
        let long = GOOD.replace("name = \"b\"", &format!("name = \"{}\"", ".".repeat(MAX_FILE_BYTES - 1000)));
        let err = TopologySpec::parse("t.toml", &long).unwrap_err().to_string();
        assert!(err.len() < 1200 && err.contains("more bytes)"), "{} bytes: {:.200}", err.len(), err);
    }

    #[test]
    fn a_file_past_the_size_limit_is_refused_before_it_is_parsed() {
        // A 2 MB params array, refused before it is parsed (a 20 MB one
        // took 1.5 GB to parse and refuse).
        let big = format!("{GOOD}\n[x]\nvalues = [{}]\n", "0.5,".repeat(1 << 19));
        let err = TopologySpec::parse("t.toml", &big).unwrap_err().to_string();
        assert!(err.starts_with("t.toml:0: ") && err.contains("a topology file is at most 1048576"), "{err}");
        let dir = std::env::temp_dir().join(format!("squall-spec-size-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("big.toml");
        std::fs::write(&file, &big).unwrap();
        let err = TopologySpec::load(&file, &[]).unwrap_err().to_string();
        assert!(err.contains(&format!("{} bytes; a topology file is at most", big.len())), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn rejects_unknown_keys_with_line() {
        let bad = GOOD.replace("parallelism = 3", "paralelism = 3");
        let err = TopologySpec::parse("t.toml", &bad).unwrap_err().to_string();
        assert!(err.starts_with("t.toml:14:"), "{err}");
        assert!(err.contains("paralelism"), "{err}");
    }
}
