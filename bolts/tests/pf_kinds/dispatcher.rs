//! `pf.dispatcher`: numbers the readings and hands out one at a time;
//! offline it holds the source back, live it keeps only the newest and
//! counts the drops.

use std::sync::Arc;

use squall_bolts::parfil::ParfilReading;
use squall_bolts::pf::kinds::dispatcher::Dispatcher;
use squall_bolts::pf::kinds::messages::{Reading, Ready};
use squall_topology::testing::{BoltHarness, Emits};

use super::{SEED, drive};

type Harness = BoltHarness<Dispatcher<ParfilReading>>;

fn dispatcher(mode: &str) -> Harness {
    let params = format!("model = \"parfil\"\nmode = \"{mode}\"");
    let mut h = BoltHarness::from_factory(Dispatcher::from_params, &params, 0, 1, SEED).unwrap();
    h.prepare().unwrap();
    h
}

fn reading(h: &mut Harness, r: &Arc<ParfilReading>) -> Emits {
    h.execute_shared("source", "reading", 0, r.clone()).unwrap()
}

fn ready(h: &mut Harness, step: u64, corrected: bool) -> Emits {
    h.execute("resampler", "ready", 0, Ready { step, corrected }).unwrap()
}

/// The (step, reading) of each reading handed out, checking that the
/// reading is the one received, not a copy.
fn handed_out(out: &Emits) -> Vec<(u64, Arc<ParfilReading>)> {
    out.on::<Reading<ParfilReading>>("reading").iter().map(|r| (r.step, r.input.clone())).collect()
}

#[test]
fn offline_hands_out_one_reading_at_a_time_and_holds_the_source_until_ready() {
    let readings = drive(3);
    let mut h = dispatcher("offline");
    let out = handed_out(&reading(&mut h, &readings[0]));
    assert_eq!(out.len(), 1);
    assert!(out[0].0 == 0 && Arc::ptr_eq(&out[0].1, &readings[0]), "reading 0 is handed out as it came");
    assert!(h.holding_inputs(), "the source waits while reading 0 is out");
    // The rest of a batch the engine had handed over waits in order.
    assert!(reading(&mut h, &readings[1]).is_empty());
    assert!(reading(&mut h, &readings[2]).is_empty());
    let out = handed_out(&ready(&mut h, 0, true));
    assert!(out.len() == 1 && out[0].0 == 1 && Arc::ptr_eq(&out[0].1, &readings[1]));
    assert!(h.holding_inputs());
    let out = handed_out(&ready(&mut h, 1, false));
    assert!(out.len() == 1 && out[0].0 == 2 && Arc::ptr_eq(&out[0].1, &readings[2]));
    assert!(ready(&mut h, 2, true).is_empty());
    assert!(!h.holding_inputs(), "nothing out, nothing waiting: the source may go on");
    h.finish().unwrap();
    assert_eq!(h.counter("dropped_readings"), Some(0), "offline drops nothing");
    assert_eq!(h.recorded("reading_us"), 3);
    assert_eq!(h.recorded("processed_scan_us"), 2, "only readings that corrected");
}

#[test]
fn live_keeps_only_the_newest_reading_while_one_is_out_and_counts_each_drop() {
    let readings = drive(6);
    let mut h = dispatcher("live");
    assert_eq!(handed_out(&reading(&mut h, &readings[0]))[0].0, 0);
    assert!(!h.holding_inputs(), "live never holds the source back");
    for r in &readings[1..4] {
        assert!(reading(&mut h, r).is_empty());
    }
    assert_eq!(h.counter("dropped_readings"), Some(2), "readings 1 and 2 gave way to 3");
    let out = handed_out(&ready(&mut h, 0, true));
    assert!(out.len() == 1 && Arc::ptr_eq(&out[0].1, &readings[3]), "the newest goes next");
    assert_eq!(out[0].0, 1, "steps number the readings handed out");
    assert!(ready(&mut h, 1, true).is_empty());
    // With nothing out, a reading goes straight out again.
    assert_eq!(handed_out(&reading(&mut h, &readings[4]))[0].0, 2);
    assert!(reading(&mut h, &readings[5]).is_empty());
    assert_eq!(handed_out(&ready(&mut h, 2, true))[0].0, 3);
    h.finish().unwrap();
    assert_eq!(h.counter("dropped_readings"), Some(2));
}

#[test]
fn a_ready_for_another_reading_than_the_one_out_fails_the_task() {
    let readings = drive(1);
    let mut h = dispatcher("offline");
    let none_out = h.execute("resampler", "ready", 0, Ready { step: 0, corrected: true }).unwrap_err();
    assert_eq!(none_out.to_string(), "pf.dispatcher: ready for reading 0 with none out");
    reading(&mut h, &readings[0]);
    let wrong = h.execute("resampler", "ready", 0, Ready { step: 4, corrected: true }).unwrap_err();
    assert_eq!(wrong.to_string(), "pf.dispatcher: ready for reading 4 while 0 is out");
}

#[test]
fn a_dispatcher_is_one_task_in_a_known_mode() {
    let two =
        BoltHarness::from_factory(Dispatcher::<ParfilReading>::from_params, "model = \"parfil\"", 0, 2, 0);
    assert!(two.unwrap_err().to_string().contains("runs as one task"));
    let bad = BoltHarness::from_factory(
        Dispatcher::<ParfilReading>::from_params,
        "model = \"parfil\"\nmode = \"later\"",
        0,
        1,
        0,
    );
    assert!(bad.unwrap_err().to_string().contains("unknown variant `later`"));
}
