//! Validation: a [`TopologySpec`] checked against a [`Registry`] becomes a
//! runnable [`Topology`].
//!
//! Everything that can be known before running is checked here and reported
//! together, each with file, line and component: unknown kinds, bad params,
//! unknown components and streams, stream/input type mismatches, grouping
//! fields missing from the stream's type, and cycles not marked `feedback`.

use std::path::Path;

use crate::declare::Declarer;
use crate::grouping::Grouping;
use crate::params::Params;
use crate::registry::{BoltFactory, Registry, SpoutFactory};
use crate::spec::{ComponentSpec, Override, Role, SpecError, SpecErrors, TopologySpec};

/// A validated topology, ready to run.
#[derive(Debug, Clone)]
pub struct Topology {
    pub(crate) spec: TopologySpec,
    pub(crate) components: Vec<Planned>,
    /// Component indices in dependency order (feedback edges ignored).
    pub(crate) order: Vec<usize>,
}

#[derive(Clone)]
pub(crate) enum Factory {
    Spout(SpoutFactory),
    Bolt(BoltFactory),
}

impl std::fmt::Debug for Factory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Factory::Spout(_) => "SpoutFactory",
            Factory::Bolt(_) => "BoltFactory",
        })
    }
}

/// One component with what it declared.
#[derive(Debug, Clone)]
pub(crate) struct Planned {
    pub(crate) spec: ComponentSpec,
    pub(crate) declared: Declarer,
    pub(crate) factory: Factory,
    pub(crate) params: Params,
}

impl Topology {
    /// Reads a topology file, applies `overrides`, and checks it against
    /// the kinds in `registry`, reporting the problems of every stage at
    /// once: the file's own (settings, names, groupings) and those of each
    /// component's params. Only a file that is not TOML stops at the first.
    pub fn load(path: &Path, overrides: &[Override], registry: &Registry) -> Result<Self, SpecErrors> {
        let (file, text) = crate::spec::read_file(path)?;
        Self::from_text(&file, &text, overrides, registry)
    }

    /// [`Topology::load`] on text already read; `file` names it in errors.
    pub fn from_text(
        file: &str,
        text: &str,
        overrides: &[Override],
        registry: &Registry,
    ) -> Result<Self, SpecErrors> {
        let (spec, errors) = TopologySpec::parse_partial(file, text, overrides)?;
        Self::validate_after(spec, errors, registry)
    }

    /// Checks `spec` against the kinds in `registry`.
    pub fn validate(spec: TopologySpec, registry: &Registry) -> Result<Self, SpecErrors> {
        Self::validate_after(spec, Vec::new(), registry)
    }

    /// Checks `spec`, which parsing found `errors` in, against the kinds
    /// in `registry`: the params of every component that parsed are
    /// checked whatever the errors; the wiring only when there are none
    /// (a component dropped for its errors would look like a missing one).
    fn validate_after(
        spec: TopologySpec,
        mut errors: Vec<SpecError>,
        registry: &Registry,
    ) -> Result<Self, SpecErrors> {
        let mut components = Vec::new();
        // Read once: the machine's memory, unless the topology sets a limit.
        let budget = crate::bounds::MemoryBudget::for_run(spec.memory_limit);
        for c in &spec.components {
            if let Some(p) = instantiate(&spec, c, registry, budget, &mut errors) {
                components.push(p);
            }
        }
        if errors.is_empty() {
            check_inputs(&spec, &components, &mut errors);
        }
        let order = if errors.is_empty() { order_or_cycle(&spec, &components, &mut errors) } else { vec![] };
        if errors.is_empty() {
            Ok(Topology { spec, components, order })
        } else {
            // In the file's order, whichever stage found them.
            errors.sort_by_key(|e| e.line);
            Err(SpecErrors(errors))
        }
    }

    /// The files and folders the components declared they read
    /// ([`Declarer::reads`]) that cannot be read here, and what their
    /// input checks ([`Declarer::check_inputs`]) refuse, each an error at
    /// its component's params. What a run in this process checks before
    /// it starts, so that a missing log is invalid input, not a failed
    /// run. (Validation does not: a cluster's coordinator validates
    /// topologies whose files live on its workers.)
    pub fn unreadable_inputs(&self) -> Vec<SpecError> {
        let mut errors = Vec::new();
        for c in &self.components {
            let at = Some((c.spec.role, c.spec.name.as_str()));
            let before = errors.len();
            for path in &c.declared.reads {
                if let Err(e) = crate::fsio::check_readable(path) {
                    let message = format!("cannot read {}: {e}", path.display());
                    errors.push(self.spec.source.error_at_line(c.spec.params_line, at, message));
                }
            }
            if errors.len() == before {
                for check in &c.declared.input_checks {
                    if let Err(message) = (check.0)() {
                        errors.push(self.spec.source.error_at_line(c.spec.params_line, at, message));
                    }
                }
            }
        }
        errors
    }

    /// The paths the components of `hosted` (by index) declared they read
    /// or write ([`Declarer::reads`], [`Declarer::writes`]) that
    /// `policy` does not allow, each an error at its component's params:
    /// what a confined worker checks before any task starts.
    pub fn confinement_errors(
        &self,
        policy: &crate::confine::Confinement,
        hosted: impl Fn(usize) -> bool,
    ) -> Vec<SpecError> {
        let mut errors = Vec::new();
        for (_, c) in self.components.iter().enumerate().filter(|(i, _)| hosted(*i)) {
            let at = Some((c.spec.role, c.spec.name.as_str()));
            let refusals = c.declared.reads.iter().map(|p| policy.check_read(p));
            let refusals = refusals.chain(c.declared.writes.iter().map(|p| policy.check_write(p)));
            for refused in refusals.filter_map(Result::err) {
                errors.push(self.spec.source.error_at_line(c.spec.params_line, at, refused.to_string()));
            }
        }
        errors
    }

    /// What the components of `hosted` (by index) declared they expose
    /// ([`Declarer::exposes`]), each naming its component.
    pub fn exposures(&self, hosted: impl Fn(usize) -> bool) -> Vec<String> {
        let mut exposures = Vec::new();
        for (_, c) in self.components.iter().enumerate().filter(|(i, _)| hosted(*i)) {
            let (role, name) = (c.spec.role, &c.spec.name);
            exposures.extend(c.declared.exposures.iter().map(|w| format!("{role} \"{name}\": {w}")));
        }
        exposures
    }

    /// The warnings the components declared ([`Declarer::warn`]), each
    /// naming its component.
    pub fn declared_warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        for c in &self.components {
            let (role, name) = (c.spec.role, &c.spec.name);
            warnings.extend(c.declared.warnings.iter().map(|w| format!("{role} \"{name}\": {w}")));
        }
        warnings
    }

    /// The topology's name.
    pub fn name(&self) -> &str {
        &self.spec.name
    }

    /// The run seed.
    pub fn seed(&self) -> u64 {
        self.spec.seed
    }

    /// The parsed specification.
    pub fn spec(&self) -> &TopologySpec {
        &self.spec
    }

    /// What the component called `name` declared.
    pub fn declared(&self, name: &str) -> Option<&Declarer> {
        self.components.iter().find(|c| c.spec.name == name).map(|c| &c.declared)
    }
}

fn instantiate(
    spec: &TopologySpec,
    c: &ComponentSpec,
    registry: &Registry,
    budget: crate::bounds::MemoryBudget,
    errors: &mut Vec<SpecError>,
) -> Option<Planned> {
    let at = Some((c.role, c.name.as_str()));
    let params = Params::new(c.params.clone(), spec.seed, c.parallelism).with_budget(budget);
    let mut declared = Declarer::default();
    let factory = match c.role {
        Role::Spout => registry.spout(&c.kind).map(|f| Factory::Spout(f.clone())),
        Role::Bolt => registry.bolt(&c.kind).map(|f| Factory::Bolt(f.clone())),
    };
    let Some(factory) = factory else {
        let known: Vec<&str> = match c.role {
            Role::Spout => registry.spout_kinds().collect(),
            Role::Bolt => registry.bolt_kinds().collect(),
        };
        let message = match registry.feature_for(&c.kind) {
            Some(feature) => format!(
                "{} kind \"{}\" is not in this build: rebuild squall with `--features {feature}` \
                 (e.g. `cargo install --path . --features {feature}`)",
                c.role, c.kind
            ),
            None => format!("unknown {} kind \"{}\" (known: {})", c.role, c.kind, known.join(", ")),
        };
        errors.push(spec.source.error_at_line(c.line, at, message));
        return None;
    };
    let built = match &factory {
        Factory::Spout(f) => f(&params).map(|s| s.declare(&mut declared)),
        Factory::Bolt(f) => f(&params).map(|b| b.declare(&mut declared)),
    };
    if let Err(e) = built {
        errors.push(spec.source.error_at_line(
            c.params_line,
            at,
            format!("bad params for kind \"{}\": {e}", c.kind),
        ));
        return None;
    }
    if c.role == Role::Bolt && c.inputs.is_empty() {
        errors.push(spec.source.error_at_line(c.line, at, "a bolt needs at least one entry in `inputs`"));
    }
    Some(Planned { spec: c.clone(), declared, factory, params })
}

fn check_inputs(spec: &TopologySpec, components: &[Planned], errors: &mut Vec<SpecError>) {
    let names: Vec<&str> = components.iter().map(|c| c.spec.name.as_str()).collect();
    for consumer in components {
        let at = Some((consumer.spec.role, consumer.spec.name.as_str()));
        for input in &consumer.spec.inputs {
            let error = |message: String| spec.source.error_at_line(input.line, at, message);
            let Some(producer) = components.iter().find(|p| p.spec.name == input.from) else {
                errors.push(error(format!(
                    "input from unknown component \"{}\" (components: {})",
                    input.from,
                    names.join(", ")
                )));
                continue;
            };
            let Some(stream) = producer.declared.stream(&input.stream) else {
                let streams: Vec<&str> =
                    producer.declared.outputs().iter().map(|s| s.name.as_str()).collect();
                errors.push(error(format!(
                    "{} \"{}\" has no stream \"{}\" (it declares: {})",
                    producer.spec.role,
                    producer.spec.name,
                    input.stream,
                    if streams.is_empty() { "none".to_string() } else { streams.join(", ") }
                )));
                continue;
            };
            if !consumer.declared.accepts().accepts(&stream.message) {
                errors.push(error(format!(
                    "stream type mismatch: {} \"{}\" stream \"{}\" carries {}, but {} \"{}\" accepts {}",
                    producer.spec.role,
                    producer.spec.name,
                    stream.name,
                    stream.message.name(),
                    consumer.spec.role,
                    consumer.spec.name,
                    consumer.declared.accepts().describe()
                )));
            }
            if let Grouping::Fields(fields) = &input.grouping {
                for f in fields {
                    if !stream.message.has_field(f) {
                        let available =
                            stream.message.fields().map_or("it has no named fields".to_string(), |fs| {
                                format!("fields: {}", fs.join(", "))
                            });
                        errors.push(error(format!(
                            "grouping field \"{f}\" is not a field of {} on stream \"{}\" ({available})",
                            stream.message.name(),
                            stream.name
                        )));
                    }
                }
            }
        }
    }
}

/// Kahn's algorithm over non-feedback edges (stable in file order); on a
/// cycle, reports it at the line of an edge that closes it.
fn order_or_cycle(spec: &TopologySpec, components: &[Planned], errors: &mut Vec<SpecError>) -> Vec<usize> {
    let n = components.len();
    let index = |name: &str| components.iter().position(|c| c.spec.name == name).expect("checked");
    let mut indegree = vec![0usize; n];
    let mut downstream: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (to, c) in components.iter().enumerate() {
        for input in c.spec.inputs.iter().filter(|i| !i.feedback) {
            let from = index(&input.from);
            downstream[from].push(to);
            indegree[to] += 1;
        }
    }
    let mut order = Vec::with_capacity(n);
    let mut ready: Vec<usize> = (0..n).filter(|&i| indegree[i] == 0).collect();
    while let Some(i) = ready.iter().copied().min() {
        ready.retain(|&r| r != i);
        order.push(i);
        for &d in &downstream[i] {
            indegree[d] -= 1;
            if indegree[d] == 0 {
                ready.push(d);
            }
        }
    }
    if order.len() == n {
        return order;
    }
    // Some component is on a cycle: walk back through unresolved inputs.
    let stuck: Vec<bool> = (0..n).map(|i| !order.contains(&i)).collect();
    let start = stuck.iter().position(|&s| s).expect("a stuck component");
    let mut path = vec![start];
    let mut current = start;
    loop {
        let c = &components[current];
        let input = c
            .spec
            .inputs
            .iter()
            .find(|i| !i.feedback && stuck[index(&i.from)])
            .expect("a stuck component has a stuck input");
        let prev = index(&input.from);
        if let Some(pos) = path.iter().position(|&p| p == prev) {
            // path[pos..] walks upstream; reversed it is the cycle in flow order.
            let cycle: Vec<usize> = path[pos..].iter().rev().copied().collect();
            errors.push(cycle_error(spec, components, &cycle));
            return order;
        }
        path.push(prev);
        current = prev;
    }
}

/// Reports a cycle (components in flow order) at the edge a user would mark:
/// one that goes backwards in file order, printed last.
fn cycle_error(spec: &TopologySpec, components: &[Planned], cycle: &[usize]) -> SpecError {
    let m = cycle.len();
    let back = (0..m).find(|&k| cycle[k] >= cycle[(k + 1) % m]).unwrap_or(m - 1);
    let (from, to) = (cycle[back], cycle[(back + 1) % m]);
    let names: Vec<&str> =
        (0..=m).map(|i| components[cycle[(back + 1 + i) % m]].spec.name.as_str()).collect();
    let target = &components[to].spec;
    let line = target
        .inputs
        .iter()
        .find(|i| !i.feedback && i.from == components[from].spec.name)
        .map_or(target.line, |i| i.line);
    spec.source.error_at_line(
        line,
        Some((target.role, target.name.as_str())),
        format!(
            "undeclared cycle {}: mark the edge that closes it with `feedback = true`",
            names.join(" -> ")
        ),
    )
}
