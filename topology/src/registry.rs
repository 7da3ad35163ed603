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
        let erased: BoltFactory = Arc::new(move |p| factory(p).map(|b| Box::new(b) as Box<dyn BoltRunner>));
        self.bolts.insert(kind.to_string(), erased);
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

    pub(crate) fn spout(&self, kind: &str) -> Option<&SpoutFactory> {
        self.spouts.get(kind)
    }

    pub(crate) fn bolt(&self, kind: &str) -> Option<&BoltFactory> {
        self.bolts.get(kind)
    }
}
