//! `pf.resampler`: after every task's correction it decides the new set;
//! when a matcher task is lost (its replacement says so), the particles it
//! held are replaced from those left and the replacement joins.

use std::collections::BTreeSet;

use squall_bolts::pf::kinds::messages::{Decision, Ready, Report};
use squall_core::sensor::PoseStamped;

use super::drive;
use super::filter::Filter;

/// The slots task `task` reported at `step`.
fn reported_slots(filter: &Filter, step: u64, task: usize) -> Vec<usize> {
    let slots = filter.reports_for(step).into_iter().filter(|(t, _)| *t == task);
    slots
        .flat_map(|(_, r)| match r {
            Report::Corrected { slots, .. } => slots.iter().map(|s| s.slot).collect(),
            _ => Vec::new(),
        })
        .collect()
}

/// The new slots `decision` places on `task`.
fn placed(decision: &Decision, task: u32) -> Vec<usize> {
    (0..decision.task_of.len()).filter(|&j| decision.task_of[j] == task).collect()
}

#[test]
fn every_task_heard_the_resampler_decides_and_lets_the_dispatcher_go_on() {
    let readings = drive(3);
    let mut f = Filter::new(6, 3);
    f.reading(0, &readings[0]);
    f.settle();
    assert_eq!(f.ready, [Ready { step: 0, corrected: true }]);
    for step in 1..3 {
        f.reading(step, &readings[step as usize]);
        f.settle();
        let d = f.decided.last().unwrap();
        assert_eq!((d.step, d.parents.len(), d.lost), (step, 6, None));
        for t in 0..3 {
            assert_eq!(placed(d, t).len(), 2, "equal shares: {d:?}");
        }
        assert_eq!(f.ready.last(), Some(&Ready { step, corrected: true }));
    }
    assert_eq!(f.resampler.counter("resamplings"), Some(2), "parfil resamples at every correction");
    let trajectory = f.resampler.finish().unwrap();
    let stamps: Vec<f64> = trajectory.on::<PoseStamped>("trajectory").iter().map(|p| p.stamp).collect();
    assert_eq!(stamps, [1.0, 2.0, 3.0], "one pose per reading, stamped with its iteration");
}

#[test]
fn a_matcher_lost_after_a_decision_before_any_update_stands_in_for_the_decided_reading() {
    // Regression (ad23154): the lost task stood in for reading 0, and the
    // next update report failed the run with "a report for reading 1 while
    // gathering 0".
    let readings = drive(4);
    let mut f = Filter::new(6, 3);
    f.reading(0, &readings[0]);
    f.settle();
    f.reading(1, &readings[1]);
    f.deliver_reports();
    let d1 = f.decided.last().unwrap().clone();
    assert_eq!(d1.step, 1);

    // Task 1 is lost with the decision on its way to every task.
    f.lose(1);
    f.deliver_reports();
    // Gone: the new slots placed on task 1, and those placed elsewhere
    // whose parent task 1 held (old slots 2 and 3) and was to send.
    let holes: Vec<u32> =
        (0..6).filter(|&j| d1.task_of[j] != 1 && [2, 3].contains(&d1.parents[j])).map(|j| j as u32).collect();
    let notice = f.decided.last().unwrap();
    assert_eq!((notice.step, notice.lost, &notice.holes), (1, Some(1), &holes));
    let lost: BTreeSet<usize> = placed(&d1, 1).into_iter().chain(holes.iter().map(|&j| j as usize)).collect();
    assert_eq!(f.resampler.counter("particles_lost"), Some(lost.len() as u64));

    // The survivors update without the lost states, and that completes
    // reading 1.
    f.settle();
    assert_eq!(f.ready.last(), Some(&Ready { step: 1, corrected: true }));

    // Reading 2: the replacement holds nothing, so it only predicts; the
    // lost particles are replaced from those left, whatever Neff, and the
    // replacement joins with its share.
    f.reading(2, &readings[2]);
    f.settle();
    assert!(matches!(f.reports_for(2).iter().find(|(t, _)| *t == 1), Some((_, Report::Predicted { .. }))));
    let survivors: BTreeSet<usize> = [0, 2].iter().flat_map(|&t| reported_slots(&f, 2, t)).collect();
    assert_eq!(survivors, (0..6).filter(|j| !lost.contains(j)).collect(), "the survivors kept the rest");
    let d2 = f.decided.iter().find(|d| d.step == 2 && d.lost.is_none()).unwrap().clone();
    assert_eq!(d2.joining, [1]);
    assert!(d2.parents.iter().all(|p| survivors.contains(&(*p as usize))), "parents {:?}", d2.parents);
    for t in 0..3 {
        assert_eq!(placed(&d2, t).len(), 2, "equal shares again: {d2:?}");
    }
    assert_eq!(
        f.ready.last(),
        Some(&Ready { step: 2, corrected: true }),
        "the replacement joined and updated"
    );

    // Reading 3: every task corrects its share of the new set.
    f.reading(3, &readings[3]);
    f.settle();
    for t in 0..3 {
        assert_eq!(reported_slots(&f, 3, t), placed(&d2, t as u32), "task {t}");
    }
    let d3 = f.decided.last().unwrap();
    assert!(d3.step == 3 && d3.joining.is_empty() && d3.lost.is_none());
    assert_eq!(f.ready.last(), Some(&Ready { step: 3, corrected: true }));
    assert_eq!(f.resampler.counter("particles_lost"), Some(lost.len() as u64), "none lost since");
    for m in &mut f.matchers {
        m.finish().unwrap();
    }
    let trajectory = f.resampler.finish().unwrap();
    assert_eq!(trajectory.on::<PoseStamped>("trajectory").len(), 4);
}
