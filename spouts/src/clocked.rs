//! What the sources share about timing their scans: how the
//! [`ScanClock`]'s decision is reported.

use squall_core::clock::{PoseSource, ScanClock};
use squall_core::slip::SlipGuard;
use squall_topology::Emitter;

/// The clock's decision in `metrics.json`: the offset applied
/// (`clock_offset_ms`), the estimate's standard error and the odometry's
/// turn scale where one was made, and the scans counted by where their
/// pose came from (`emitted` of them in all).
pub(crate) fn report_clock(clock: &ScanClock, emitted: u64, out: &mut Emitter) {
    let Some(report) = clock.report() else { return };
    out.measured("clock_offset_ms", 1e3 * report.offset);
    if let Some(e) = report.estimate {
        out.measured("clock_offset_estimate_ms", 1e3 * e.offset);
        out.measured("clock_offset_standard_error_ms", 1e3 * e.standard_error.min(1e6));
        out.measured("odometry_turn_scale", e.turn_scale);
        out.count("clock_pairs", e.pairs as u64);
    }
    out.count("clock_warmup_scans", report.warmup_scans as u64);
    let source = match report.source {
        PoseSource::OdometryStream => "scans_posed_from_odometry_stream",
        PoseSource::ScanPoses => "scans_posed_from_scan_poses",
        PoseSource::AsLogged => "scans_posed_as_logged",
    };
    let (held, flowed) = (clock.held_as_logged(), clock.flowed_as_logged());
    out.count(source, emitted.saturating_sub(held + flowed));
    if flowed > 0 {
        out.count("scans_posed_as_logged_in_the_warmup", flowed);
    }
    if held > 0 {
        out.count("scans_posed_as_logged_beyond_the_odometry", held);
    }
}

/// The slip guard's counts in `metrics.json`: the steps it found slipped
/// and mended (`slipped_steps`) of those it tested (`slip_tested_steps`).
pub(crate) fn report_slips(guard: Option<&SlipGuard>, out: &mut Emitter) {
    if let Some(g) = guard {
        let (slips, steps) = g.counts();
        out.count("slipped_steps", slips);
        out.count("slip_tested_steps", steps);
    }
}
