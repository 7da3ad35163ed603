//! Every SLAM setting in one place, with GMapping's ROS defaults (but
//! `lskip`), checked when built.

use crate::error::{Error, Result, non_negative, positive};
use serde::{Deserialize, Serialize};

pub use crate::pf::resample::Scheme;
pub use crate::pf::smoother::Smoother;
pub use crate::pf::trajectory::BetweenScans;
use squall_core::geometry::Real;
use squall_core::motion::MotionNoise;

/// A limit on pose evaluations per particle per reading (seed 003's
/// scan-matching cutoff). In files: `"none"` or a number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "CutoffText", into = "CutoffText")]
pub enum Cutoff {
    /// Hill climbing runs until it converges.
    Unbounded,
    /// At most this many pose evaluations.
    Evaluations(u32),
}

/// How a cutoff is written: `"none"` or a count.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
enum CutoffText {
    Count(u32),
    Name(String),
}

impl TryFrom<CutoffText> for Cutoff {
    type Error = Error;

    fn try_from(t: CutoffText) -> Result<Self> {
        match t {
            CutoffText::Count(n) => Ok(Cutoff::Evaluations(n)),
            CutoffText::Name(s) if s == "none" => Ok(Cutoff::Unbounded),
            CutoffText::Name(s) => Err(Error::Setting(format!(
                "cutoff must be \"none\" or a number of evaluations, got \"{s}\""
            ))),
        }
    }
}

impl From<Cutoff> for CutoffText {
    fn from(c: Cutoff) -> Self {
        match c {
            Cutoff::Unbounded => CutoffText::Name("none".into()),
            Cutoff::Evaluations(n) => CutoffText::Count(n),
        }
    }
}

/// How a particle's pose is drawn at a correcting reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Proposal {
    /// GMapping's: the motion model's noise is drawn at every reading and
    /// the scan matcher climbs from the noisy pose to the nearest mode,
    /// which becomes the pose.
    Climb,
    /// The improved proposal in closed form ([`crate::slam::proposal`]):
    /// the matcher climbs from a draw of the odometry's prediction with
    /// its uncertainty (relatives explore different modes; a turn's error
    /// is systematic, see `turn_error`), then the pose is drawn from the
    /// product of the scan's Gaussian (its information matrix at the mode)
    /// and the motion model's around the odometry's noise-free
    /// prediction; the weight gains how well the two agree.
    Gaussian,
}

/// SLAM settings; `Default` gives GMapping's ROS defaults, but matches
/// every other beam (`lskip` 1 where GMapping's is 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SlamOptions {
    /// Particles. The default is 30.
    pub particles: usize,
    /// Map cell size, metres. The default is 0.05.
    pub delta: Real,
    /// Beams longer than this are cut for mapping and ignored for matching,
    /// metres. The default is 80 (effectively the laser's range).
    pub max_urange: Real,
    /// Matching kernel σ (the score's Gaussian), metres. The default is 0.05.
    pub sigma: Real,
    /// Cells searched around each end point. The default is 1.
    pub kernel: i64,
    /// First linear step of the hill climber, metres. The default is 0.05.
    pub lstep: Real,
    /// First angular step, radians. The default is 0.05.
    pub astep: Real,
    /// Step halvings. The default is 5.
    pub iterations: u32,
    /// Likelihood σ, metres. The default is 0.075.
    pub lsigma: Real,
    /// Smoothing of the weights (log-likelihoods are divided by
    /// `ogain` × particles before exponentiating). The default is 3.
    pub ogain: Real,
    /// Match and weigh a scan whose beams return with every (lskip+1)-th
    /// beam; a scan whose beams mostly return nothing keeps more, each
    /// counting for its share of the view (see `PreparedScan::new`); maps
    /// still get every beam. The default is 1, every other beam: a third
    /// less time per processed scan, at the accuracy of every beam within
    /// the spread of seeds (docs/decisions/0001-lskip-default-1.md).
    /// GMapping's is 0.
    pub lskip: usize,
    /// Translation noise per metre of translation. The default is 0.1.
    pub srr: Real,
    /// Rotation noise per metre of translation. The default is 0.2.
    pub srt: Real,
    /// Translation noise per radian of rotation. The default is 0.1.
    pub str: Real,
    /// Rotation noise per radian of rotation, drawn afresh at every
    /// reading: GMapping's proposal's (the Gaussian proposal's is
    /// `turn_error`). The default is 0.2.
    pub stt: Real,
    /// How far the odometry may be off about a turn, as a share of the
    /// turn (one standard deviation), with the Gaussian proposal. The
    /// error is systematic over the readings between two corrections (a
    /// wheel base misjudged, wheels slipping through the turn), so it
    /// does not shrink when the odometry reports more often, as `stt`'s
    /// does (see `squall_core::motion::MotionSpread`). With
    /// `learn_turn_error`, the value a run starts from, worth ten turns
    /// of `angular_update`. The default is 0.1.
    pub turn_error: Real,
    /// Each particle learns its robot's turn error from its lineage's
    /// corrections (the heading each matched against the odometry's
    /// prediction, over the turning and driving between), starting from
    /// `turn_error` (`squall_core::motion::TurnErrorEstimate`); `false`
    /// keeps `turn_error` fixed. The default is `true`.
    pub learn_turn_error: bool,
    /// Process a scan after this much travel, metres. The default is 1.0.
    pub linear_update: Real,
    /// ...or this much turning, radians. The default is 0.5.
    pub angular_update: Real,
    /// Resample when Neff falls below this fraction of the particles. The
    /// default is 0.5.
    pub resample_threshold: Real,
    /// Occupancy above which a cell counts as a wall for matching. The
    /// default is 0.1.
    pub occupied_threshold: Real,
    /// Pose evaluations allowed per particle per reading. The default is
    /// unbounded.
    pub cutoff: Cutoff,
    /// When the climb matches fewer than this fraction of the beams, a
    /// wide search looks further (squall's addition for poor odometry and
    /// for re-entering a mapped area a little off; 0 turns it off, as in
    /// GMapping). The default is 0.75: on re-entering after a long loop the
    /// climb's matched fraction dips to about 0.7–0.8. Off under a cutoff,
    /// which bounds every evaluation.
    pub wide_search_below: Real,
    /// Half-width of the wide search in x and y, metres. The default is 0.3.
    pub wide_search_reach: Real,
    /// Half-width of the wide search in heading, radians. The default is
    /// 0.15.
    pub wide_search_turn: Real,
    /// The wide search's pose replaces the climb's only if its score is
    /// this many times higher. The default is 1.2.
    pub wide_search_margin: Real,
    /// Processed readings between snapshots of each particle's map, which
    /// the old-map search matches against (see [`crate::slam::old_map`]):
    /// the snapshot searched is 1–2 times this old. 0 turns the search off.
    /// The default is 50 (about 50 m of travel at the default
    /// `linear_update`). Off under a cutoff.
    pub old_map_age: usize,
    /// The old-map search runs when the climb matches fewer than this
    /// fraction of the beams (but at least half), in an area the old map
    /// covers. The default is 0.85.
    pub old_map_below: Real,
    /// Half-width of the old-map search in x and y, metres. The default
    /// is 0.6.
    pub old_map_reach: Real,
    /// Half-width of the old-map search in heading, radians. The default
    /// is 0.1.
    pub old_map_turn: Real,
    /// How `trajectory.tum` fills in poses between processed scans:
    /// `"interpolate"` spreads each correction back over the scans before
    /// it, `"odometry"` composes the last corrected pose with odometry (as
    /// GMapping reports). The default is `"interpolate"`.
    pub between_scans: BetweenScans,
    /// What is done to the best lineage's poses before they are written:
    /// `"scans"` fuses them with the odometry and with each processed
    /// scan matched against the one before (the default); `"odometry"`
    /// with the odometry alone, weighing each by noise estimated from
    /// the run (see [`crate::pf::smoother`]); `"none"` writes them as the
    /// filter corrected them. Only the trajectory changes: the particles
    /// and maps do not.
    pub smoother: Smoother,
    /// How the new set is drawn: `"low_variance"` (GMapping's, the
    /// default), `"ring"` (the thesis's sparse graph) or `"aggregation"`.
    pub resampling: Scheme,
    /// How poses are drawn: `"gaussian"` or `"climb"` (GMapping's). The
    /// default is `"gaussian"`.
    pub proposal: Proposal,
    /// The largest map, metres a side, centred on the first scan: a scan
    /// whose odometry puts the map past it (a jump in the log's odometry)
    /// is refused with an error rather than grow every particle's map
    /// until memory runs out. The default is 2000, past any building or
    /// campus a laser maps.
    pub max_map_m: Real,
}

/// The most memory one particle's tile index may take at `max_map_m`,
/// bytes: a map bound that with a small `delta` would need more is an
/// error before the run.
pub const MAX_INDEX_BYTES: Real = 256.0 * 1024.0 * 1024.0;

impl Default for SlamOptions {
    fn default() -> Self {
        SlamOptions {
            particles: 30,
            delta: 0.05,
            max_urange: 80.0,
            sigma: 0.05,
            kernel: 1,
            lstep: 0.05,
            astep: 0.05,
            iterations: 5,
            lsigma: 0.075,
            ogain: 3.0,
            lskip: 1,
            srr: 0.1,
            srt: 0.2,
            str: 0.1,
            stt: 0.2,
            turn_error: 0.1,
            learn_turn_error: true,
            linear_update: 1.0,
            angular_update: 0.5,
            resample_threshold: 0.5,
            occupied_threshold: 0.1,
            cutoff: Cutoff::Unbounded,
            wide_search_below: 0.75,
            wide_search_reach: 0.3,
            wide_search_turn: 0.15,
            wide_search_margin: 1.2,
            old_map_age: 50,
            old_map_below: 0.85,
            old_map_reach: 0.6,
            old_map_turn: 0.1,
            between_scans: BetweenScans::Interpolate,
            smoother: Smoother::Scans,
            resampling: Scheme::LowVariance,
            proposal: Proposal::Gaussian,
            max_map_m: 2000.0,
        }
    }
}

impl SlamOptions {
    /// The motion model's noise settings.
    pub fn motion_noise(&self) -> MotionNoise {
        MotionNoise { srr: self.srr, srt: self.srt, str: self.str, stt: self.stt }
    }

    /// Checks every range; says which setting is wrong.
    pub fn check(&self) -> Result<()> {
        if self.particles == 0 {
            return Err(Error::Setting("particles must be at least 1".into()));
        }
        for (n, v) in [
            ("delta", self.delta),
            ("max_urange", self.max_urange),
            ("sigma", self.sigma),
            ("lstep", self.lstep),
            ("astep", self.astep),
            ("lsigma", self.lsigma),
            ("ogain", self.ogain),
            ("wide_search_reach", self.wide_search_reach),
            ("wide_search_turn", self.wide_search_turn),
            ("old_map_reach", self.old_map_reach),
            ("old_map_turn", self.old_map_turn),
            ("max_map_m", self.max_map_m),
        ] {
            positive(n, v)?;
        }
        let index_bytes = crate::slam::grid::TiledGrid::index_bytes(self.max_map_m, self.delta);
        if index_bytes > MAX_INDEX_BYTES {
            return Err(Error::Setting(format!(
                "a {} m map of {} m cells needs {:.3e} bytes of tile index per particle (at most {} MiB): \
                 raise delta or lower max_map_m",
                self.max_map_m,
                self.delta,
                index_bytes,
                MAX_INDEX_BYTES / 1024.0 / 1024.0
            )));
        }
        for (n, v) in [
            ("srr", self.srr),
            ("srt", self.srt),
            ("str", self.str),
            ("stt", self.stt),
            ("turn_error", self.turn_error),
            ("linear_update", self.linear_update),
            ("angular_update", self.angular_update),
            ("wide_search_below", self.wide_search_below),
            ("wide_search_margin", self.wide_search_margin),
            ("old_map_below", self.old_map_below),
        ] {
            non_negative(n, v)?;
        }
        if !(0.0..=1.0).contains(&self.resample_threshold) || !(0.0..1.0).contains(&self.occupied_threshold) {
            return Err(Error::Setting(
                "resample_threshold must be in [0, 1] and occupied_threshold in [0, 1)".into(),
            ));
        }
        if self.iterations > 30 {
            return Err(Error::Setting(format!(
                "iterations must be at most 30 step halvings, got {}",
                self.iterations
            )));
        }
        if !(0..=5).contains(&self.kernel) {
            return Err(Error::Setting(format!("kernel must be 0..=5 cells, got {}", self.kernel)));
        }
        if self.cutoff == Cutoff::Evaluations(0) {
            return Err(Error::Setting("cutoff must allow at least 1 evaluation".into()));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cutoff_reads_none_or_a_number() {
        let o: SlamOptions = toml::from_str("cutoff = 140\nparticles = 20").unwrap();
        assert_eq!((o.cutoff, o.particles, o.delta), (Cutoff::Evaluations(140), 20, 0.05));
        let o: SlamOptions = toml::from_str("cutoff = \"none\"\nbetween_scans = \"odometry\"").unwrap();
        assert_eq!((o.cutoff, o.between_scans), (Cutoff::Unbounded, BetweenScans::Odometry));
        assert!(toml::from_str::<SlamOptions>("between_scans = \"spline\"").is_err());
        assert!(toml::from_str::<SlamOptions>("cutoff = \"fast\"").is_err());
        assert!(toml::from_str::<SlamOptions>("partcles = 3").unwrap_err().to_string().contains("partcles"));
        assert!(SlamOptions { kernel: 9, ..SlamOptions::default() }.check().is_err());
        assert!(SlamOptions { iterations: 31, ..SlamOptions::default() }.check().is_err());
        assert!(SlamOptions { old_map_reach: 0.0, ..SlamOptions::default() }.check().is_err());
        assert!(SlamOptions { old_map_below: -0.1, ..SlamOptions::default() }.check().is_err());
        let o: SlamOptions = toml::from_str("old_map_age = 0").unwrap();
        assert_eq!((o.old_map_age, o.old_map_below), (0, 0.85));
    }
}
