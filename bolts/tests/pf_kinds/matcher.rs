//! `pf.matcher`: each task reports its share of the particles with their
//! weights, carries out the resampler's decision by sending the parents'
//! states other tasks need straight to them, and the K tasks together
//! report what one task does.

use squall_bolts::pf::kinds::messages::{Decision, Reading, Report};
use squall_bolts::pf::shard::SlotReport;
use squall_core::geometry::{Pose2, normalize_angle};
use squall_topology::testing::Emits;

use super::filter::{ParfilMatcher, ParfilTransfer, matcher};
use super::{drive, options};

/// The one report in `out`.
fn report(out: &Emits) -> Report {
    let reports = out.on::<Report>("report");
    assert_eq!(reports.len(), 1, "{reports:?}");
    reports[0].clone()
}

/// `reports` with no state sizes: what one task, which need not size its
/// states, reports.
fn without_sizes(reports: &[SlotReport]) -> Vec<SlotReport> {
    reports.iter().map(|s| SlotReport { bytes: 0, ..*s }).collect()
}

fn slots(report: &Report) -> Vec<SlotReport> {
    match report {
        Report::Corrected { slots, .. } => slots.clone(),
        other => panic!("not a correction: {other:?}"),
    }
}

/// parfil's log-likelihood of `bearings` at `pose`: Gaussian bearing
/// noise of 0.1 rad on each of the four landmarks.
fn log_likelihood(pose: &Pose2, bearings: &[f64; 4]) -> f64 {
    let expected = options(4).bearings(pose);
    expected.iter().zip(bearings).map(|(e, o)| -0.5 * (normalize_angle(o - e) / 0.1).powi(2)).sum()
}

fn decision(step: u64, parents: [u32; 4], task_of: [u32; 4], best: u32) -> Decision {
    Decision {
        step,
        parents: parents.to_vec(),
        task_of: task_of.to_vec(),
        best,
        fresh: Vec::new(),
        joining: Vec::new(),
        lost: None,
        holes: Vec::new(),
    }
}

fn execute_decision(m: &mut ParfilMatcher, d: &Decision) -> Emits {
    m.execute("resampler", "decision", 0, d.clone()).unwrap()
}

/// A transfer as (reading, (new slot, state) pairs, whether the reading
/// comes with it).
type Sent = (u64, Vec<(u32, Pose2)>, bool);

/// The transfers in `out`, by receiving task.
fn transfers(out: &Emits, tasks: usize) -> Vec<Vec<Sent>> {
    (0..tasks)
        .map(|t| {
            out.to_peer::<ParfilTransfer>(t)
                .iter()
                .map(|x| (x.step, x.states.clone(), x.reading.is_some()))
                .collect()
        })
        .collect()
}

#[test]
fn two_tasks_report_their_shares_exchange_parents_and_together_report_what_one_task_does() {
    let readings = drive(3);
    let mut one = matcher(4, 0, 1, false);
    let mut two = [matcher(4, 0, 2, false), matcher(4, 1, 2, false)];
    let read = |m: &mut ParfilMatcher, step: u64| {
        let reading = Reading { step, input: readings[step as usize].clone() };
        report(&m.execute("dispatcher", "reading", 0, reading).unwrap())
    };

    // Reading 0 starts the filter: each task its half of the particles,
    // placed where one task places them.
    let started = |r: Report| match r {
        Report::Started { task, tasks, poses, particles, .. } => (task, tasks, poses, particles),
        other => panic!("{other:?}"),
    };
    let (_, _, all, _) = started(read(&mut one, 0));
    let (a, b) = (started(read(&mut two[0], 0)), started(read(&mut two[1], 0)));
    assert_eq!((a.0, a.1, a.3, b.0, b.1, b.3), (0, 2, 4, 1, 2, 4));
    assert_eq!(a.2.iter().map(|p| p.0).collect::<Vec<_>>(), [0, 1]);
    assert_eq!(b.2.iter().map(|p| p.0).collect::<Vec<_>>(), [2, 3]);
    assert_eq!([a.2, b.2].concat(), all);

    // Reading 1 corrects them: each slot weighed by parfil's likelihood of
    // the bearings at its pose.
    let whole = slots(&read(&mut one, 1));
    let (first, second) = (slots(&read(&mut two[0], 1)), slots(&read(&mut two[1], 1)));
    assert_eq!(first.iter().map(|s| s.slot).collect::<Vec<_>>(), [0, 1]);
    assert_eq!(second.iter().map(|s| s.slot).collect::<Vec<_>>(), [2, 3]);
    for s in &whole {
        let expected = log_likelihood(&s.pose, &readings[1].bearings);
        assert!(
            (s.log_likelihood - expected).abs() < 1e-9,
            "slot {}: {} vs {expected}",
            s.slot,
            s.log_likelihood
        );
        assert_eq!((s.evaluations, s.fit), (1, s.log_likelihood));
    }
    // Two tasks size each state (parfil's pose: 24 bytes) for the
    // assignment; one task does not, since nothing can move. The rest is
    // what one task reports.
    assert!(whole.iter().all(|s| s.bytes == 0), "{whole:?}");
    let two_tasks = [first, second].concat();
    assert!(two_tasks.iter().all(|s| s.bytes == 24), "{two_tasks:?}");
    assert_eq!(without_sizes(&two_tasks), whole);

    // The decision: new slots 0 and 1 from old slot 3 on task 0, new slots
    // 2 and 3 from old slots 0 and 1 on task 1. Each task sends the other
    // what it needs, and updates once it has it.
    let d = decision(1, [3, 3, 0, 1], [0, 0, 1, 1], 0);
    let out0 = execute_decision(&mut two[0], &d);
    let out1 = execute_decision(&mut two[1], &d);
    assert!(out0.on::<Report>("report").is_empty() && out1.on::<Report>("report").is_empty());
    let pose = |slot: usize| whole[slot].pose;
    assert_eq!(transfers(&out0, 2), [vec![], vec![(1, vec![(2, pose(0)), (3, pose(1))], false)]]);
    assert_eq!(transfers(&out1, 2), [vec![(1, vec![(0, pose(3)), (1, pose(3))], false)], vec![]]);
    let to0 = out1.0.iter().find(|e| e.task == Some(0)).unwrap().shared::<ParfilTransfer>().unwrap();
    let to1 = out0.0.iter().find(|e| e.task == Some(1)).unwrap().shared::<ParfilTransfer>().unwrap();
    let updated = |out: Emits| match report(&out) {
        Report::Updated { step, task, tasks, .. } => (step, task, tasks),
        other => panic!("{other:?}"),
    };
    assert_eq!(updated(two[0].execute_peer_shared(1, to0).unwrap()), (1, 0, 2));
    assert_eq!(updated(two[1].execute_peer_shared(0, to1).unwrap()), (1, 1, 2));
    let alone = execute_decision(&mut one, &decision(1, [3, 3, 0, 1], [0; 4], 0));
    assert!(transfers(&alone, 1)[0].is_empty(), "one task has every parent");
    assert_eq!(updated(alone), (1, 0, 1));

    // Reading 2: the particles moved from their new parents, the same
    // wherever their states came from.
    let whole = slots(&read(&mut one, 2));
    let split = [slots(&read(&mut two[0], 2)), slots(&read(&mut two[1], 2))].concat();
    assert_eq!(without_sizes(&split), whole);

    // Without resampling nothing moves; the best particle's holder (task 1
    // for slot 2) emits its snapshot at the end.
    let keep = decision(2, [0, 1, 2, 3], [0, 0, 1, 1], 2);
    for (m, task) in two.iter_mut().zip(0..) {
        let out = execute_decision(m, &keep);
        assert!(transfers(&out, 2).iter().all(Vec::is_empty));
        assert_eq!(updated(out), (2, task, 2));
    }
    updated(execute_decision(&mut one, &decision(2, [0, 1, 2, 3], [0; 4], 2)));
    assert_eq!(one.finish().unwrap().on::<Pose2>("map"), [&whole[2].pose]);
    assert!(two[0].finish().unwrap().on::<Pose2>("map").is_empty());
    assert_eq!(two[1].finish().unwrap().on::<Pose2>("map"), [&whole[2].pose]);
}

#[test]
fn a_decision_for_another_reading_than_the_one_pending_fails_the_task() {
    let readings = drive(2);
    let mut m = matcher(4, 0, 1, false);
    for step in 0..2 {
        let reading = Reading { step, input: readings[step as usize].clone() };
        m.execute("dispatcher", "reading", 0, reading).unwrap();
    }
    let err = m.execute("resampler", "decision", 0, decision(5, [0, 1, 2, 3], [0; 4], 0)).unwrap_err();
    assert_eq!(err.to_string(), "pf.matcher: decision for reading 5 while 1 is pending");
    let unfinished = m.finish().unwrap_err();
    assert_eq!(unfinished.to_string(), "pf.matcher: the run ended with a reading unfinished");
}
