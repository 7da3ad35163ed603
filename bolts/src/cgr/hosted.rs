//! Localization on the particle filter kinds (`model = "cgr"`): the model
//! built from a matcher's params (the map file, particles, start,
//! resampling, measurement and motion settings, where precomputed scenes
//! are cached), and the registration of the localization kinds.

use crate::Error;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use serde::Deserialize;
use squall_core::geometry::{Pose2, Real};
use squall_core::linemap::LineMap;
use squall_core::motion::MotionNoise;
use squall_topology::Registry;
use squall_topology::bounds::MemoryBudget;

use crate::cgr::depth_points::DepthPoints;
use crate::cgr::laser_points::LaserPoints;
use crate::cgr::measurement::CgrOptions;
use crate::cgr::model::{CgrModel, Init, LocalizeOptions};
use crate::cgr::scene_grid::SceneGrid;
use crate::pf::kinds::{HostedModel, from_table, register_model};
use crate::pf::model::Injection;
use crate::pf::resample::Scheme;

/// Registers `cgr.laser`, `cgr.fspf` and CGR as the particle filter kinds'
/// `model = "cgr"`.
pub fn register(r: &mut Registry) {
    r.register_bolt("cgr.laser", LaserPoints::from_params);
    r.register_bolt("cgr.fspf", DepthPoints::from_params);
    register_model::<CgrModel>(r, "cgr");
}

impl HostedModel for CgrModel {
    type Snapshot = Pose2;

    fn from_table(table: toml::Table, budget: MemoryBudget) -> crate::Result<Self> {
        cgr_model(table, budget)
    }

    fn snapshot(&self, state: &Pose2) -> Pose2 {
        *state
    }
}

/// The `cgr` model's params, flat; any left out takes the default of
/// [`LocalizeOptions`] / [`CgrOptions`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct CgrParams {
    /// The line-map file (required).
    map: PathBuf,
    /// Particles at the start (the most, with `min_particles` fewer).
    particles: usize,
    /// The fewest KLD-sampling keeps (default: `particles`, a fixed set).
    min_particles: Option<usize>,
    /// `"known"` (then `start` = [x, y, θ]) or `"global"`.
    init: String,
    start: Option<[Real; 3]>,
    resampling: Scheme,
    resample_threshold: Real,
    /// `"grid"` (precomputed) or `"on_demand"`.
    scenes: String,
    cell: Real,
    /// Where precomputed scenes are cached (default: the system's
    /// temporary folder, `squall-scenes`).
    cache_dir: Option<PathBuf>,
    sigma: Real,
    /// Range-dependent noise: σ² + (this × r²)² per point (depth).
    noise_per_r2: Real,
    correlation: Real,
    normal_tolerance_deg: Real,
    range: Real,
    refine_iterations: u32,
    outlier_sigmas: Real,
    /// Points short of the map count as fitting in augmented MCL's test
    /// for a lost robot (a depth camera's view filled by a person).
    occlusion_fits: bool,
    /// The largest obstacle the map leaves out, metres (with
    /// `occlusion_fits`).
    occluder_size: Real,
    /// Points at corners facing the other wall are left out (depth).
    leave_out_corners: bool,
    /// Refinement ends with a whole-curvature Newton step (depth).
    newton_step: bool,
    /// Augmented MCL (random particles when observations stop fitting):
    /// off by default; `injection = true` with `alpha_slow`, `alpha_fast`,
    /// `min_drop` and `lost_share`.
    injection: bool,
    alpha_slow: Real,
    alpha_fast: Real,
    min_drop: Real,
    lost_share: Real,
    srr: Real,
    srt: Real,
    str: Real,
    stt: Real,
    /// Keep the particles inside the building (true by default), closing
    /// gaps in its outline narrower than `inside_opening` metres.
    keep_inside: bool,
    inside_opening: Real,
}

/// Augmented MCL's rates when `injection = true` and none are given.
const DEFAULT_INJECTION: Injection =
    Injection { alpha_slow: 0.01, alpha_fast: 0.3, min_drop: 0.1, lost_share: 0.5 };

impl Default for CgrParams {
    fn default() -> Self {
        let o = LocalizeOptions::default();
        let (c, m) = (&o.cgr, o.motion);
        let injection = o.injection.unwrap_or(DEFAULT_INJECTION);
        CgrParams {
            map: PathBuf::new(),
            particles: o.particles,
            min_particles: None,
            init: "global".into(),
            start: None,
            resampling: o.resampling,
            resample_threshold: o.resample_threshold,
            scenes: "grid".into(),
            cell: 0.2,
            cache_dir: None,
            sigma: c.sigma,
            noise_per_r2: c.noise_per_r2,
            correlation: c.correlation,
            normal_tolerance_deg: c.normal_tolerance_deg,
            range: c.range,
            refine_iterations: c.refine_iterations,
            outlier_sigmas: c.outlier_sigmas,
            occlusion_fits: c.occlusion_fits,
            occluder_size: c.occluder_size,
            leave_out_corners: c.leave_out_corners,
            newton_step: c.newton_step,
            injection: o.injection.is_some(),
            alpha_slow: injection.alpha_slow,
            alpha_fast: injection.alpha_fast,
            min_drop: injection.min_drop,
            lost_share: injection.lost_share,
            srr: m.srr,
            srt: m.srt,
            str: m.str,
            stt: m.stt,
            keep_inside: o.inside_opening.is_some(),
            inside_opening: o.inside_opening.unwrap_or(squall_core::interior::DEFAULT_OPENING),
        }
    }
}

/// What one particle takes while CGR localizes, bytes: its pose and
/// weight, and its share of the per-reading scratch (its refined pose,
/// observation and report). Measured: the peak resident memory of
/// `squall localize --map EDSH120_vector.txt --sim --duration 2` grows by
/// 1.3 kB a particle from 100 000 to 400 000 particles.
const BYTES_PER_PARTICLE: usize = 1300;

/// Scene grids built in this process, by cache key: every matcher task
/// shares one. With a `dir`, the grid is also cached there on disk.
fn shared_grid(
    map: &LineMap,
    cell: Real,
    range: Real,
    dir: Option<&std::path::Path>,
) -> crate::Result<Arc<SceneGrid>> {
    static GRIDS: OnceLock<Mutex<HashMap<u64, Arc<SceneGrid>>>> = OnceLock::new();
    let grids = GRIDS.get_or_init(Default::default);
    let mut grids = grids.lock().map_err(|_| Error::CachePoisoned)?;
    let key = SceneGrid::key(map, cell, range);
    if let Some(g) = grids.get(&key) {
        return Ok(g.clone());
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let grid = match dir {
        Some(dir) => {
            let (grid, built) = SceneGrid::load_or_build(map, cell, range, threads, dir)?;
            if built {
                tracing::info!("observable scenes precomputed and cached in {}", dir.display());
            }
            grid
        }
        None => SceneGrid::build(map, cell, range, threads)?,
    };
    let grid = Arc::new(grid);
    grids.insert(key, grid.clone());
    Ok(grid)
}

/// The `cgr` model from the matcher's params (without `model` and
/// `map_interval`).
pub(crate) fn cgr_model(table: toml::Table, budget: MemoryBudget) -> crate::Result<CgrModel> {
    let p: CgrParams = from_table(table)?;
    budget.check(
        format!("{} particles of about {BYTES_PER_PARTICLE} bytes", p.particles),
        p.particles as f64 * BYTES_PER_PARTICLE as f64,
    )?;
    if p.map.as_os_str().is_empty() {
        return Err(Error::Setting("`map` (a line-map file) is required".into()));
    }
    let init = match (p.init.as_str(), p.start) {
        ("global", _) => Init::Global,
        ("known", Some([x, y, theta])) => Init::Known(Pose2::new(x, y, theta)),
        ("known", None) => return Err(Error::Setting("init = \"known\" needs start = [x, y, theta]".into())),
        (other, _) => {
            return Err(Error::Setting(format!("init must be \"known\" or \"global\", got \"{other}\"")));
        }
    };
    let cgr = CgrOptions {
        sigma: p.sigma,
        noise_per_r2: p.noise_per_r2,
        correlation: p.correlation,
        normal_tolerance_deg: p.normal_tolerance_deg,
        range: p.range,
        refine_iterations: p.refine_iterations,
        outlier_sigmas: p.outlier_sigmas,
        occlusion_fits: p.occlusion_fits,
        occluder_size: p.occluder_size,
        leave_out_corners: p.leave_out_corners,
        newton_step: p.newton_step,
    };
    cgr.check()?;
    crate::error::positive("cell", p.cell)?;
    crate::error::non_negative("inside_opening", p.inside_opening)?;
    squall_topology::confine::check_read(&p.map)?;
    let map = Arc::new(LineMap::load(&p.map)?);
    let scenes = match p.scenes.as_str() {
        "on_demand" => None,
        "grid" => {
            let (width, height, bytes) = SceneGrid::size_before_scenes(&map, p.cell);
            budget.check(
                format!(
                    "observable scenes on a {width} × {height} grid (cell = {} m) over the map ({})",
                    squall_topology::spec::readable_number(p.cell),
                    p.map.display()
                ),
                bytes,
            )?;
            // A confined worker writes only where it was told: the cache
            // goes where `cache_dir` says (under its --out), or nowhere.
            let dir = match (&p.cache_dir, squall_topology::confine::policy()) {
                (Some(dir), _) => {
                    squall_topology::confine::check_write(dir)?;
                    Some(dir.clone())
                }
                (None, Some(_)) => None,
                (None, None) => Some(std::env::temp_dir().join("squall-scenes")),
            };
            Some(shared_grid(&map, p.cell, p.range, dir.as_deref())?)
        }
        other => {
            return Err(Error::Setting(format!("scenes must be \"grid\" or \"on_demand\", got \"{other}\"")));
        }
    };
    let options = LocalizeOptions {
        particles: p.particles,
        min_particles: p.min_particles.unwrap_or(p.particles),
        cgr,
        motion: MotionNoise { srr: p.srr, srt: p.srt, str: p.str, stt: p.stt },
        init,
        resampling: p.resampling,
        resample_threshold: p.resample_threshold,
        injection: p.injection.then_some(Injection {
            alpha_slow: p.alpha_slow,
            alpha_fast: p.alpha_fast,
            min_drop: p.min_drop,
            lost_share: p.lost_share,
        }),
        inside_opening: p.keep_inside.then_some(p.inside_opening),
    };
    CgrModel::new(map, scenes, options)
}
