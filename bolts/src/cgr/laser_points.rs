//! `cgr.laser`: laser scans as the 2-D points with normals that CGR
//! matches.

use serde::Deserialize;
use squall_core::geometry::Real;
use squall_core::sensor::LaserReading;
use squall_topology::{Bolt, BoxError, Declarer, Emitter, ParamError, Params, Tuple};

use crate::cgr::observation::Observation2d;

/// `cgr.laser`: each `LaserReading` becomes an `Observation2d` (beams up
/// to `max_range`, default 8 m).
#[derive(Debug)]
pub(crate) struct LaserPoints {
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
    pub(crate) fn from_params(p: &Params) -> Result<Self, ParamError> {
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
