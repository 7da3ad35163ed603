//! What the sources do to their front scans on the way out: mark the
//! readings the laser wrote for "no return" as such ([`NoReturnCodes`]),
//! pose each scan at the instant it was measured ([`ScanClock`]) and,
//! where asked, mend the steps where the wheels slipped ([`SlipGuard`]);
//! and how they report it.

use squall_core::clock::{PoseSource, ScanClock};
use squall_core::geometry::Pose2;
use squall_core::no_return::{NoReturnCodes, NoReturnMode};
use squall_core::sensor::LaserReading;
use squall_core::slip::SlipGuard;
use squall_topology::Emitter;

/// A source's front scans between the reader and the stream.
#[derive(Debug)]
pub(crate) struct ScanConditioner {
    codes: NoReturnCodes,
    clock: ScanClock,
    slips: Option<SlipGuard>,
    /// Scans given out.
    emitted: u64,
}

impl ScanConditioner {
    /// Scans whose no-return readings are found as `no_return` says,
    /// timed by `clock`, their slips mended if `mend_slips`.
    pub(crate) fn new(no_return: &NoReturnMode, clock: ScanClock, mend_slips: bool) -> Self {
        ScanConditioner {
            codes: NoReturnCodes::new(no_return),
            clock,
            slips: mend_slips.then(SlipGuard::new),
            emitted: 0,
        }
    }

    /// An odometry message of the stream.
    pub(crate) fn odometry(&mut self, stamp: f64, pose: Pose2) {
        self.clock.odometry(stamp, pose);
    }

    /// A front scan as read.
    pub(crate) fn scan(&mut self, mut reading: LaserReading) {
        self.codes.observe(&reading);
        self.codes.mark(&mut reading);
        self.clock.scan(reading);
    }

    /// The end of the input: every held scan is ready.
    pub(crate) fn finish(&mut self) {
        self.clock.finish();
    }

    /// The next scan ready to go out, in order.
    pub(crate) fn next_ready(&mut self) -> Option<LaserReading> {
        let mut reading = self.clock.next_ready()?;
        // A code found while the scan waited in the warm-up.
        self.codes.mark(&mut reading);
        self.emitted += 1;
        Some(match &mut self.slips {
            Some(guard) => guard.mend(reading),
            None => reading,
        })
    }

    /// What was decided and mended, in `metrics.json`.
    pub(crate) fn report(&self, out: &mut Emitter) {
        report_codes(&self.codes, out);
        report_clock(&self.clock, self.emitted, out);
        report_slips(self.slips.as_ref(), out);
    }
}

/// The no-return codes in `metrics.json`: how many are known below the
/// declared range (`no_return_codes`), each band (`no_return_code_K_from_m`,
/// `_to_m`, lowest first), the readings marked, and the scans read when
/// the first was found.
fn report_codes(codes: &NoReturnCodes, out: &mut Emitter) {
    let bands = codes.bands();
    if !codes.detects() && bands.is_empty() {
        return;
    }
    out.count("no_return_codes", bands.len() as u64);
    for (k, band) in bands.iter().enumerate() {
        out.measured(&format!("no_return_code_{}_from_m", k + 1), band.from);
        out.measured(&format!("no_return_code_{}_to_m", k + 1), band.to);
    }
    out.count("no_return_readings_marked", codes.marked());
    if let Some(after) = codes.found_after_scans() {
        out.count("no_return_code_found_after_scans", after);
    }
}

/// The clock's decision in `metrics.json`: the offset applied
/// (`clock_offset_ms`), the estimate's standard error and the odometry's
/// turn scale where one was made, and the scans counted by where their
/// pose came from (`emitted` of them in all).
fn report_clock(clock: &ScanClock, emitted: u64, out: &mut Emitter) {
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
fn report_slips(guard: Option<&SlipGuard>, out: &mut Emitter) {
    if let Some(g) = guard {
        let (slips, steps) = g.counts();
        out.count("slipped_steps", slips);
        out.count("slip_tested_steps", steps);
    }
}
