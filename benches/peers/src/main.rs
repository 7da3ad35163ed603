//! squall's probe pipeline (source → relay → sink) beside the same
//! pipeline in timely dataflow and in three threads joined by bounded
//! channels, with the same 64-byte records, in one invocation, reported as
//! million messages per second and as ratios to squall.
//!
//!     cargo run --release --manifest-path benches/peers/Cargo.toml -- [MESSAGES] [RUNS]
//!
//! Every system runs once per round, in the same order, for `RUNS` rounds
//! (5 unless given): alternating keeps a noisy machine's drift out of the
//! ratios. Medians and the worst round are printed.

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

/// A 64-byte record, as squall's probe: sequence number, key, send time
/// and padding, inline.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Record {
    seq: u64,
    key: u64,
    sent_ns: u64,
    padding: [u64; 5],
}

/// The record with squall's former probe shape: its padding on the heap.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct HeapRecord {
    seq: u64,
    key: u64,
    sent_ns: u64,
    padding: Vec<u8>,
}

fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

fn record(seq: u64) -> Record {
    Record { seq, key: seq % 1024, sent_ns: seq, padding: [0; 5] }
}

/// squall's probe pipeline at `parallelism` (relay and sink), batching
/// as `batch` says (a TOML inline table, or empty for the default).
fn squall(messages: u64, parallelism: usize, batch: &str) -> Duration {
    let batch = if batch.is_empty() { String::new() } else { format!(", batch = {batch}") };
    let toml = format!(
        r#"
[topology]
name = "peers"

[[spout]]
name = "source"
kind = "probe.source"
params = {{ count = {messages}, message_bytes = 64 }}

[[bolt]]
name = "relay"
kind = "probe.relay"
parallelism = {parallelism}
inputs = [ {{ from = "source"{batch} }} ]

[[bolt]]
name = "sink"
kind = "probe.sink"
parallelism = {parallelism}
inputs = [ {{ from = "relay"{batch} }} ]
"#
    );
    let spec = squall::topology::TopologySpec::parse("peers.toml", &toml).expect("a valid topology");
    let topology = squall::topology::Topology::validate(spec, &squall::builtin::registry()).expect("valid");
    let report = squall::topology::run(&topology, &squall::topology::RunOptions::default()).expect("runs");
    let sink = report.component("sink").expect("a sink");
    assert_eq!(sink.received, messages, "the sink received every message");
    Duration::from_secs_f64(report.wall_secs)
}

/// The same pipeline in timely dataflow: a source operator, a relay
/// (`map`), and a sink counting what it sees, on `workers` workers. As in
/// squall's probe, one source makes every record (on worker 0); with more
/// than one worker, records are exchanged between workers before the
/// relay (by sequence number) and before the sink (by key). `heap`: records carry their padding on the heap and a clock
/// reading each, as squall's probe did.
fn timely(messages: u64, workers: usize, heap: bool) -> Duration {
    use timely::dataflow::operators::vec::{Map, ToStream};
    use timely::dataflow::operators::{Exchange, Inspect};
    let started = Instant::now();
    let counts = timely::execute(timely::Config::process(workers), move |worker| {
        let (index, peers) = (worker.index() as u64, worker.peers() as u64);
        let mine = 0..if index == 0 { messages } else { 0 };
        let mut seen = 0u64;
        if heap {
            let seen = std::rc::Rc::new(std::cell::Cell::new(0u64));
            let s = seen.clone();
            worker.dataflow::<u64, _, _>(|scope| {
                let stream = mine
                    .map(|seq| HeapRecord { seq, key: seq % 1024, sent_ns: now_ns(), padding: vec![0; 40] })
                    .to_stream(scope);
                let stream = if peers > 1 { stream.exchange(|r: &HeapRecord| r.seq) } else { stream };
                let stream = stream.map(|r| r);
                let stream = if peers > 1 { stream.exchange(|r: &HeapRecord| r.key) } else { stream };
                stream.inspect(move |_| s.set(s.get() + 1));
            });
            while worker.step() {}
            return seen.get();
        }
        let counter = std::rc::Rc::new(std::cell::Cell::new(0u64));
        let c = counter.clone();
        worker.dataflow::<u64, _, _>(|scope| {
            let stream = mine.map(record).to_stream(scope);
            let stream = if peers > 1 { stream.exchange(|r: &Record| r.seq) } else { stream };
            let stream = stream.map(|r| r);
            let stream = if peers > 1 { stream.exchange(|r: &Record| r.key) } else { stream };
            stream.inspect(move |_| c.set(c.get() + 1));
        });
        while worker.step() {}
        seen += counter.get();
        seen
    })
    .expect("timely runs")
    .join()
    .into_iter()
    .map(|r| r.expect("a worker ends"))
    .sum::<u64>();
    assert_eq!(counts, messages, "timely's sink saw every record");
    started.elapsed()
}

/// Three threads, source → relay → sink, joined by `bounded(1024)`
/// channels, `per_send` records per send.
fn channels(messages: u64, per_send: usize, heap: bool) -> Duration {
    let started = Instant::now();
    if heap {
        let (tx, rx) = crossbeam_channel::bounded::<HeapRecord>(1024);
        let (tx2, rx2) = crossbeam_channel::bounded::<HeapRecord>(1024);
        let source = std::thread::spawn(move || {
            for seq in 0..messages {
                tx.send(HeapRecord { seq, key: seq % 1024, sent_ns: now_ns(), padding: vec![0; 40] })
                    .unwrap();
            }
        });
        let relay = std::thread::spawn(move || rx.iter().for_each(|r| tx2.send(r).unwrap()));
        let seen = rx2.iter().count() as u64;
        source.join().unwrap();
        relay.join().unwrap();
        assert_eq!(seen, messages);
        return started.elapsed();
    }
    let (tx, rx) = crossbeam_channel::bounded::<Vec<Record>>(1024);
    let (tx2, rx2) = crossbeam_channel::bounded::<Vec<Record>>(1024);
    let source = std::thread::spawn(move || {
        let mut seq = 0;
        while seq < messages {
            let n = (messages - seq).min(per_send as u64);
            tx.send((seq..seq + n).map(record).collect()).unwrap();
            seq += n;
        }
    });
    let relay = std::thread::spawn(move || rx.iter().for_each(|r| tx2.send(r).unwrap()));
    let seen = rx2.iter().map(|b| b.len() as u64).sum::<u64>();
    source.join().unwrap();
    relay.join().unwrap();
    assert_eq!(seen, messages);
    started.elapsed()
}

/// Three threads joined by `bounded(1024)` channels, 256 records per
/// send, each record in its own `Arc<dyn Any>` as squall shares a
/// message (allocated by the source, freed by the sink): the floor that
/// payload representation sets, whatever the engine around it does.
fn channels_arc(messages: u64) -> Duration {
    type Shared = std::sync::Arc<dyn std::any::Any + Send + Sync>;
    const PER_SEND: u64 = 256;
    let started = Instant::now();
    let (tx, rx) = crossbeam_channel::bounded::<Vec<Shared>>(1024);
    let (tx2, rx2) = crossbeam_channel::bounded::<Vec<Shared>>(1024);
    let source = std::thread::spawn(move || {
        let mut seq = 0;
        while seq < messages {
            let n = (messages - seq).min(PER_SEND);
            tx.send((seq..seq + n).map(|s| std::sync::Arc::new(record(s)) as Shared).collect()).unwrap();
            seq += n;
        }
    });
    let relay = std::thread::spawn(move || {
        rx.iter().for_each(|batch| {
            let out: Vec<Shared> =
                batch.into_iter().map(|r| r.downcast::<Record>().expect("a record") as Shared).collect();
            tx2.send(out).unwrap()
        })
    });
    let seen = rx2.iter().map(|b| b.iter().filter(|r| r.is::<Record>()).count() as u64).sum::<u64>();
    source.join().unwrap();
    relay.join().unwrap();
    assert_eq!(seen, messages);
    started.elapsed()
}

struct System {
    name: &'static str,
    run: Box<dyn Fn(u64) -> Duration>,
    rates: Vec<f64>,
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let messages: u64 = args.get(1).map_or(10_000_000, |a| a.parse().expect("MESSAGES is a number"));
    let runs: usize = args.get(2).map_or(5, |a| a.parse().expect("RUNS is a number"));
    let batched = std::env::var("PEERS_SQUALL_BATCH").unwrap_or_default();
    let mut systems: Vec<System> = vec![
        System {
            name: "squall probe, parallelism 1",
            run: Box::new({
                let b = batched.clone();
                move |m| squall(m, 1, &b)
            }),
            rates: vec![],
        },
        System {
            name: "squall probe, parallelism 2",
            run: Box::new({
                let b = batched.clone();
                move |m| squall(m, 2, &b)
            }),
            rates: vec![],
        },
        System {
            name: "squall probe, parallelism 1, batch max = 1",
            run: Box::new(|m| squall(m, 1, "{ max = 1 }")),
            rates: vec![],
        },
        System { name: "timely 0.32, 1 worker", run: Box::new(|m| timely(m, 1, false)), rates: vec![] },
        System {
            name: "timely, 2 workers, exchanged twice",
            run: Box::new(|m| timely(m, 2, false)),
            rates: vec![],
        },
        System {
            name: "timely, heap records + clock, 1 worker",
            run: Box::new(|m| timely(m, 1, true)),
            rates: vec![],
        },
        System {
            name: "timely, heap records + clock, 2 workers",
            run: Box::new(|m| timely(m, 2, true)),
            rates: vec![],
        },
        System {
            name: "3 threads, bounded(1024), 1 per send",
            run: Box::new(|m| channels(m, 1, false)),
            rates: vec![],
        },
        System {
            name: "3 threads, bounded(1024), 1024 per send",
            run: Box::new(|m| channels(m, 1024, false)),
            rates: vec![],
        },
        System {
            name: "3 threads, 256 per send, a shared Arc per record",
            run: Box::new(channels_arc),
            rates: vec![],
        },
        System {
            name: "3 threads, 1 per send, heap records + clock",
            run: Box::new(|m| channels(m, 1, true)),
            rates: vec![],
        },
    ];
    // PEERS_ONLY / PEERS_SKIP: systems whose name contains the text.
    if let Ok(only) = std::env::var("PEERS_ONLY") {
        systems.retain(|s| s.name.contains(&only));
    }
    if let Ok(skip) = std::env::var("PEERS_SKIP") {
        systems.retain(|s| !s.name.contains(&skip));
    }
    for round in 0..runs {
        for s in &mut systems {
            let took = (s.run)(messages);
            s.rates.push(messages as f64 / took.as_secs_f64() / 1e6);
            eprintln!("round {round}: {:<45} {:>8.2} M msg/s", s.name, s.rates.last().unwrap());
        }
    }
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let base = median(&systems[0].rates);
    println!("{messages} messages of 64 bytes, {runs} rounds");
    println!("| system | M msg/s, median | worst | ratio to squall p1 |");
    println!("| --- | --- | --- | --- |");
    for s in &systems {
        let m = median(&s.rates);
        let worst = s.rates.iter().copied().fold(f64::INFINITY, f64::min);
        println!("| {} | {m:.2} | {worst:.2} | {:.2} |", s.name, m / base);
    }
}
