//! Component kinds by name: how a topology file's `kind = "..."` becomes a
//! running component.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

use crate::component::{Bolt, Spout};
use crate::error::ParamError;
use crate::params::Params;
use crate::runtime::erased::{BoltRunner, SpoutRunner};

pub(crate) type SpoutFactory = Arc<dyn Fn(&Params) -> Result<Box<dyn SpoutRunner>, ParamError> + Send + Sync>;
pub(crate) type BoltFactory = Arc<dyn Fn(&Params) -> Result<Box<dyn BoltRunner>, ParamError> + Send + Sync>;

/// Maps kind names to component factories.
///
/// A factory builds one instance per task from the component's `params`; it
/// should only check and store parameters (heavy loading belongs in
/// `open`/`prepare`, which run on the task's own thread). It is also called
/// once during validation, so that bad parameters are reported with the
/// file and line before anything runs.
#[derive(Clone, Default)]
pub struct Registry {
    spouts: BTreeMap<String, SpoutFactory>,
    bolts: BTreeMap<String, BoltFactory>,
    /// Bolt kinds with variants, by kind (see
    /// [`Registry::register_bolt_variant`]).
    families: BTreeMap<String, Family>,
    /// Kinds this build leaves out, with the Cargo feature that brings
    /// them (see [`Registry::compiled_out`]).
    missing: BTreeMap<String, String>,
}

/// The variants of one bolt kind, chosen by a string parameter, in the
/// order they were registered.
#[derive(Clone)]
struct Family {
    selector: String,
    variants: Vec<(String, BoltFactory)>,
}

impl Family {
    /// The factory that reads the selector and builds that variant.
    fn factory(self) -> BoltFactory {
        Arc::new(move |p: &Params| {
            let names = || self.variants.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>().join(", ");
            let selector = &self.selector;
            let name =
                p.table().get(selector).and_then(|v| v.as_str()).ok_or_else(|| {
                    ParamError::new(format!("`{selector}` is required: one of {}", names()))
                })?;
            let (_, factory) = self.variants.iter().find(|(n, _)| n == name).ok_or_else(|| {
                ParamError::new(format!("unknown {selector} \"{name}\": one of {}", names()))
            })?;
            factory(p)
        })
    }
}

impl fmt::Debug for Registry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Registry")
            .field("spouts", &self.spouts.keys().collect::<Vec<_>>())
            .field("bolts", &self.bolts.keys().collect::<Vec<_>>())
            .finish()
    }
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers a spout kind. A later registration of the same name
    /// replaces the earlier one.
    pub fn register_spout<S, F>(&mut self, kind: &str, factory: F) -> &mut Self
    where
        S: Spout,
        F: Fn(&Params) -> Result<S, ParamError> + Send + Sync + 'static,
    {
        let erased: SpoutFactory = Arc::new(move |p| factory(p).map(|s| Box::new(s) as Box<dyn SpoutRunner>));
        self.spouts.insert(kind.to_string(), erased);
        self
    }

    /// Registers a bolt kind. A later registration of the same name replaces
    /// the earlier one.
    pub fn register_bolt<B, F>(&mut self, kind: &str, factory: F) -> &mut Self
    where
        B: Bolt,
        F: Fn(&Params) -> Result<B, ParamError> + Send + Sync + 'static,
    {
        self.families.remove(kind);
        self.bolts.insert(kind.to_string(), erase_bolt(factory));
        self
    }

    /// Registers one variant of a bolt kind whose implementation the string
    /// parameter `selector` chooses: a component of kind `kind` with
    /// `selector = "variant"` is built by `factory` (which sees the
    /// selector among its params). Lets one kind serve several models
    /// (`kind = "pf.matcher"`, `model = "slam"`) while the kind's code
    /// names none of them. A missing or unknown selector is a parameter
    /// error listing the variants in the order they were registered. A
    /// later registration of the same variant replaces the earlier one; a
    /// plain [`Registry::register_bolt`] of the kind replaces them all.
    pub fn register_bolt_variant<B, F>(
        &mut self,
        kind: &str,
        selector: &str,
        variant: &str,
        factory: F,
    ) -> &mut Self
    where
        B: Bolt,
        F: Fn(&Params) -> Result<B, ParamError> + Send + Sync + 'static,
    {
        let family = self
            .families
            .entry(kind.to_string())
            .or_insert_with(|| Family { selector: selector.to_string(), variants: Vec::new() });
        family.selector = selector.to_string();
        let erased = erase_bolt(factory);
        match family.variants.iter_mut().find(|(n, _)| n == variant) {
            Some(slot) => slot.1 = erased,
            None => family.variants.push((variant.to_string(), erased)),
        }
        let factory = family.clone().factory();
        self.bolts.insert(kind.to_string(), factory);
        self
    }

    /// Registered spout kinds, sorted.
    pub fn spout_kinds(&self) -> impl Iterator<Item = &str> {
        self.spouts.keys().map(String::as_str)
    }

    /// Registered bolt kinds, sorted.
    pub fn bolt_kinds(&self) -> impl Iterator<Item = &str> {
        self.bolts.keys().map(String::as_str)
    }

    /// Records that `kind` exists but is compiled out of this build, and
    /// which Cargo feature brings it, so that a topology naming it is told
    /// to rebuild with the feature rather than that the kind is unknown.
    pub fn compiled_out(&mut self, kind: &str, feature: &str) -> &mut Self {
        self.missing.insert(kind.to_string(), feature.to_string());
        self
    }

    /// The Cargo feature that brings `kind`, if this build leaves it out.
    pub(crate) fn feature_for(&self, kind: &str) -> Option<&str> {
        self.missing.get(kind).map(String::as_str)
    }

    pub(crate) fn spout(&self, kind: &str) -> Option<&SpoutFactory> {
        self.spouts.get(kind)
    }

    pub(crate) fn bolt(&self, kind: &str) -> Option<&BoltFactory> {
        self.bolts.get(kind)
    }
}

/// `factory` as the registry stores it: building a boxed runner, so that
/// each task's loop stays monomorphized.
fn erase_bolt<B, F>(factory: F) -> BoltFactory
where
    B: Bolt,
    F: Fn(&Params) -> Result<B, ParamError> + Send + Sync + 'static,
{
    Arc::new(move |p| factory(p).map(|b| Box::new(b) as Box<dyn BoltRunner>))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Declarer, Emitter, Tuple};

    /// A bolt that declares one output stream named after its variant.
    #[derive(Debug)]
    struct Named(&'static str);

    impl Bolt for Named {
        fn declare(&self, d: &mut Declarer) {
            d.input::<u64>().output::<u64>(self.0);
        }

        async fn execute(&mut self, _: Tuple, _: &mut Emitter) -> Result<(), crate::BoxError> {
            Ok(())
        }
    }

    fn params(toml: &str) -> Params {
        Params::new(toml.parse().unwrap(), 1, 1)
    }

    /// The output stream the built bolt declares, or the error.
    fn build(r: &Registry, toml: &str) -> Result<Vec<String>, String> {
        let bolt = r.bolt("family").unwrap()(&params(toml)).map_err(|e| e.to_string())?;
        let mut d = Declarer::default();
        bolt.declare(&mut d);
        Ok(d.outputs().iter().map(|s| s.name.clone()).collect())
    }

    #[test]
    fn a_selector_parameter_chooses_the_variant() {
        let mut r = Registry::new();
        r.register_bolt_variant("family", "model", "first", |_| Ok(Named("one")));
        r.register_bolt_variant("family", "model", "second", |_| Ok(Named("two")));
        assert_eq!(build(&r, "model = \"second\"").unwrap(), ["two"]);
        assert_eq!(build(&r, "model = \"first\"").unwrap(), ["one"]);
        assert_eq!(r.bolt_kinds().collect::<Vec<_>>(), ["family"]);
        let missing = build(&r, "").unwrap_err();
        assert!(missing.contains("`model` is required: one of first, second"), "{missing}");
        let unknown = build(&r, "model = \"third\"").unwrap_err();
        assert!(unknown.contains("unknown model \"third\": one of first, second"), "{unknown}");
        // A later registration of a variant replaces it in place.
        r.register_bolt_variant("family", "model", "first", |_| Ok(Named("uno")));
        assert_eq!(build(&r, "model = \"first\"").unwrap(), ["uno"]);
        let missing = build(&r, "").unwrap_err();
        assert!(missing.contains("one of first, second"), "{missing}");
        // A plain registration replaces the family.
        r.register_bolt("family", |_| Ok(Named("plain")));
        assert_eq!(build(&r, "").unwrap(), ["plain"]);
    }

    #[test]
    fn a_kind_compiled_out_is_named_with_the_feature_that_brings_it() {
        let text = "[topology]\nname = \"t\"\n\n[[spout]]\nname = \"source\"\nkind = \"live.ingest\"\n";
        let mut r = Registry::new();
        let unknown = crate::Topology::from_text("t.toml", text, &[], &r).unwrap_err().to_string();
        assert!(
            unknown.contains("t.toml:4") && unknown.contains("unknown spout kind \"live.ingest\""),
            "{unknown}"
        );
        r.compiled_out("live.ingest", "cluster");
        assert_eq!(r.feature_for("live.ingest"), Some("cluster"));
        let missing = crate::Topology::from_text("t.toml", text, &[], &r).unwrap_err().to_string();
        assert!(missing.contains("t.toml:4"), "{missing}");
        assert!(
            missing.contains(
                "spout kind \"live.ingest\" is not in this build: rebuild squall with `--features cluster`"
            ),
            "{missing}"
        );
        assert!(!missing.contains("unknown"), "{missing}");
    }
}
