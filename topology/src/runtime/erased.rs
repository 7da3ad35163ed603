//! Object-safe wrappers so the registry can hold any component kind, while
//! each task's loop stays monomorphized (no dynamic dispatch per tuple).

use tokio::runtime::Handle;

use crate::component::{Bolt, Spout};
use crate::declare::Declarer;
use crate::error::BoxError;
use crate::runtime::task::{BoltTask, SpoutTask, run_bolt, run_spout};

/// A spout instance of some kind.
pub(crate) trait SpoutRunner: Send {
    fn declare(&self, declarer: &mut Declarer);
    /// Drives the task on the current thread until it exits.
    fn run(&mut self, task: &mut SpoutTask, runtime: &Handle) -> Result<(), BoxError>;
}

/// A bolt instance of some kind.
pub(crate) trait BoltRunner: Send {
    fn declare(&self, declarer: &mut Declarer);
    /// Drives the task on the current thread until it exits.
    fn run(&mut self, task: &mut BoltTask, runtime: &Handle) -> Result<(), BoxError>;
}

impl<S: Spout> SpoutRunner for S {
    fn declare(&self, declarer: &mut Declarer) {
        Spout::declare(self, declarer);
    }

    fn run(&mut self, task: &mut SpoutTask, runtime: &Handle) -> Result<(), BoxError> {
        runtime.block_on(run_spout(self, task))
    }
}

impl<B: Bolt> BoltRunner for B {
    fn declare(&self, declarer: &mut Declarer) {
        Bolt::declare(self, declarer);
    }

    fn run(&mut self, task: &mut BoltTask, runtime: &Handle) -> Result<(), BoxError> {
        runtime.block_on(run_bolt(self, task))
    }
}
