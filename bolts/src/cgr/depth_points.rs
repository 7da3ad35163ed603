//! `cgr.fspf`: depth frames reduced by Fast Sampling Plane Filtering to the
//! 2-D points with normals that CGR matches.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use squall_core::camera::{CameraMount, DepthFrame};
use squall_core::depth_render::DepthCamera;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, Tuple};

use crate::cgr::fspf::{FspfOptions, PlaneFilter, PlaneFiltered};
use crate::cgr::observation::Observation2d;

/// `cgr.fspf`: each `DepthFrame` becomes an `Observation2d`: FSPF, then
/// the plane points to the robot frame with floor and ceiling dropped
/// (the camera of the `depth_sim` spout: D435, 0.8 m up, level).
#[derive(Debug)]
pub(crate) struct DepthPoints {
    filter: PlaneFilter,
    mount: CameraMount,
    rng: ChaCha8Rng,
    planes: PlaneFiltered,
}

/// `cgr.fspf`'s params; a param left out takes FSPF's default.
#[derive(Debug, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
struct P {
    /// n_max: plane points to extract per frame. The default is 2000.
    max_points: usize,
    /// The camera's depth noise, σ(z) = this × z² metres; the plane check
    /// widens to 3σ where that exceeds ε, and far walls are kept. The
    /// simulated D435's is 0.0015, the real D435 frames show about
    /// 0.001. The default is 0, the fixed ε (decision 0025).
    noise_per_z2: f64,
}

impl Default for P {
    fn default() -> Self {
        P { max_points: FspfOptions::default().max_points, noise_per_z2: FspfOptions::default().noise_per_z2 }
    }
}

impl DepthPoints {
    /// Builds it (the camera is the `depth_sim` spout's D435; the seed is
    /// the topology's).
    pub(crate) fn from_params(p: &Params) -> Result<Self, ParamError> {
        let params: P = p.parse()?;
        if params.max_points == 0 {
            return Err(ParamError::new("max_points must be at least 1"));
        }
        if !(params.noise_per_z2.is_finite() && params.noise_per_z2 >= 0.0) {
            return Err(ParamError::new(format!(
                "noise_per_z2 must be a finite number ≥ 0 (metres per square metre of depth), got {}",
                params.noise_per_z2
            )));
        }
        let camera = DepthCamera::d435_on_robot();
        let options = FspfOptions {
            max_points: params.max_points,
            noise_per_z2: params.noise_per_z2,
            ..FspfOptions::default()
        };
        Ok(DepthPoints {
            filter: PlaneFilter::new(options, camera.intrinsics),
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
