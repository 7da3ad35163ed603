//! The localization kinds: `cgr.laser` turns laser scans into the 2-D
//! points with normals that CGR matches, and the `cgr` model for the
//! particle filter kinds (`model = "cgr"`), built from the matcher's
//! params: the map file, particles, start, resampling, measurement and
//! motion settings, and where precomputed scenes are cached.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use serde::Deserialize;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, Tuple};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use crate::cgr::measurement::CgrOptions;
use crate::cgr::model::{CgrModel, Init, LocalizeOptions};
use crate::cgr::observation::Observation2d;
use crate::cgr::scene_grid::SceneGrid;
use crate::pf::model::Injection;
use crate::pf::resample::Scheme;
use crate::pf_topology::from_table;
use squall_core::camera::{CameraMount, DepthFrame};
use squall_core::depth_render::DepthCamera;
use squall_core::geometry::{Pose2, Real};
use squall_core::linemap::LineMap;
use squall_core::motion::MotionNoise;
use squall_core::sensor::LaserReading;

/// `cgr.laser`: each `LaserReading` becomes an `Observation2d` (beams up
/// to `max_range`, default 8 m).
#[derive(Debug)]
pub struct LaserPoints {
    max_range: Real,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LaserParams {
    #[serde(default = "default_range")]
    max_range: Real,
}

fn default_range() -> Real {
    8.0
}

impl LaserPoints {
    /// Builds it from `max_range`.
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: LaserParams = p.parse()?;
        if !(params.max_range.is_finite() && params.max_range > 0.0) {
            return Err(ParamError::new(format!("max_range must be > 0, got {}", params.max_range)));
        }
        Ok(LaserPoints { max_range: params.max_range })
    }
}

impl Bolt for LaserPoints {
    fn declare(&self, d: &mut Declarer) {
        d.input::<LaserReading>().output::<Observation2d>("default");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let scan = input.get::<LaserReading>().ok_or("cgr.laser takes LaserReading")?;
        out.emit("default", Observation2d::from_laser(scan, self.max_range)).await?;
        Ok(())
    }
}

/// `cgr.fspf`: each `DepthFrame` becomes an `Observation2d`: FSPF, then
/// the plane points to the robot frame with floor and ceiling dropped
/// (the camera of the `depth_sim` spout: D435, 0.8 m up, level).
#[derive(Debug)]
pub struct DepthPoints {
    filter: PlaneFilter,
    mount: CameraMount,
    rng: ChaCha8Rng,
    planes: PlaneFiltered,
}

impl DepthPoints {
    /// Builds it (params: none yet; the seed is the topology's).
    pub fn from_params(p: &Params) -> Result<Self, ParamError> {
        if !p.table().is_empty() {
            return Err(ParamError::new("cgr.fspf takes no params yet (the D435 on the depth_sim robot)"));
        }
        let camera = DepthCamera::d435_on_robot();
        Ok(DepthPoints {
            filter: PlaneFilter::new(FspfOptions::default(), camera.intrinsics),
            mount: camera.mount,
            rng: ChaCha8Rng::seed_from_u64(p.seed() ^ 0xf5bf),
            planes: PlaneFiltered::default(),
        })
    }
}

impl Bolt for DepthPoints {
    fn declare(&self, d: &mut Declarer) {
        d.input::<DepthFrame>().output::<Observation2d>("default");
    }

    async fn execute(&mut self, input: Tuple, out: &mut Emitter) -> Result<(), BoxError> {
        let frame = input.get::<DepthFrame>().ok_or("cgr.fspf takes DepthFrame")?;
        let started = std::time::Instant::now();
        self.filter.filter(&frame.image, &mut self.rng, &mut self.planes);
        out.record("fspf_us", started.elapsed().as_micros() as u64);
        let obs =
            Observation2d::from_plane_filtered(&self.planes, &self.mount, 0.5, frame.stamp, frame.odometry);
        out.record("wall_points", obs.points.len() as u64);
        out.emit("default", obs).await?;
        Ok(())
    }
}

/// The `cgr` model's params, flat; any left out takes the default of
/// [`LocalizeOptions`] / [`CgrOptions`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct CgrParams {
    /// The line-map file (required).
    map: PathBuf,
    particles: usize,
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
    correlation: Real,
    normal_tolerance_deg: Real,
    range: Real,
    refine_iterations: u32,
    outlier_sigmas: Real,
    /// Augmented MCL (random particles when observations stop fitting):
    /// off by default; `injection = true` with `alpha_slow`, `alpha_fast`
    /// and `min_drop`.
    injection: bool,
    alpha_slow: Real,
    alpha_fast: Real,
    min_drop: Real,
    srr: Real,
    srt: Real,
    str: Real,
    stt: Real,
}

/// Augmented MCL's rates when `injection = true` and none are given.
const DEFAULT_INJECTION: Injection = Injection { alpha_slow: 0.01, alpha_fast: 0.3, min_drop: 0.1 };

impl Default for CgrParams {
    fn default() -> Self {
        let o = LocalizeOptions::default();
        let (c, m) = (&o.cgr, o.motion);
        let injection = o.injection.unwrap_or(DEFAULT_INJECTION);
        CgrParams {
            map: PathBuf::new(),
            particles: o.particles,
            init: "global".into(),
            start: None,
            resampling: o.resampling,
            resample_threshold: o.resample_threshold,
            scenes: "grid".into(),
            cell: 0.2,
            cache_dir: None,
            sigma: c.sigma,
            correlation: c.correlation,
            normal_tolerance_deg: c.normal_tolerance_deg,
            range: c.range,
            refine_iterations: c.refine_iterations,
            outlier_sigmas: c.outlier_sigmas,
            injection: o.injection.is_some(),
            alpha_slow: injection.alpha_slow,
            alpha_fast: injection.alpha_fast,
            min_drop: injection.min_drop,
            srr: m.srr,
            srt: m.srt,
            str: m.str,
            stt: m.stt,
        }
    }
}

/// Scene grids built in this process, by cache key: every matcher task
/// shares one.
fn shared_grid(
    map: &LineMap,
    cell: Real,
    range: Real,
    dir: &std::path::Path,
) -> Result<Arc<SceneGrid>, String> {
    static GRIDS: OnceLock<Mutex<HashMap<u64, Arc<SceneGrid>>>> = OnceLock::new();
    let grids = GRIDS.get_or_init(Default::default);
    let mut grids = grids.lock().map_err(|_| "the scene grid cache was poisoned".to_string())?;
    let key = SceneGrid::key(map, cell, range);
    if let Some(g) = grids.get(&key) {
        return Ok(g.clone());
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (grid, built) =
        SceneGrid::load_or_build(map, cell, range, threads, dir).map_err(|e| e.to_string())?;
    if built {
        tracing::info!("observable scenes precomputed and cached in {}", dir.display());
    }
    let grid = Arc::new(grid);
    grids.insert(key, grid.clone());
    Ok(grid)
}

/// The `cgr` model from the matcher's params (without `model` and
/// `map_interval`).
pub fn cgr_model(table: toml::Table) -> Result<CgrModel, String> {
    let p: CgrParams = from_table(table)?;
    if p.map.as_os_str().is_empty() {
        return Err("`map` (a line-map file) is required".into());
    }
    let init = match (p.init.as_str(), p.start) {
        ("global", _) => Init::Global,
        ("known", Some([x, y, theta])) => Init::Known(Pose2::new(x, y, theta)),
        ("known", None) => return Err("init = \"known\" needs start = [x, y, theta]".into()),
        (other, _) => return Err(format!("init must be \"known\" or \"global\", got \"{other}\"")),
    };
    let cgr = CgrOptions {
        sigma: p.sigma,
        correlation: p.correlation,
        normal_tolerance_deg: p.normal_tolerance_deg,
        range: p.range,
        refine_iterations: p.refine_iterations,
        outlier_sigmas: p.outlier_sigmas,
    };
    cgr.check()?;
    if !(p.cell.is_finite() && p.cell > 0.0) {
        return Err(format!("cell must be > 0, got {}", p.cell));
    }
    let map = Arc::new(LineMap::load(&p.map).map_err(|e| e.to_string())?);
    let scenes = match p.scenes.as_str() {
        "on_demand" => None,
        "grid" => {
            let dir = p.cache_dir.clone().unwrap_or_else(|| std::env::temp_dir().join("squall-scenes"));
            Some(shared_grid(&map, p.cell, p.range, &dir)?)
        }
        other => return Err(format!("scenes must be \"grid\" or \"on_demand\", got \"{other}\"")),
    };
    let options = LocalizeOptions {
        particles: p.particles,
        cgr,
        motion: MotionNoise { srr: p.srr, srt: p.srt, str: p.str, stt: p.stt },
        init,
        resampling: p.resampling,
        resample_threshold: p.resample_threshold,
        injection: p.injection.then_some(Injection {
            alpha_slow: p.alpha_slow,
            alpha_fast: p.alpha_fast,
            min_drop: p.min_drop,
        }),
    };
    CgrModel::new(map, scenes, options)
}
