//! What a particle filter needs from its model; everything else (sharding
//! the particles over tasks, weights, resampling, reassignment, the best
//! particle's lineage) is written once in this module's siblings.

use rand_chacha::ChaCha8Rng;

use crate::pf::resample::Scheme;
use crate::pf::trajectory::{BetweenScans, MeasuredStep, NoiseWeights, Smoother, TrajectoryOutput};
use squall_core::geometry::{Pose2, Real};

/// The model-specific parts of a particle filter.
///
/// A reading either only moves the particles (predict) or, when the model's
/// gate says so, also corrects them (refine and weigh), after which the set
/// may be resampled and every particle updated with the reading (a map
/// update, for SLAM). Every method is deterministic given its arguments, so
/// that a particle evolves identically on whichever task holds it.
pub trait ParticleModel: Send + Sync + 'static {
    /// A reading as the source streams it.
    type Input: Send + Sync + 'static;
    /// What prediction consumes between two readings (for SLAM: the two
    /// odometry poses and the stamp).
    type Control: Clone + Send + Sync + 'static;
    /// One particle's state.
    type State: Clone + Send + Sync + 'static;
    /// Scratch memory reused from particle to particle on one task.
    type Scratch: Default + Send;
    /// What the gate remembers between readings.
    type Gate: Default + Send;

    /// Particles in the set.
    fn particles(&self) -> usize;

    /// The state every particle starts from at the first reading (built
    /// once and shared: for SLAM, one map).
    fn start(&self, first: &Self::Input) -> Self::State;

    /// Spreads one particle's copy of the start state, drawing from `rng`
    /// (for global localization: a pose the first reading supports). The
    /// default keeps it.
    fn scatter(&self, state: &mut Self::State, first: &Self::Input, rng: &mut ChaCha8Rng) {
        let _ = (state, first, rng);
    }

    /// The reading's stamp and odometry pose (the lineage's marks, from
    /// which every reading's pose is filled in).
    fn mark(&self, input: &Self::Input) -> (f64, Pose2);

    /// The control from `previous` to `input`.
    fn control(&self, previous: &Self::Input, input: &Self::Input) -> Self::Control;

    /// Whether `input`, reached by `control`, corrects the particles.
    fn gate(&self, gate: &mut Self::Gate, control: &Self::Control) -> bool;

    /// Moves a particle by a control, drawing noise from `rng`.
    fn predict(&self, state: &mut Self::State, control: &Self::Control, rng: &mut ChaCha8Rng);

    /// Prepares a correcting reading once per task before its particles
    /// are corrected (for SLAM: the usable beams and their directions).
    fn prepare(&self, input: &Self::Input, scratch: &mut Self::Scratch) {
        let _ = (input, scratch);
    }

    /// Checks a reading before any particle takes it (`first`: the run's
    /// first reading, `None` for the first itself). `Err` says why the
    /// model cannot take it, and the run fails saying so; the default
    /// takes every reading.
    fn admit(&self, first: Option<&Self::Input>, input: &Self::Input) -> Result<(), String> {
        let _ = (first, input);
        Ok(())
    }

    /// Refines a particle against a correcting reading, drawing from `rng`
    /// where the refinement samples (SLAM's Gaussian proposal); returns its
    /// log-likelihood and the work spent.
    fn correct(
        &self,
        state: &mut Self::State,
        input: &Self::Input,
        scratch: &mut Self::Scratch,
        rng: &mut ChaCha8Rng,
    ) -> Correction;

    /// Adds a correcting reading to a particle after resampling; returns
    /// the work counted (for SLAM: map tiles cloned). The default, for
    /// models whose state is only a pose, does nothing.
    fn update(&self, state: &mut Self::State, input: &Self::Input) -> u64 {
        let _ = (state, input);
        0
    }

    /// The model's own measurement of the motion between two correcting
    /// readings, apart from the particles (for SLAM: the later scan
    /// matched against the earlier one), for the output smoother. The
    /// default measures nothing.
    fn measure_step(&self, from: &Self::Input, to: &Self::Input) -> Option<MeasuredStep> {
        let _ = (from, to);
        None
    }

    /// The particle's pose, for outputs and the lineage.
    fn pose(&self, state: &Self::State) -> Pose2;

    /// Bytes that move when the state is sent to another task.
    fn state_bytes(&self, state: &Self::State) -> u64;

    /// What a particle has learned of the robot, as named whole numbers,
    /// reported as the matcher's counters at the end of a run for the best
    /// particle (for SLAM: its odometry's turn error in thousandths). The
    /// default learns nothing.
    fn learned(&self, state: &Self::State) -> Vec<(&'static str, u64)> {
        let _ = state;
        Vec::new()
    }

    /// Smoothing of the weights: log-weights are divided by this × N
    /// before exponentiating (GMapping's ogain). The default, 1 / N, takes
    /// the likelihoods as they are.
    fn weight_smoothing(&self) -> Real {
        1.0 / self.particles() as Real
    }

    /// KLD-sampling of the set's size at each resampling (see
    /// [`crate::pf::kld`]); the default keeps [`Self::particles`].
    fn kld(&self) -> Option<crate::pf::kld::Kld> {
        None
    }

    /// Resample when Neff falls below this fraction of the particles.
    fn resample_threshold(&self) -> Real;

    /// How the new set is drawn when resampling.
    fn resampling(&self) -> Scheme {
        Scheme::LowVariance
    }

    /// Random particles to add when the observations stop fitting
    /// (augmented MCL, for recovery from kidnapping); `None`, the
    /// default, adds none.
    fn injection(&self) -> Option<Injection> {
        None
    }

    /// Redraws a particle from scratch (an injected one), given the
    /// reading just corrected: a model may draw states that reading
    /// supports. The default keeps it.
    fn inject(&self, state: &mut Self::State, reading: &Self::Input, rng: &mut ChaCha8Rng) {
        let _ = (state, reading, rng);
    }

    /// How the written trajectory is made from the best lineage. The
    /// default writes the corrected poses as they are and composes them
    /// with odometry in between.
    fn trajectory_output(&self) -> TrajectoryOutput {
        TrajectoryOutput {
            between: BetweenScans::Odometry,
            noise: NoiseWeights { per_metre: 0.0, per_radian: 0.0 },
            smoother: Smoother::None,
        }
    }
}

/// Augmented MCL's smoothing of the best particle's observation
/// likelihood: a slow and a fast average; while the fast one is below the slow one by more
/// than a dead band, a share 1 − fast/slow · e^`min_drop` of the particles,
/// and at least `lost_share`, is redrawn (see [`ParticleModel::inject`]);
/// a set KLD-sampling sizes grows to that share of its most particles.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Injection {
    /// Rate of the slow average (0 < slow < fast ≤ 1).
    pub alpha_slow: Real,
    /// Rate of the fast average.
    pub alpha_fast: Real,
    /// The dead band: how far (in the model's fit, a log-likelihood) the
    /// fast average must fall below the slow one before anything is
    /// injected. Without it every ordinary dip of the fit injects a few
    /// particles, and one that happens to fit a look-alike place better
    /// for a moment takes the estimate there.
    pub min_drop: Real,
    /// The least share redrawn once the fit has dropped past the dead
    /// band (0 to 1). 1 − fast/slow starts small, and the moment one
    /// redrawn particle fits a look-alike place the fast average recovers
    /// and the search stops, usually before a draw has landed at the
    /// robot's true place. A lost robot is better served by a mixture:
    /// part of the set keeps what it believed (a drop may be people in
    /// the way), the rest searches where the reading fits.
    pub lost_share: Real,
}

/// One particle's correction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Correction {
    /// Log-likelihood of the reading at the refined state.
    pub log_likelihood: Real,
    /// Work spent (for SLAM: pose evaluations).
    pub evaluations: u32,
    /// How well the reading fits, on a scale that does not grow with the
    /// reading's size (for CGR: the log-likelihood per point, see
    /// `CgrOptions::occlusion_fits`); what augmented MCL averages; −∞ when
    /// the reading holds nothing to fit. Models without
    /// injection may repeat the log-likelihood.
    pub fit: Real,
}
