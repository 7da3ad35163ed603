//! Localization on a line map as a [`ParticleModel`]: the odometry motion
//! model predicts, Corrective Gradient Refinement moves each particle up
//! the measurement likelihood, the likelihood at the refined pose weighs
//! it. The observable scene comes from a precomputed grid when there is
//! one, else it is ray cast on demand.

use std::borrow::Cow;
use std::sync::Arc;

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::cgr::measurement::{CgrOptions, refine};
use crate::cgr::observation::Observation2d;
use crate::cgr::scene::observable_scene;
use crate::cgr::scene_grid::SceneGrid;
use crate::geometry::{Pose2, Real};
use crate::linemap::LineMap;
use crate::pf::model::{Correction, Injection, ParticleModel};
use crate::pf::resample::Scheme;
use crate::slam::model::OdometryStep;
use crate::slam::motion::{MotionNoise, sample_motion};

/// Where the particles start.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Init {
    /// Tracking: every particle at this pose.
    Known(Pose2),
    /// Global localization: uniform over the map's bounding box.
    Global,
}

/// Localization settings.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizeOptions {
    /// Particles.
    pub particles: usize,
    /// Measurement and refinement.
    pub cgr: CgrOptions,
    /// Motion noise.
    pub motion: MotionNoise,
    /// Where the particles start.
    pub init: Init,
    /// How the new set is drawn.
    pub resampling: Scheme,
    /// Resample below this fraction of N (Neff).
    pub resample_threshold: Real,
    /// Random particles injected when observations stop fitting (augmented
    /// MCL, meant for recovery from kidnapping); `None`, the default, turns
    /// it off. Not yet shown to recover a kidnapped robot here.
    pub injection: Option<Injection>,
}

impl Default for LocalizeOptions {
    fn default() -> Self {
        LocalizeOptions {
            particles: 50,
            cgr: CgrOptions::default(),
            motion: MotionNoise { srr: 0.1, srt: 0.2, str: 0.1, stt: 0.2 },
            init: Init::Global,
            resampling: Scheme::LowVariance,
            resample_threshold: 0.5,
            injection: None,
        }
    }
}

/// The model: the map, its precomputed scenes if any, the settings.
#[derive(Debug, Clone)]
pub struct CgrModel {
    map: Arc<LineMap>,
    scenes: Option<Arc<SceneGrid>>,
    options: LocalizeOptions,
}

impl CgrModel {
    /// The model; errors name the wrong setting.
    pub fn new(
        map: Arc<LineMap>,
        scenes: Option<Arc<SceneGrid>>,
        options: LocalizeOptions,
    ) -> Result<Self, String> {
        options.cgr.check()?;
        if options.particles == 0 {
            return Err("particles must be at least 1".into());
        }
        if let Some(i) = options.injection {
            if !(0.0 < i.alpha_slow && i.alpha_slow < i.alpha_fast && i.alpha_fast <= 1.0) {
                return Err(format!(
                    "injection rates must satisfy 0 < alpha_slow < alpha_fast ≤ 1, got {} and {}",
                    i.alpha_slow, i.alpha_fast
                ));
            }
        }
        Ok(CgrModel { map, scenes, options })
    }

    /// The walls visible from `pose`: the grid's cell if the pose is on the
    /// grid, else ray cast.
    fn lines_at(&self, pose: &Pose2) -> Cow<'_, [u32]> {
        if let Some(lines) = self.scenes.as_ref().and_then(|g| g.lines_at(pose.x, pose.y)) {
            return Cow::Borrowed(lines);
        }
        let mut ids: Vec<u32> = observable_scene(&self.map, (pose.x, pose.y), self.options.cgr.range)
            .iter()
            .map(|v| v.line)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        Cow::Owned(ids)
    }
}

impl ParticleModel for CgrModel {
    type Input = Observation2d;
    type Control = OdometryStep;
    type State = Pose2;
    type Scratch = ();
    type Gate = ();

    fn particles(&self) -> usize {
        self.options.particles
    }

    fn start(&self, _: &Observation2d) -> Pose2 {
        match self.options.init {
            Init::Known(p) => p,
            Init::Global => Pose2::IDENTITY,
        }
    }

    fn scatter(&self, pose: &mut Pose2, rng: &mut ChaCha8Rng) {
        if self.options.init == Init::Global {
            self.inject(pose, rng);
        }
    }

    fn injection(&self) -> Option<Injection> {
        self.options.injection
    }

    fn inject(&self, pose: &mut Pose2, rng: &mut ChaCha8Rng) {
        let (x0, y0, x1, y1) = self.map.bounds();
        *pose = Pose2::new(
            x0 + rng.random::<Real>() * (x1 - x0),
            y0 + rng.random::<Real>() * (y1 - y0),
            (rng.random::<Real>() * 2.0 - 1.0) * std::f64::consts::PI,
        );
    }

    fn mark(&self, input: &Observation2d) -> (f64, Pose2) {
        (input.stamp, input.odometry)
    }

    fn control(&self, previous: &Observation2d, input: &Observation2d) -> OdometryStep {
        OdometryStep { stamp: input.stamp, from: previous.odometry, to: input.odometry }
    }

    fn gate(&self, (): &mut (), _: &OdometryStep) -> bool {
        true
    }

    fn predict(&self, pose: &mut Pose2, step: &OdometryStep, rng: &mut ChaCha8Rng) {
        *pose = sample_motion(pose, &step.from, &step.to, &self.options.motion, rng);
    }

    fn correct(&self, pose: &mut Pose2, input: &Observation2d, (): &mut ()) -> Correction {
        let (refined, e, evaluations) =
            refine(&self.map, &mut |p: &Pose2| self.lines_at(p), pose, input, &self.options.cgr);
        *pose = refined;
        let points = input.points.len().max(1) as Real;
        Correction { log_likelihood: e.log_likelihood, evaluations, fit: e.log_likelihood / points }
    }

    fn pose(&self, pose: &Pose2) -> Pose2 {
        *pose
    }

    fn state_bytes(&self, _: &Pose2) -> u64 {
        std::mem::size_of::<Pose2>() as u64
    }

    fn weight_smoothing(&self) -> Real {
        // Plain likelihoods: log-weights divided by smoothing × N = 1.
        1.0 / self.options.particles as Real
    }

    fn resample_threshold(&self) -> Real {
        self.options.resample_threshold
    }

    fn resampling(&self) -> Scheme {
        self.options.resampling
    }
}
