//! GMapping's particle as a [`ParticleModel`]: a pose and a map; the
//! odometry motion model predicts, the scan matcher corrects and weighs,
//! the scan is integrated into the map after resampling.

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::pf::model::{Correction, ParticleModel};
use crate::pf::resample::Scheme;
use crate::pf::trajectory::{MeasuredStep, NoiseWeights, Smoother, TrajectoryOutput};
use crate::slam::grid::TiledGrid;
use crate::slam::integrate::integrate_scan;
use crate::slam::matcher::{Matcher, PreparedScan};
use crate::slam::old_map::{MapHistory, search_old_map};
use crate::slam::options::{Proposal, SlamOptions};
use crate::slam::proposal::{draw, noisy_start};
use squall_core::covariance::scale;
use squall_core::geometry::{Pose2, Real, normalize_angle};
use squall_core::motion::{MotionSpread, TurnErrorEstimate, TurnErrorPrior, sample_motion};
use squall_core::sensor::LaserReading;

/// One SLAM hypothesis: where the robot is and the map built along the
/// way (tiles shared with relatives until written).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SlamParticle {
    /// Current pose: the particle's sample of the robot's path ends here,
    /// and its map is built from it.
    pub pose: Pose2,
    /// The pose the particle reports: the proposal's mean at the last
    /// correction (the prediction's since). The sample `pose` carries the
    /// proposal's noise, which keeps relatives apart; the mean is the
    /// better estimate of where the robot is given the particle's map (a
    /// Rao-Blackwellized estimate: along a corridor it is the odometry's
    /// prediction, not one draw around it). Equal to `pose` with
    /// GMapping's proposal.
    pub estimate: Pose2,
    /// The particle's map.
    pub map: TiledGrid,
    /// Snapshots of the map for the old-map search.
    pub history: MapHistory,
    /// The uncertainty of the odometry's prediction since the last
    /// correcting reading, for the Gaussian proposal.
    pub spread: MotionSpread,
    /// What the lineage's corrections say of the odometry's turn error.
    pub turns: TurnErrorEstimate,
}

impl SlamParticle {
    /// The grids the particle holds: its map and its snapshots.
    pub fn grids(&self) -> impl Iterator<Item = &TiledGrid> {
        std::iter::once(&self.map).chain(self.history.grids())
    }

    /// Bytes of the distinct tiles of its grids.
    pub fn memory(&self) -> usize {
        let MapHistory { recent, old, .. } = &self.history;
        let recent_beyond = recent.as_ref().map_or(0, |r| r.bytes_beyond(&[&self.map]));
        let old_beyond = old.as_ref().map_or(0, |o| match recent {
            Some(r) => o.bytes_beyond(&[&self.map, r]),
            None => o.bytes_beyond(&[&self.map]),
        });
        self.map.bytes() + recent_beyond + old_beyond
    }
}

/// The odometry between two readings, and the later one's stamp.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OdometryStep {
    /// The later reading's stamp, seconds.
    pub stamp: f64,
    /// Odometry pose of the earlier reading.
    pub from: Pose2,
    /// Odometry pose of the later reading.
    pub to: Pose2,
}

/// Per-task scratch: the prepared reading and the matcher's caches.
#[derive(Debug, Default)]
pub struct SlamScratch {
    prepared: Option<PreparedScan>,
    matcher: Matcher,
}

/// Travel since the last corrected reading (metres, radians).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Travelled {
    linear: Real,
    angular: Real,
}

/// GMapping's model, with its settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SlamModel {
    options: SlamOptions,
}

impl SlamModel {
    /// The model; errors name the wrong option.
    pub fn new(options: SlamOptions) -> crate::Result<Self> {
        options.check()?;
        Ok(SlamModel { options })
    }

    /// The settings.
    pub fn options(&self) -> &SlamOptions {
        &self.options
    }

    /// What a lineage's turn error is learned from: the configured one,
    /// over turns of the update angle; headings within the climb's first
    /// angular step are the matcher's to resolve, never clipped.
    fn turn_prior(&self) -> TurnErrorPrior {
        let o = &self.options;
        TurnErrorPrior { turn_error: o.turn_error, turn: o.angular_update, resolution: o.astep }
    }

    /// The turn error `p`'s prediction is spread with.
    pub fn turn_error(&self, p: &SlamParticle) -> Real {
        if self.options.learn_turn_error {
            p.turns.turn_error(&self.turn_prior())
        } else {
            self.options.turn_error
        }
    }
}

impl ParticleModel for SlamModel {
    type Input = LaserReading;
    type Control = OdometryStep;
    type State = SlamParticle;
    type Scratch = SlamScratch;
    type Gate = Travelled;

    fn particles(&self) -> usize {
        self.options.particles
    }

    fn start(&self, first: &LaserReading) -> SlamParticle {
        let o = &self.options;
        let mut map = TiledGrid::new(o.delta, (0.0, 0.0))
            .and_then(|g| g.with_wall_threshold(o.occupied_threshold))
            .expect("SlamModel::new checked delta > 0 and occupied_threshold in [0, 1)");
        integrate_scan(&mut map, &first.odometry, first, o.max_urange);
        map.take_clone_count();
        let pose = first.odometry;
        SlamParticle {
            pose,
            estimate: pose,
            map,
            history: MapHistory::default(),
            spread: MotionSpread::default(),
            turns: TurnErrorEstimate::default(),
        }
    }

    fn mark(&self, input: &LaserReading) -> (f64, Pose2) {
        (input.stamp, input.odometry)
    }

    /// A scan whose beams, from where its odometry puts it, would reach
    /// past the map's bound ([`SlamOptions::max_map_m`], a square centred
    /// on the first scan) is refused: a jump in the odometry would
    /// otherwise grow every particle's map until memory runs out.
    fn admit(&self, first: Option<&LaserReading>, input: &LaserReading) -> Result<(), String> {
        let origin = first.unwrap_or(input).odometry;
        let at = input.odometry.compose(&input.laser_offset);
        let reach = self.options.max_urange.min(input.range_max);
        let half = self.options.max_map_m / 2.0;
        let (dx, dy) = (at.x - origin.x, at.y - origin.y);
        if dx.abs() + reach <= half && dy.abs() + reach <= half {
            return Ok(());
        }
        Err(format!(
            "its odometry ({:.1}, {:.1}) is {:.0} m from the first scan's, and with beams of {reach} m the map \
             would pass its bound of {} m a side (max_map_m): a jump in the log's odometry? (raise \
             max_map_m if the robot went that far)",
            input.odometry.x,
            input.odometry.y,
            dx.hypot(dy),
            self.options.max_map_m
        ))
    }

    fn control(&self, previous: &LaserReading, input: &LaserReading) -> OdometryStep {
        OdometryStep { stamp: input.stamp, from: previous.odometry, to: input.odometry }
    }

    fn gate(&self, travelled: &mut Travelled, step: &OdometryStep) -> bool {
        let d = step.to.relative_to(&step.from);
        travelled.linear += d.x.hypot(d.y);
        travelled.angular += normalize_angle(d.theta).abs();
        if travelled.linear < self.options.linear_update && travelled.angular < self.options.angular_update {
            return false;
        }
        *travelled = Travelled::default();
        true
    }

    fn predict(&self, p: &mut SlamParticle, step: &OdometryStep, rng: &mut ChaCha8Rng) {
        let noise = self.options.motion_noise();
        p.pose = match self.options.proposal {
            Proposal::Climb => sample_motion(&p.pose, &step.from, &step.to, &noise, rng),
            // The noise-free prediction and its spread; the noise is drawn
            // at the correction (see `correct`).
            Proposal::Gaussian => {
                let turn_error = self.turn_error(p);
                p.spread.propagate(&p.pose, &step.from, &step.to, &noise, turn_error)
            }
        };
        p.estimate = p.pose;
    }

    fn prepare(&self, input: &LaserReading, scratch: &mut SlamScratch) {
        scratch.prepared = Some(PreparedScan::new(input, &self.options));
    }

    fn correct(
        &self,
        p: &mut SlamParticle,
        input: &LaserReading,
        scratch: &mut SlamScratch,
        rng: &mut ChaCha8Rng,
    ) -> Correction {
        let o = &self.options;
        let SlamScratch { prepared, matcher } = scratch;
        let prepared = prepared.get_or_insert_with(|| PreparedScan::new(input, o));
        let motion = p.spread.covariance();
        let start = match o.proposal {
            Proposal::Climb => p.pose,
            Proposal::Gaussian => noisy_start(&p.pose, &motion, rng),
        };
        let climbed = matcher.refine(&p.map, &start, prepared, o);
        let m = search_old_map(matcher, &p.map, &p.history, climbed, prepared, o);
        let fit = m.log_likelihood * prepared.per_beam();
        match o.proposal {
            Proposal::Climb => {
                // A climb that matched nothing leaves the pose where it was.
                p.pose = m.pose;
                p.estimate = m.pose;
                Correction { log_likelihood: fit, evaluations: m.evaluations, fit }
            }
            Proposal::Gaussian => {
                let information =
                    scale(&matcher.information(&p.map, &m.pose, prepared, o), prepared.per_beam());
                let drawn = draw(&m.pose, &information, &p.pose, &motion, rng);
                if o.learn_turn_error {
                    let heading_error = normalize_angle(m.pose.theta - p.pose.theta);
                    let prior = self.turn_prior();
                    p.turns.observe(p.spread.turned, p.spread.driven, heading_error, &prior);
                }
                p.pose = drawn.pose;
                p.estimate = drawn.mean;
                p.spread = MotionSpread::default();
                let log_likelihood = fit + drawn.log_agreement;
                Correction { log_likelihood, evaluations: m.evaluations, fit }
            }
        }
    }

    fn update(&self, p: &mut SlamParticle, input: &LaserReading) -> u64 {
        integrate_scan(&mut p.map, &p.pose, input, self.options.max_urange);
        p.history.record(&p.map, self.options.old_map_age);
        p.map.take_clone_count()
    }

    fn pose(&self, p: &SlamParticle) -> Pose2 {
        p.estimate
    }

    fn state_bytes(&self, p: &SlamParticle) -> u64 {
        p.memory() as u64
    }

    /// With the Gaussian proposal and `learn_turn_error`: the turn error
    /// the particle's lineage learned (`turn_error_permille`, thousandths
    /// of a turn, one standard deviation) and the matcher's heading noise
    /// it found in the corrections (`matcher_heading_noise_mrad`), a
    /// calibration of the robot's odometry and of the scan matching.
    fn learned(&self, p: &SlamParticle) -> Vec<(&'static str, u64)> {
        if !self.options.learn_turn_error || self.options.proposal != Proposal::Gaussian {
            return Vec::new();
        }
        let thousandths = |x: Real| (1000.0 * x).round() as u64;
        vec![
            ("turn_error_permille", thousandths(self.turn_error(p))),
            ("matcher_heading_noise_mrad", thousandths(p.turns.matcher_noise().sqrt())),
        ]
    }

    fn weight_smoothing(&self) -> Real {
        self.options.ogain
    }

    fn resample_threshold(&self) -> Real {
        self.options.resample_threshold
    }

    fn resampling(&self) -> Scheme {
        self.options.resampling
    }

    fn measure_step(&self, from: &LaserReading, to: &LaserReading) -> Option<MeasuredStep> {
        if self.options.smoother != Smoother::Scans {
            return None;
        }
        squall_core::scan_match::match_scans(from, to)
    }

    fn trajectory_output(&self) -> TrajectoryOutput {
        let o = &self.options;
        TrajectoryOutput {
            between: o.between_scans,
            noise: NoiseWeights { per_metre: o.srr, per_radian: o.str },
            smoother: o.smoother,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slam::scenes::{room, scan_of};
    use rand::SeedableRng;

    /// The heading deviation of a particle's prediction after a half
    /// radian turned on the spot in `readings` odometry readings.
    fn turn_deviation(options: SlamOptions, readings: usize) -> Real {
        let model = SlamModel::new(options).unwrap();
        let mut p = model.start(&scan_of(&room(), &Pose2::new(3.0, 2.0, 0.0)));
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let at = |i: usize| Pose2::new(0.0, 0.0, 0.5 * i as Real / readings as Real);
        for i in 0..readings {
            model.predict(&mut p, &OdometryStep { stamp: i as f64, from: at(i), to: at(i + 1) }, &mut rng);
        }
        p.spread.covariance()[2][2].sqrt()
    }

    #[test]
    fn a_turn_is_as_uncertain_whatever_the_odometrys_rate() {
        let o = SlamOptions::default();
        let expected = o.turn_error * 0.5;
        for readings in [1, 40] {
            let deviation = turn_deviation(o.clone(), readings);
            assert!((deviation - expected).abs() < 1e-9, "{readings} readings: {deviation} vs {expected}");
        }
        let doubled = turn_deviation(SlamOptions { turn_error: 0.2, ..o }, 40);
        assert!((doubled - 2.0 * expected).abs() < 1e-9, "the setting scales it: {doubled}");
    }
}

#[cfg(test)]
mod learning {
    use super::*;
    use crate::slam::scenes::{room, scan_of};
    use rand::SeedableRng;

    /// The turn error one particle has learned after turning on the spot
    /// in the room, `turns` corrections of 0.6 rad each in six readings,
    /// its odometry reporting `reported` of every turn.
    fn learned_turn_error(reported: Real, turns: usize) -> Real {
        let model = SlamModel::new(SlamOptions::default()).unwrap();
        let world = room();
        let truth = |k: usize| Pose2::new(3.0, 2.0, normalize_angle(0.1 * k as Real));
        let odometry = |k: usize| Pose2::new(0.0, 0.0, normalize_angle(0.1 * reported * k as Real));
        let mut p = model.start(&scan_of(&world, &Pose2::new(3.0, 2.0, 0.0)));
        let (mut rng, mut scratch) = (ChaCha8Rng::seed_from_u64(7), SlamScratch::default());
        for turn in 0..turns {
            for k in 6 * turn..6 * (turn + 1) {
                let step = OdometryStep { stamp: k as f64, from: odometry(k), to: odometry(k + 1) };
                model.predict(&mut p, &step, &mut rng);
            }
            let k = 6 * (turn + 1);
            let reading = LaserReading { odometry: odometry(k), ..scan_of(&world, &truth(k)) };
            model.prepare(&reading, &mut scratch);
            model.correct(&mut p, &reading, &mut scratch, &mut rng);
            model.update(&mut p, &reading);
        }
        model.turn_error(&p)
    }

    #[test]
    fn a_particle_learns_how_far_its_odometry_misjudges_turns() {
        // Turns under-reported by a fifth: each correction finds the
        // heading a quarter of the reported turn further on.
        let under = learned_turn_error(0.8, 40);
        assert!((under - 0.25).abs() < 0.05, "{under}");
        // Exact odometry: the prior's 0.1 gives way to what the matcher
        // finds, a small fraction of it.
        let exact = learned_turn_error(1.0, 40);
        assert!(exact < 0.05, "{exact}");
        // Before any correction, the setting.
        assert!((learned_turn_error(0.8, 0) - SlamOptions::default().turn_error).abs() < 1e-12);
    }

    #[test]
    fn what_a_particle_learned_is_reported_in_thousandths() {
        let model = SlamModel::new(SlamOptions::default()).unwrap();
        let mut p = model.start(&scan_of(&room(), &Pose2::new(3.0, 2.0, 0.0)));
        assert_eq!(model.learned(&p), vec![("turn_error_permille", 100), ("matcher_heading_noise_mrad", 0)]);
        for r in [0.3, -0.3, 0.3, -0.3] {
            p.turns.observe(0.5, 0.0, r * 0.5, &model.turn_prior());
        }
        let learned = model.learned(&p);
        assert_eq!(learned[0], ("turn_error_permille", (1000.0 * model.turn_error(&p)).round() as u64));
        assert!(learned[1].1 > 0, "alternating innovations are the matcher's: {learned:?}");
        let climb =
            SlamModel::new(SlamOptions { proposal: Proposal::Climb, ..SlamOptions::default() }).unwrap();
        assert!(climb.learned(&p).is_empty());
    }

    #[test]
    fn a_fixed_turn_error_is_kept() {
        let model =
            SlamModel::new(SlamOptions { learn_turn_error: false, ..SlamOptions::default() }).unwrap();
        let mut p = model.start(&scan_of(&room(), &Pose2::new(3.0, 2.0, 0.0)));
        p.turns.observe(0.5, 0.0, 0.2, &model.turn_prior());
        assert_eq!(model.turn_error(&p), model.options().turn_error);
    }
}
