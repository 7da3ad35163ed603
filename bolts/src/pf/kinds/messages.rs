//! What the particle filter's components send each other.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::pf::kld::Kld;
use crate::pf::model::Injection;
use crate::pf::resample::Scheme;
use crate::pf::shard::SlotReport;
use crate::pf::trajectory::{MeasuredStep, TrajectoryOutput};
use squall_core::geometry::{Pose2, Real};

/// Dispatcher → every matcher task: a reading and its number in the run
/// (0 starts the filter).
#[derive(Debug, Serialize, Deserialize)]
#[serde(bound(serialize = "I: Serialize", deserialize = "I: serde::de::DeserializeOwned"))]
pub struct Reading<I> {
    /// The reading's number.
    pub step: u64,
    /// The reading, shared by every matcher task.
    pub input: Arc<I>,
}

/// Resampler → dispatcher (feedback): every matcher is done with `step`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ready {
    /// The reading.
    pub step: u64,
    /// Whether it corrected the particles (rather than only moving them).
    pub corrected: bool,
}

/// What the resampler needs of the model, sent once by the matchers
/// (which hold the model's settings) when they start.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// Weights are smoothed by dividing log-weights by this × N.
    pub smoothing: Real,
    /// Resample below this fraction of N.
    pub threshold: Real,
    /// How the new set is drawn.
    pub scheme: Scheme,
    /// Augmented MCL's averaging, if particles are injected.
    pub injection: Option<Injection>,
    /// How the written trajectory is made from the best lineage.
    pub trajectory: TrajectoryOutput,
    /// KLD-sampling of the set's size, if the model asks for it.
    pub kld: Option<Kld>,
}

/// Matcher task → resampler.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Report {
    /// The first reading started the filter.
    Started {
        /// The reporting task and how many there are.
        task: u32,
        /// Matcher tasks.
        tasks: u32,
        /// The reading's stamp and odometry.
        mark: (f64, Pose2),
        /// (slot, pose) of the particles this task holds.
        poses: Vec<(u32, Pose2)>,
        /// Particles in the set.
        particles: u32,
        /// The model's resampling settings.
        settings: Settings,
    },
    /// A reading moved the particles only.
    Predicted {
        /// The reading.
        step: u64,
        /// The reporting task.
        task: u32,
        /// Matcher tasks.
        tasks: u32,
        /// The reading's stamp and odometry.
        mark: (f64, Pose2),
    },
    /// A reading corrected this task's particles.
    Corrected {
        /// The reading.
        step: u64,
        /// The reporting task.
        task: u32,
        /// Matcher tasks.
        tasks: u32,
        /// The reading's stamp and odometry.
        mark: (f64, Pose2),
        /// One report per particle held.
        slots: Vec<SlotReport>,
        /// Microseconds the task spent correcting.
        busy_us: u64,
        /// The model's measurement of the step since the previous
        /// correcting reading (task 0 only; see
        /// [`crate::pf::ParticleModel::measure_step`]).
        measured: Option<MeasuredStep>,
    },
    /// This task replaces one whose particles were lost with its process
    /// (cluster mode): it holds nothing until a decision has it join.
    Lost {
        /// The reporting task.
        task: u32,
        /// Matcher tasks.
        tasks: u32,
    },
    /// The task adopted the new set and updated it with the reading.
    Updated {
        /// The reading.
        step: u64,
        /// The reporting task.
        task: u32,
        /// Matcher tasks.
        tasks: u32,
        /// Microseconds spent exchanging and updating.
        busy_us: u64,
        /// Work the updates counted (map tiles cloned, for SLAM).
        update_work: u64,
    },
}

impl Report {
    /// The reading and the reporting task, for reports about a reading.
    pub fn step_and_task(&self) -> Option<(u64, u32)> {
        match self {
            Report::Predicted { step, task, .. }
            | Report::Corrected { step, task, .. }
            | Report::Updated { step, task, .. } => Some((*step, *task)),
            Report::Started { .. } | Report::Lost { .. } => None,
        }
    }
}

/// Resampler → every matcher task (feedback): the new particle set and
/// where each particle lives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Decision {
    /// The reading.
    pub step: u64,
    /// New slot j descends from old slot `parents[j]`.
    pub parents: Vec<u32>,
    /// The task that holds new slot j.
    pub task_of: Vec<u32>,
    /// The best particle's new slot.
    pub best: u32,
    /// New slots redrawn at random (augmented MCL), in order.
    pub fresh: Vec<u32>,
    /// Tasks that hold nothing (their particles were lost) and take up
    /// their new slots with this decision; their senders add the reading.
    pub joining: Vec<u32>,
    /// Set on a notice, not a decision: this task was lost after the
    /// decision for `step`, so the new slots in `holes` will not come;
    /// tasks waiting for them go on without them.
    pub lost: Option<u32>,
    /// With `lost`: the new slots whose states went with the lost task.
    pub holes: Vec<u32>,
}

impl Decision {
    /// The notice that `task` was lost after the decision for `step`.
    pub fn lost_notice(step: u64, task: u32, holes: Vec<u32>) -> Self {
        Decision {
            step,
            parents: Vec::new(),
            task_of: Vec::new(),
            best: 0,
            fresh: Vec::new(),
            joining: Vec::new(),
            lost: Some(task),
            holes,
        }
    }
}

/// Matcher task → matcher task (peer exchange): parents' states for new
/// slots the receiver holds from now on. In-process the states' maps share
/// their tiles with the sender's.
#[derive(Debug, Serialize, Deserialize)]
#[serde(bound(
    serialize = "S: Serialize, I: Serialize",
    deserialize = "S: serde::de::DeserializeOwned, I: serde::de::DeserializeOwned"
))]
pub struct Transfer<S, I> {
    /// The reading whose decision this carries out.
    pub step: u64,
    /// (new slot, state).
    pub states: Vec<(u32, S)>,
    /// The reading itself, for a task joining with this decision (it
    /// never got it: it replaces one that was lost).
    pub reading: Option<Arc<Reading<I>>>,
}
