//! The command line's numbers: clap value parsers that refuse, before
//! anything runs, a value past its bound ([`squall_topology::bounds`]),
//! so clap exits 2 naming the flag, the value and what is allowed
//! (`error: invalid value '1e300' for '--ui-linger <SECS>': expected
//! seconds in [0, 604800] (a week)`). `docs/guide/limits.md` has the
//! table.

use squall_topology::bounds::{self, MAX_BEAMS, MAX_SIM_SECS};
use squall_topology::spec::{MAX_PARALLELISM, readable_number};

/// The farthest a laser's range may be set, metres: the longest-range 2D
/// lidars reach 300 m, and simulated rays are cast this far.
pub(crate) const MAX_RANGE_M: f64 = 1000.0;

/// The fastest a log may be played back, times its own pace: a
/// thousand times is past what any consumer keeps up with, while a log's
/// gaps divided by more underflow the clock's nanoseconds.
#[cfg(feature = "cluster")]
pub(crate) const MAX_SPEED: f64 = 1000.0;

/// The slowest, times its own pace (a thousandth): a 10 Hz laser's
/// gaps become minutes, inside the week any wait may last.
#[cfg(feature = "cluster")]
pub(crate) const MIN_SPEED: f64 = 1e-3;

fn number(s: &str) -> Result<f64, String> {
    s.trim().parse::<f64>().map_err(|_| format!("expected a number, got \"{s}\""))
}

/// The message clap prints after the value: the bound's `expected`.
fn expected(e: bounds::BoundError) -> String {
    format!("expected {}", e.expected)
}

/// Seconds to wait, 0 allowed: [0, a week].
pub(crate) fn wait_secs(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::wait_secs("", v, true).map(|_| v).map_err(expected)
}

/// Seconds to wait, more than 0: (0, a week] (`worker`, `robot`).
#[cfg(feature = "cluster")]
pub(crate) fn positive_wait_secs(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::wait_secs("", v, false).map(|_| v).map_err(expected)
}

/// A period, seconds: [0.1, a week] (shorter ones would rewrite a file
/// faster than a person reads it, and cost the run).
pub(crate) fn period_secs(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::real("", v, 0.1, bounds::MAX_WAIT_SECS, "seconds", "a week at most").map_err(expected)
}

/// Simulated seconds: (0, [`MAX_SIM_SECS`]].
pub(crate) fn sim_secs(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v.is_finite() && v > 0.0 && v <= MAX_SIM_SECS {
        Ok(v)
    } else {
        Err(format!(
            "expected simulated seconds in (0, {}] (stamps keep a microsecond's resolution)",
            readable_number(MAX_SIM_SECS)
        ))
    }
}

/// Seconds into a simulated run: [0, [`MAX_SIM_SECS`]].
pub(crate) fn sim_instant(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::real("", v, 0.0, MAX_SIM_SECS, "seconds", "").map_err(expected)
}

/// A playback speed: [[`MIN_SPEED`], [`MAX_SPEED`]].
#[cfg(feature = "cluster")]
pub(crate) fn speed(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::real("", v, MIN_SPEED, MAX_SPEED, "a factor of the log's pace", "").map_err(expected)
}

/// A field of view, degrees: [1, 360] (a scanner narrower than a degree
/// is a range finder; wider than a turn sees its own beams again).
pub(crate) fn fov_deg(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::real("", v, 1.0, 360.0, "degrees", "one turn at most").map_err(expected)
}

/// A laser's range, metres: (0, [`MAX_RANGE_M`]].
pub(crate) fn range_m(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v.is_finite() && v > 0.0 && v <= MAX_RANGE_M {
        Ok(v)
    } else {
        Err(format!("expected metres in (0, {MAX_RANGE_M}] (the longest-range 2D lidars reach 300 m)"))
    }
}

/// A simulated scan's latency, seconds: [0, 0.5] (as the clock's
/// search).
pub(crate) fn latency_secs(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::real("", v, 0.0, 0.5, "seconds", "as far as the scan clock searches").map_err(expected)
}

/// A simulated odometry rate, Hz: [0, 50] (0: one message a scan; 50:
/// the simulator's physics rate).
pub(crate) fn odom_hz(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::real("", v, 0.0, 50.0, "messages a second", "the simulator's physics rate").map_err(expected)
}

/// The mean time between simulated wheel slips, seconds: [10, 10⁹].
pub(crate) fn slip_every_secs(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    bounds::real("", v, 10.0, MAX_SIM_SECS, "seconds", "a slip lasts up to 6 s").map_err(expected)
}

/// A systematic share of error: (-0.5, 0.5).
pub(crate) fn error_share(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v.is_finite() && v.abs() < 0.5 {
        Ok(v)
    } else {
        Err("expected a share in (-0.5, 0.5) (0.05: 5% too much)".into())
    }
}

/// Beams of a scan: 2..=[`MAX_BEAMS`].
pub(crate) fn beams(s: &str) -> Result<usize, String> {
    let v: u64 = s.trim().parse().map_err(|_| format!("expected a count, got \"{s}\""))?;
    bounds::count("", v, 2, MAX_BEAMS as u64, "a scan needs a first and a last beam; no laser has more")
        .map(|v| v as usize)
        .map_err(expected)
}

/// Tasks of one component: 1..=[`MAX_PARALLELISM`].
pub(crate) fn tasks(s: &str) -> Result<usize, String> {
    let v: u64 = s.trim().parse().map_err(|_| format!("expected a count, got \"{s}\""))?;
    bounds::count("", v, 1, MAX_PARALLELISM as u64, "a component's most tasks")
        .map(|v| v as usize)
        .map_err(expected)
}

/// A seed that a topology takes (TOML's integers are 64-bit signed):
/// 0..=[`i64::MAX`].
pub(crate) fn seed(s: &str) -> Result<u64, String> {
    let v: u64 = s.trim().parse().map_err(|_| format!("expected a count, got \"{s}\""))?;
    bounds::count("", v, 0, i64::MAX as u64, "a topology's integers are 64-bit signed").map_err(expected)
}

/// Pose evaluations per particle per reading: `none` or a count of 1 or
/// more (as [`positive_count`]); kept as the text the topology takes.
pub(crate) fn cutoff(s: &str) -> Result<String, String> {
    if s.trim() == "none" {
        return Ok("none".into());
    }
    positive_count(s).map(|n| n.to_string()).map_err(|e| format!("{e}, or none"))
}

/// A count of 1 or more that a topology takes as an integer (TOML's are
/// 64-bit signed): 1..=[`i64::MAX`]. What the count costs (particles'
/// memory) is checked against the memory limit when the topology is.
pub(crate) fn positive_count(s: &str) -> Result<u64, String> {
    let v: u64 = s.trim().parse().map_err(|_| format!("expected a count, got \"{s}\""))?;
    bounds::count("", v, 1, i64::MAX as u64, "").map_err(expected)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_parser_refuses_the_hostile_values_with_its_bound() {
        type Parser = fn(&str) -> Result<f64, String>;
        let parsers: Vec<(&str, Parser)> = vec![
            ("wait", wait_secs),
            ("period", period_secs),
            ("sim", sim_secs),
            ("instant", sim_instant),
            ("fov", fov_deg),
            ("range", range_m),
        ];
        #[cfg(feature = "cluster")]
        let parsers =
            [parsers, vec![("positive wait", positive_wait_secs as Parser), ("speed", speed)]].concat();
        for (name, parse) in parsers {
            for bad in ["-1", "NaN", "inf", "-inf", "1e300", "1.7976931348623157e308", "x", ""] {
                let e = parse(bad).expect_err(&format!("{name} took {bad}"));
                assert!(e.starts_with("expected "), "{name} {bad}: {e}");
            }
        }
        assert_eq!(wait_secs("0"), Ok(0.0));
        assert!(sim_secs("0").is_err());
        #[cfg(feature = "cluster")]
        assert!(positive_wait_secs("0").is_err() && speed("0").is_err());
        assert_eq!(sim_secs("600"), Ok(600.0));
        for count in [beams as fn(&str) -> Result<usize, String>, tasks] {
            for bad in ["0", "-1", "18446744073709551616", "1e3", "NaN"] {
                assert!(count(bad).is_err(), "{bad}");
            }
        }
        assert_eq!(beams("65536"), Ok(65536));
        assert!(beams("65537").is_err());
        assert!(positive_count("9223372036854775808").is_err());
        assert_eq!(positive_count("9223372036854775807"), Ok(i64::MAX as u64));
    }
}
