//! parfil, the thesis's toy particle filter (§6.3.1): a robot in a
//! rectangular room that wraps around, four landmarks at the corners,
//! bearing-only observations of all four with Gaussian noise, and
//! forward/turn controls with Gaussian noise. Global localization: the
//! particles start uniformly over the room. The third [`ParticleModel`],
//! cheap per particle, so it measures the topology's own overhead.

mod hosted;
mod spout;

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::pf::model::{Correction, ParticleModel};
use crate::pf::resample::Scheme;
use squall_core::geometry::{Pose2, Real, normalize_angle};
use squall_core::random::standard_normal;
use squall_topology::Registry;

pub use spout::ParfilSpout;

/// Registers the `parfil` spout (the simulated world) and parfil as the
/// particle filter kinds' `model = "parfil"`.
pub fn register(r: &mut Registry) {
    r.register_spout("parfil", ParfilSpout::from_params);
    crate::pf::kinds::register_model::<ParfilModel>(r, "parfil");
}

/// The room and the noise; `Default` gives the thesis's set-up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParfilOptions {
    /// Particles. The default is 1000.
    pub particles: usize,
    /// Room width (x), metres; positions wrap around. The default is 100.
    pub width: Real,
    /// Room height (y), metres. The default is 100.
    pub height: Real,
    /// Standard deviation of the forward motion, metres. The default is
    /// 0.05.
    pub forward_noise: Real,
    /// Standard deviation of the turn, radians. The default is 0.05.
    pub turn_noise: Real,
    /// Standard deviation of a bearing, radians. The default is 0.1.
    pub bearing_noise: Real,
    /// How the new set is drawn (`"low_variance"`, `"ring"`,
    /// `"aggregation"`). The default is `"aggregation"`, as in the thesis.
    pub resampling: Scheme,
}

impl Default for ParfilOptions {
    fn default() -> Self {
        ParfilOptions {
            particles: 1000,
            width: 100.0,
            height: 100.0,
            forward_noise: 0.05,
            turn_noise: 0.05,
            bearing_noise: 0.1,
            resampling: Scheme::Aggregation,
        }
    }
}

impl ParfilOptions {
    /// Checks every range; says which setting is wrong.
    pub fn check(&self) -> crate::Result<()> {
        if self.particles == 0 {
            return Err(crate::Error::Setting("particles must be at least 1".into()));
        }
        for (name, v) in
            [("width", self.width), ("height", self.height), ("bearing_noise", self.bearing_noise)]
        {
            crate::error::positive(name, v)?;
        }
        for (name, v) in [("forward_noise", self.forward_noise), ("turn_noise", self.turn_noise)] {
            crate::error::non_negative(name, v)?;
        }
        Ok(())
    }

    /// The landmarks: the room's corners.
    pub fn landmarks(&self) -> [(Real, Real); 4] {
        [(0.0, 0.0), (self.width, 0.0), (0.0, self.height), (self.width, self.height)]
    }

    /// Bearings of the four landmarks from `pose`, in the robot frame.
    pub fn bearings(&self, pose: &Pose2) -> [Real; 4] {
        self.landmarks().map(|(lx, ly)| normalize_angle((ly - pose.y).atan2(lx - pose.x) - pose.theta))
    }

    /// `pose` driven `forward` metres after turning `turn`, wrapped into
    /// the room.
    pub fn drive(&self, pose: &Pose2, forward: Real, turn: Real) -> Pose2 {
        let theta = pose.theta + turn;
        let x = (pose.x + forward * theta.cos()).rem_euclid(self.width);
        let y = (pose.y + forward * theta.sin()).rem_euclid(self.height);
        Pose2::new(x, y, theta)
    }
}

/// One iteration's input: the control that moved the robot and the
/// bearings it then observed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParfilReading {
    /// Iteration number.
    pub iteration: u64,
    /// Commanded forward distance, metres.
    pub forward: Real,
    /// Commanded turn, radians (before moving).
    pub turn: Real,
    /// Observed bearings of the four landmarks, radians.
    pub bearings: [Real; 4],
}

/// A simulated robot for parfil: drives the commanded control with noise
/// and observes noisy bearings, deterministically per seed.
#[derive(Debug)]
pub struct ParfilWorld {
    options: ParfilOptions,
    truth: Pose2,
    rng: ChaCha8Rng,
    iteration: u64,
}

impl ParfilWorld {
    /// The robot at `start`.
    pub fn new(options: ParfilOptions, start: Pose2, seed: u64) -> Self {
        use rand::SeedableRng;
        ParfilWorld { options, truth: start, rng: ChaCha8Rng::seed_from_u64(seed), iteration: 0 }
    }

    /// The true pose.
    pub fn truth(&self) -> Pose2 {
        self.truth
    }

    /// Moves by the control and observes.
    pub fn step(&mut self, forward: Real, turn: Real) -> ParfilReading {
        let o = &self.options;
        let noisy_turn = turn + o.turn_noise * standard_normal(&mut self.rng);
        let noisy_forward = forward + o.forward_noise * standard_normal(&mut self.rng);
        self.truth = o.drive(&self.truth, noisy_forward, noisy_turn);
        let mut bearings = o.bearings(&self.truth);
        for b in &mut bearings {
            *b = normalize_angle(*b + o.bearing_noise * standard_normal(&mut self.rng));
        }
        self.iteration += 1;
        ParfilReading { iteration: self.iteration, forward, turn, bearings }
    }
}

/// parfil as a particle model: the state is a pose.
#[derive(Debug, Clone, PartialEq)]
pub struct ParfilModel {
    options: ParfilOptions,
}

impl ParfilModel {
    /// The model; errors name the wrong option.
    pub fn new(options: ParfilOptions) -> crate::Result<Self> {
        options.check()?;
        Ok(ParfilModel { options })
    }
}

impl ParticleModel for ParfilModel {
    type Input = ParfilReading;
    type Control = (Real, Real);
    type State = Pose2;
    type Scratch = ();
    type Gate = ();

    fn particles(&self) -> usize {
        self.options.particles
    }

    fn start(&self, _: &ParfilReading) -> Pose2 {
        Pose2::IDENTITY
    }

    fn scatter(&self, pose: &mut Pose2, _: &ParfilReading, rng: &mut ChaCha8Rng) {
        let o = &self.options;
        *pose = Pose2::new(
            rng.random::<Real>() * o.width,
            rng.random::<Real>() * o.height,
            (rng.random::<Real>() * 2.0 - 1.0) * std::f64::consts::PI,
        );
    }

    fn mark(&self, input: &ParfilReading) -> (f64, Pose2) {
        (input.iteration as f64, Pose2::IDENTITY)
    }

    fn control(&self, _: &ParfilReading, input: &ParfilReading) -> (Real, Real) {
        (input.forward, input.turn)
    }

    fn gate(&self, (): &mut (), _: &(Real, Real)) -> bool {
        true
    }

    fn predict(&self, pose: &mut Pose2, &(forward, turn): &(Real, Real), rng: &mut ChaCha8Rng) {
        let o = &self.options;
        let turn = turn + o.turn_noise * standard_normal(rng);
        let forward = forward + o.forward_noise * standard_normal(rng);
        *pose = o.drive(pose, forward, turn);
    }

    fn correct(
        &self,
        pose: &mut Pose2,
        input: &ParfilReading,
        (): &mut (),
        _: &mut ChaCha8Rng,
    ) -> Correction {
        let expected = self.options.bearings(pose);
        let per_sigma = 1.0 / self.options.bearing_noise;
        let log_likelihood = expected
            .iter()
            .zip(&input.bearings)
            .map(|(e, o)| -0.5 * (normalize_angle(o - e) * per_sigma).powi(2))
            .sum();
        Correction { log_likelihood, evaluations: 1, fit: log_likelihood }
    }

    fn pose(&self, pose: &Pose2) -> Pose2 {
        *pose
    }

    fn state_bytes(&self, _: &Pose2) -> u64 {
        std::mem::size_of::<Pose2>() as u64
    }

    fn resample_threshold(&self) -> Real {
        // Every iteration, as in the thesis.
        1.0
    }

    fn resampling(&self) -> Scheme {
        self.options.resampling
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pf::Filter;

    /// Runs the filter on a simulated drive; returns the error of the best
    /// particle's pose at the end, metres.
    fn final_error(scheme: Scheme, shards: usize) -> (Real, Pose2) {
        let options = ParfilOptions { particles: 2000, resampling: scheme, ..ParfilOptions::default() };
        let mut world = ParfilWorld::new(options.clone(), Pose2::new(30.0, 50.0, 0.5), 4);
        let mut filter = Filter::new(ParfilModel::new(options).unwrap(), 9, shards).unwrap();
        filter.process(&ParfilReading {
            iteration: 0,
            forward: 0.0,
            turn: 0.0,
            bearings: world.step(0.0, 0.0).bearings,
        });
        for _ in 0..60 {
            filter.process(&world.step(1.5, 0.05));
        }
        let best = *filter.best_state().unwrap();
        let truth = world.truth();
        ((best.x - truth.x).hypot(best.y - truth.y), best)
    }

    #[test]
    fn the_filter_finds_the_robot_from_a_uniform_start() {
        for scheme in [Scheme::LowVariance, Scheme::Aggregation, Scheme::Ring] {
            let (error, _) = final_error(scheme, 1);
            // A uniform guess is 38 m off on average in this room; the
            // bearings' noise (0.1 rad at 30–70 m) leaves a few metres.
            assert!(error < 5.0, "{scheme:?}: {error:.2} m from the truth");
        }
    }

    #[test]
    fn shards_give_the_same_particles() {
        assert_eq!(final_error(Scheme::Aggregation, 1).1, final_error(Scheme::Aggregation, 3).1);
    }

    #[test]
    fn bearings_are_relative_to_the_heading_and_wrap() {
        let o = ParfilOptions::default();
        let b = o.bearings(&Pose2::new(50.0, 50.0, std::f64::consts::FRAC_PI_2));
        assert!((b[3] - (-std::f64::consts::FRAC_PI_4)).abs() < 1e-12, "{b:?}");
        let p = o.drive(&Pose2::new(99.0, 1.0, 0.0), 2.0, 0.0);
        assert!((p.x - 1.0).abs() < 1e-12);
        assert!(ParfilOptions { width: 0.0, ..o }.check().is_err());
    }
}
