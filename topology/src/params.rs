//! A component's `params` table from the topology file.

use serde::de::DeserializeOwned;

use crate::bounds::MemoryBudget;
use crate::error::ParamError;

/// The `params` of one component, handed to its factory.
#[derive(Debug, Clone, Default)]
pub struct Params {
    table: toml::Table,
    seed: u64,
    parallelism: usize,
    budget: MemoryBudget,
}

impl Params {
    /// Params from a TOML table.
    pub fn new(table: toml::Table, seed: u64, parallelism: usize) -> Self {
        Params { table, seed, parallelism, budget: MemoryBudget::default() }
    }

    /// The same params with the run's memory budget, against which a
    /// factory checks what its structures would take before the run
    /// (validation gives every component the topology's).
    pub fn with_budget(mut self, budget: MemoryBudget) -> Self {
        self.budget = budget;
        self
    }

    /// The run's memory budget (no limit unless [`Params::with_budget`]
    /// set one).
    pub fn budget(&self) -> MemoryBudget {
        self.budget
    }

    /// Deserializes the table into the component's parameter struct. Use
    /// `#[serde(deny_unknown_fields)]` on it so misspelt keys are errors.
    pub fn parse<P: DeserializeOwned>(&self) -> Result<P, ParamError> {
        P::deserialize(toml::Value::Table(self.table.clone())).map_err(|e| {
            // toml's messages end with a newline and may quote the input.
            ParamError::new(e.to_string().trim())
        })
    }

    /// The raw table.
    pub fn table(&self) -> &toml::Table {
        &self.table
    }

    /// The topology seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The component's parallelism.
    pub fn parallelism(&self) -> usize {
        self.parallelism
    }
}
