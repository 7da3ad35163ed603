//! Replaying recorded data at its recorded rate (times a factor): when
//! each record is due, and a wait for it that a stopping run cuts short.

use std::sync::Arc;
use std::time::{Duration, Instant};

use squall_topology::spec::readable_number;
use squall_topology::{ParamError, StopRequest};

/// How fast a spout replays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// As fast as downstream accepts.
    Max,
    /// The recorded rate times this factor (1.0 = real time).
    Recorded(f64),
}

/// Parses a `rate` parameter: `"max"` or a positive factor.
pub(crate) fn pace(rate: Option<&toml::Value>) -> Result<Pace, ParamError> {
    match rate {
        None => Ok(Pace::Max),
        Some(toml::Value::String(s)) if s == "max" => Ok(Pace::Max),
        Some(v) => match v.as_float().or_else(|| v.as_integer().map(|i| i as f64)) {
            Some(f) if f.is_finite() && f > 0.0 => Ok(Pace::Recorded(f)),
            _ => Err(ParamError::new(format!("rate must be \"max\" or a positive factor, got {v}"))),
        },
    }
}

/// A record's stamp that lies too far after the first to be waited for:
/// the wait is past what the clock can represent.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "stamp {} lies {} s after the first record's ({}): replayed at rate {factor}, \
     the wait cannot be timed; replay with rate = \"max\" or fix the stamp",
    readable_number(*.stamp), readable_number(.stamp - .first), readable_number(*.first)
)]
pub struct PaceError {
    /// The record's stamp, seconds.
    pub stamp: f64,
    /// The first record's stamp.
    pub first: f64,
    /// The rate factor.
    pub factor: f64,
}

/// The clock of a paced replay.
#[derive(Debug)]
pub(crate) struct Pacer {
    pace: Pace,
    /// Wall clock and stamp of the first record.
    clock: Option<(Instant, f64)>,
    /// The run's stop request, once the spout is open.
    stop: Option<Arc<StopRequest>>,
}

impl Pacer {
    pub(crate) fn new(pace: Pace) -> Self {
        Pacer { pace, clock: None, stop: None }
    }

    /// Cuts waits short when `stop` is requested (given at `open`).
    pub(crate) fn watch(&mut self, stop: Arc<StopRequest>) {
        self.stop = Some(stop);
    }

    /// Waits until the record stamped `stamp` is due (at once unpaced or
    /// when it is late). `Ok(true)` when it is due, `Ok(false)` when the
    /// run was asked to stop first: the caller returns without emitting.
    pub(crate) async fn wait_for(&mut self, stamp: f64) -> Result<bool, PaceError> {
        let Pace::Recorded(factor) = self.pace else { return Ok(true) };
        let (start, first) = *self.clock.get_or_insert((Instant::now(), stamp));
        let gap = stamp - first;
        let due = Duration::try_from_secs_f64((gap / factor).max(0.0))
            .ok()
            .and_then(|wait| start.checked_add(wait))
            .ok_or(PaceError { stamp, first, factor })?;
        let sleep = tokio::time::sleep_until(due.into());
        match &self.stop {
            None => {
                sleep.await;
                Ok(true)
            }
            Some(stop) => tokio::select! {
                () = sleep => Ok(true),
                () = stop.requested() => Ok(false),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn runtime() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_current_thread().enable_time().build().unwrap()
    }

    #[test]
    fn rate_is_max_or_a_positive_factor() {
        assert_eq!(pace(None).unwrap(), Pace::Max);
        assert_eq!(pace(Some(&toml::Value::String("max".into()))).unwrap(), Pace::Max);
        assert_eq!(pace(Some(&toml::Value::Float(2.5))).unwrap(), Pace::Recorded(2.5));
        assert_eq!(pace(Some(&toml::Value::Integer(1))).unwrap(), Pace::Recorded(1.0));
        assert!(pace(Some(&toml::Value::Float(-1.0))).is_err());
        assert!(pace(Some(&toml::Value::String("fast".into()))).is_err());
    }

    #[test]
    fn a_stamp_too_far_ahead_is_an_error_not_a_panic() {
        runtime().block_on(async {
            let mut pacer = Pacer::new(Pace::Recorded(1.0));
            assert_eq!(pacer.wait_for(10.0).await, Ok(true));
            let e = pacer.wait_for(1e300).await.unwrap_err();
            assert_eq!((e.first, e.factor), (10.0, 1.0));
            assert!(e.to_string().contains("stamp 1e300"), "{e}");
        });
    }

    #[test]
    fn a_stop_request_ends_a_long_wait() {
        runtime().block_on(async {
            let stop = Arc::new(StopRequest::default());
            let mut pacer = Pacer::new(Pace::Recorded(1.0));
            pacer.watch(stop.clone());
            assert_eq!(pacer.wait_for(0.0).await, Ok(true));
            // Ten million seconds ahead: only the stop can end the wait.
            let requester = async {
                tokio::task::yield_now().await;
                stop.request();
            };
            let (waited, ()) = tokio::join!(pacer.wait_for(1e7), requester);
            assert_eq!(waited, Ok(false));
            // A request made before the wait ends it at once.
            assert_eq!(pacer.wait_for(2e7).await, Ok(false));
        });
    }
}
