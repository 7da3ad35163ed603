//! The bounds on the numbers a user gives: command-line flags, topology
//! keys and component params. Each bound follows from what the machine or
//! the algorithm can do (a clock's range, a float's resolution, the
//! memory a structure takes), and is checked before anything runs, so a
//! number past it is an error naming the flag or key, the value and the
//! bound, never a panic, an abort or a run that cannot end.
//! `docs/guide/limits.md` has the table of them.
//!
//! Two kinds of bound:
//!
//! - fixed ones ([`MAX_WAIT_SECS`], [`MAX_SIM_SECS`], [`MAX_BEAMS`], …),
//!   checked by [`wait_secs`], [`count`] and [`real`];
//! - the memory a component's structures would take before its first
//!   tuple (particles, an index over a map, a simulated run's outputs),
//!   checked by a [`MemoryBudget`] against the run's memory limit, which
//!   the user can raise (`[topology] memory_limit_mb`).

use std::fmt;
use std::time::Duration;

use crate::spec::readable_number;

/// The longest wait, timeout, linger or period, seconds (a week): longer
/// ones cannot be timed on every platform's clock (tokio's timer wheel
/// reaches about two years; `Instant` arithmetic overflows past a few
/// hundred years), and no run of squall waits a week on purpose.
pub const MAX_WAIT_SECS: f64 = 7.0 * 24.0 * 3600.0;

/// The longest simulated run, seconds (about 32 years). Stamps are `f64`
/// seconds: up to 2⁵² µs (4.5 × 10⁹ s) they keep a microsecond's
/// resolution, a thousandth of the fastest sensor's period, so every
/// step's stamp stays distinct and ordered; past that, adding a physics
/// step to the clock stops changing it and a run never ends. The memory
/// a long run's outputs take is checked against the memory limit as well.
pub const MAX_SIM_SECS: f64 = 1e9;

/// The most beams one scan may carry. The densest lasers sold give a few
/// thousand beams a turn (a Hokuyo UST-10LX 1081, a SICK LMS4000 1800
/// over 70°); 65 536 leaves room for any and for depth-camera rows,
/// while a claimed million per scan is a corrupt record.
pub const MAX_BEAMS: usize = 1 << 16;

/// The widest angular span of one scan, radians: a full turn (plus a
/// beam's float error). A wider one would see its own beams again.
pub const MAX_SCAN_SPAN: f64 = std::f64::consts::TAU * (1.0 + 1e-6);

/// A number outside its bound.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{name} {value}: expected {expected}")]
pub struct BoundError {
    /// The flag or key (`--ui-linger`, `matcher.params.particles`).
    pub name: String,
    /// The value as given.
    pub value: String,
    /// What is allowed, with the bound and, where it helps, why.
    pub expected: String,
}

impl BoundError {
    /// `name` with `value` is refused: `expected` says what is allowed.
    pub fn new(name: impl fmt::Display, value: impl fmt::Display, expected: impl fmt::Display) -> Self {
        BoundError { name: name.to_string(), value: value.to_string(), expected: expected.to_string() }
    }
}

/// A wait of `secs` seconds given as `name`: a duration in
/// [0, [`MAX_WAIT_SECS`]] (or (0, …] when `zero_allowed` is false).
pub fn wait_secs(name: &str, secs: f64, zero_allowed: bool) -> Result<Duration, BoundError> {
    let low_ok = if zero_allowed { secs >= 0.0 } else { secs > 0.0 };
    if low_ok && secs <= MAX_WAIT_SECS {
        return Ok(Duration::from_secs_f64(secs));
    }
    let low = if zero_allowed { "[0" } else { "(0" };
    Err(BoundError::new(name, readable_number(secs), format!("seconds in {low}, {MAX_WAIT_SECS}] (a week)")))
}

/// A real number given as `name`, finite and in `low..=high`; `unit`
/// names what it measures (`"metres"`) and `why` the bound's reason, for
/// the message.
pub fn real(name: &str, value: f64, low: f64, high: f64, unit: &str, why: &str) -> Result<f64, BoundError> {
    if value.is_finite() && (low..=high).contains(&value) {
        return Ok(value);
    }
    let why = if why.is_empty() { String::new() } else { format!(" ({why})") };
    Err(BoundError::new(
        name,
        readable_number(value),
        format!("{unit} in [{}, {}]{why}", readable_number(low), readable_number(high)),
    ))
}

/// A count given as `name`, in `low..=high`; `why` is the bound's reason.
pub fn count(name: &str, value: u64, low: u64, high: u64, why: &str) -> Result<u64, BoundError> {
    if (low..=high).contains(&value) {
        return Ok(value);
    }
    let why = if why.is_empty() { String::new() } else { format!(" ({why})") };
    Err(BoundError::new(name, value, format!("a count in {low}..={high}{why}")))
}

/// The memory a run may take, for checking what a component's structures
/// would need before the run starts against it: the run's memory limit
/// (`[topology] memory_limit_mb`, by default 90% of what the machine or
/// its cgroup allows), or no limit where neither is known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryBudget {
    limit: Option<u64>,
    /// How a user raises the limit, for the message.
    raised_with: &'static str,
}

/// How a run's limit is raised: its topology's key.
const TOPOLOGY_LIMIT: &str =
    "[topology] memory_limit_mb; on the command line --set topology.memory_limit_mb=N";

impl Default for MemoryBudget {
    fn default() -> Self {
        MemoryBudget { limit: None, raised_with: TOPOLOGY_LIMIT }
    }
}

/// What a component would need is past the memory limit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{what} would take {} before the run starts, past the memory limit of {} (by default 90% of \
     this machine's memory; {raised_with}): ask for less, or raise the limit",
    mib(*bytes),
    mib(*limit as f64)
)]
pub struct OverBudget {
    /// What was estimated, with the settings that decide it.
    pub what: String,
    /// The estimate, bytes.
    pub bytes: f64,
    /// The limit, bytes.
    pub limit: u64,
    /// How the limit is raised.
    pub raised_with: &'static str,
}

/// Bytes as MiB or GiB for a message.
fn mib(bytes: f64) -> String {
    let mib = bytes / (1024.0 * 1024.0);
    if mib >= 10.0 * 1024.0 {
        format!("{} GiB", readable_number((mib / 1024.0).round()))
    } else {
        format!("{} MiB", readable_number(mib.ceil()))
    }
}

impl MemoryBudget {
    /// A budget of `limit` bytes; `None`, no limit.
    pub fn new(limit: Option<u64>) -> Self {
        MemoryBudget { limit, ..MemoryBudget::default() }
    }

    /// The same budget, its messages saying the limit is raised with
    /// `how` (a flag) rather than the topology's key.
    pub fn raised_with(self, how: &'static str) -> Self {
        MemoryBudget { raised_with: how, ..self }
    }

    /// The limit a run gets from its topology's `memory_limit_mb`
    /// (`configured`), or by default 90% of the machine's memory.
    pub fn for_run(configured: Option<u64>) -> Self {
        MemoryBudget::new(configured.or_else(crate::runtime::memory::default_limit))
    }

    /// The limit, bytes.
    pub fn limit(&self) -> Option<u64> {
        self.limit
    }

    /// Checks that `bytes` (an estimate of what `what` takes; NaN or
    /// infinite counts as too much) fits the limit.
    pub fn check(&self, what: impl fmt::Display, bytes: f64) -> Result<(), OverBudget> {
        match self.limit {
            Some(limit) if bytes.is_nan() || bytes > limit as f64 => {
                Err(OverBudget { what: what.to_string(), bytes, limit, raised_with: self.raised_with })
            }
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_are_bounded_by_a_week_and_name_the_flag() {
        assert_eq!(wait_secs("--ui-linger", 2.5, true), Ok(Duration::from_millis(2500)));
        assert_eq!(wait_secs("--ui-linger", 0.0, true), Ok(Duration::ZERO));
        for bad in [-1.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, MAX_WAIT_SECS * 1.01] {
            let e = wait_secs("--ui-linger", bad, true).unwrap_err();
            assert!(e.to_string().starts_with("--ui-linger "), "{e}");
            assert!(e.to_string().contains("604800"), "{e}");
        }
        assert_eq!(
            wait_secs("--connect-secs", 0.0, false).unwrap_err().to_string(),
            "--connect-secs 0: expected seconds in (0, 604800] (a week)"
        );
        assert_eq!(
            wait_secs("x", 1e300, true).unwrap_err().value,
            "1e300",
            "huge values are written as a person reads them"
        );
    }

    #[test]
    fn reals_and_counts_say_the_range_and_why() {
        assert_eq!(real("--speed", 2.0, 1e-3, 1e3, "a factor", ""), Ok(2.0));
        let e = real("--speed", f64::NAN, 1e-3, 1e3, "a factor", "the log's clock").unwrap_err();
        assert_eq!(e.to_string(), "--speed NaN: expected a factor in [0.001, 1000] (the log's clock)");
        assert_eq!(
            count("--matchers", 0, 1, 1024, "").unwrap_err().to_string(),
            "--matchers 0: expected a count in 1..=1024"
        );
    }

    #[test]
    fn a_budget_refuses_what_would_not_fit_and_says_how_to_raise_it() {
        let budget = MemoryBudget::new(Some(1 << 30));
        assert_eq!(budget.check("x", 1e9), Ok(()));
        let e = budget.check("100000000 particles of 624 bytes", 6.24e10).unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with("100000000 particles of 624 bytes would take 58 GiB"), "{text}");
        assert!(text.contains("1024 MiB") && text.contains("memory_limit_mb"), "{text}");
        assert!(budget.check("x", f64::NAN).is_err() && budget.check("x", f64::INFINITY).is_err());
        assert_eq!(MemoryBudget::new(None).check("x", f64::INFINITY), Ok(()));
    }
}
