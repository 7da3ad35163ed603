use super::*;
use crate::scan_match::room::scan_in_room;

const HALF: (Real, Real) = (5.0, 3.0);
const PILLARS: [(Real, Real); 2] = [(2.0, 1.0), (-2.5, -1.2)];

/// The robot's true pose at `t`: wandering a little and turning back and
/// forth at a changing rate.
fn truth(t: f64) -> Pose2 {
    Pose2::new(
        0.6 * (0.3 * t).sin(),
        0.4 * (0.2 * t).cos() - 0.4,
        normalize_angle(0.8 * (0.7 * t).sin() + 0.3 * (1.9 * t).sin()),
    )
}

/// A log of `seconds`: odometry at 50 Hz, scans at 10 Hz stamped `lag`
/// after they were measured, each with the odometry at its stamp attached
/// (what a driver that stamps on arrival records). Readings in log order.
enum Reading {
    Odom(f64, Pose2),
    Scan(LaserReading),
}

fn log(seconds: f64, lag: f64, with_stream: bool) -> Vec<Reading> {
    let mut out = Vec::new();
    let (mut next_odom, mut next_scan) = (0.0, 0.05);
    while next_scan < seconds {
        if with_stream && next_odom <= next_scan + lag {
            out.push(Reading::Odom(next_odom, truth(next_odom)));
            next_odom += 0.02;
        } else {
            let stamp = next_scan + lag;
            let mut scan = scan_in_room(truth(next_scan), truth(stamp), HALF, &PILLARS);
            scan.stamp = stamp;
            out.push(Reading::Scan(scan));
            next_scan += 0.1;
        }
    }
    // The odometry goes on a little after the last scan, as on a robot.
    while with_stream && next_odom <= seconds + 0.5 {
        out.push(Reading::Odom(next_odom, truth(next_odom)));
        next_odom += 0.02;
    }
    out
}

/// Runs `readings` through a clock in `mode`; the scans it gives out.
fn run(mode: ClockMode, readings: Vec<Reading>) -> (ScanClock, Vec<LaserReading>) {
    let mut clock = ScanClock::new(mode);
    let mut out = Vec::new();
    for r in readings {
        match r {
            Reading::Odom(t, p) => clock.odometry(t, p),
            Reading::Scan(s) => clock.scan(s),
        }
        while let Some(s) = clock.next_ready() {
            out.push(s);
        }
    }
    clock.finish();
    while let Some(s) = clock.next_ready() {
        out.push(s);
    }
    (clock, out)
}

/// The largest heading error of `scans` against the truth at their
/// measured instants (stamp − `lag`).
fn worst_heading_error(scans: &[LaserReading], lag: f64) -> Real {
    scans
        .iter()
        .map(|s| normalize_angle(s.odometry.theta - truth(s.stamp - lag).theta).abs())
        .fold(0.0, Real::max)
}

#[test]
fn learns_a_known_lag_from_the_odometry_stream_and_poses_every_scan_at_its_instant() {
    for lag in [0.08, -0.05] {
        let readings = log(80.0, lag, true);
        let scans_in = readings.iter().filter(|r| matches!(r, Reading::Scan(_))).count();
        let (clock, out) = run(ClockMode::Auto, readings);
        let report = clock.report().expect("decided");
        assert_eq!(report.source, PoseSource::OdometryStream);
        assert!((report.offset + lag).abs() < 0.005, "lag {lag}: {report:?}");
        assert!(report.warmup_scans < scans_in, "the warm-up ended early: {report:?}");
        assert_eq!(out.len(), scans_in, "every scan is given out, in order");
        assert!(out.windows(2).all(|w| w[0].stamp < w[1].stamp));
        // As logged the heading is off by up to the turn rate times the
        // lag; re-posed it is within the estimate's error.
        assert!(worst_heading_error(&out, lag) < 0.01, "{} {report:?}", worst_heading_error(&out, lag));
        assert_eq!(clock.held_as_logged(), 0);
    }
}

#[test]
fn without_an_odometry_stream_the_scans_own_poses_are_interpolated() {
    let (clock, out) = run(ClockMode::Auto, log(80.0, 0.08, false));
    let report = clock.report().unwrap();
    assert_eq!(report.source, PoseSource::ScanPoses);
    assert!((report.offset + 0.08).abs() < 0.01, "{report:?}");
    assert!(worst_heading_error(&out[1..], 0.08) < 0.02, "{}", worst_heading_error(&out[1..], 0.08));
}

#[test]
fn a_known_offset_is_applied_and_the_log_mode_keeps_the_recorded_poses() {
    let (clock, out) = run(ClockMode::Fixed(-0.08), log(20.0, 0.08, true));
    assert_eq!(clock.report().unwrap().source, PoseSource::OdometryStream);
    assert!(worst_heading_error(&out, 0.08) < 1e-3);
    let readings = log(20.0, 0.08, true);
    let logged: Vec<Pose2> = readings
        .iter()
        .filter_map(|r| match r {
            Reading::Scan(s) => Some(s.odometry),
            _ => None,
        })
        .collect();
    let (clock, out) = run(ClockMode::Log, readings);
    assert_eq!(clock.report().unwrap().source, PoseSource::AsLogged);
    assert_eq!(out.iter().map(|s| s.odometry).collect::<Vec<_>>(), logged);
}

#[test]
fn a_robot_that_never_turns_keeps_the_logged_poses() {
    // Straight along the room: no change of turn rate, nothing to learn.
    let mut clock = ScanClock::new(ClockMode::Auto);
    for k in 0..300 {
        let t = k as f64 * 0.1;
        let pose = Pose2::new(-2.0 + 0.01 * t, 0.0, 0.0);
        clock.odometry(t, pose);
        let mut scan = scan_in_room(pose, pose, HALF, &PILLARS);
        scan.stamp = t;
        clock.scan(scan);
        assert!(clock.next_ready().is_none(), "held during the warm-up");
    }
    clock.finish();
    let report = clock.report().unwrap();
    assert_eq!((report.source, report.offset), (PoseSource::AsLogged, 0.0));
    assert_eq!(std::iter::from_fn(|| clock.next_ready()).count(), 300);
}

#[test]
fn a_flowing_clock_gives_out_every_scan_at_once_and_the_offset_once_learnt() {
    let lag = 0.08;
    let mut clock = ScanClock::flowing(ClockMode::Auto);
    let (mut given, mut late) = (Vec::new(), 0);
    for r in log(80.0, lag, true) {
        match r {
            Reading::Odom(t, p) => clock.odometry(t, p),
            Reading::Scan(s) => {
                clock.scan(s);
                let before = given.len();
                given.extend(std::iter::from_fn(|| clock.next_ready()));
                // Before the offset is decided, each scan comes out as it
                // goes in; after, within the odometry's next message.
                if given.len() == before {
                    late += 1;
                }
            }
        }
    }
    clock.finish();
    given.extend(std::iter::from_fn(|| clock.next_ready()));
    let report = clock.report().unwrap();
    assert!((report.offset + lag).abs() < 0.005, "{report:?}");
    assert!(late <= 1, "{late} scans waited");
    // The warm-up's scans keep the logged poses, the later ones are right.
    let warm = report.warmup_scans;
    assert!(worst_heading_error(&given[..warm], lag) > 0.02);
    assert!(worst_heading_error(&given[warm..], lag) < 0.01);
}

#[test]
fn the_setting_takes_a_word_or_seconds() {
    let parse = |s: ClockSetting| ClockMode::try_from(s);
    assert_eq!(parse(ClockSetting::Word("auto".into())), Ok(ClockMode::Auto));
    assert_eq!(parse(ClockSetting::Word("log".into())), Ok(ClockMode::Log));
    assert_eq!(parse(ClockSetting::Seconds(-0.12)), Ok(ClockMode::Fixed(-0.12)));
    for bad in
        [ClockSetting::Seconds(0.6), ClockSetting::Seconds(f64::NAN), ClockSetting::Word("late".into())]
    {
        let e = parse(bad).unwrap_err();
        assert!(e.contains("expected \"auto\", \"log\" or seconds in [-0.5, 0.5]"), "{e}");
    }
}
