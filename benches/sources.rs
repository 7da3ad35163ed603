//! How fast robot data is read: scans per second from the ACES log as CARMEN
//! text and as a ROS 2 bag (MCAP, zstd, CDR). Reading must never be a
//! topology's bottleneck: the goal is at least 50 000 scans/s.
//!
//!     cargo bench --bench sources
//!
//! Needs `../shared/data` beside the repository.

use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use squall::spouts::carmen::{ReadOptions, read_log};
use squall::spouts::rosbag2::{Topics, read_bag};

fn shared(rel: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    assert!(path.exists(), "missing {}: this bench reads the shared data set", path.display());
    path
}

fn sources(c: &mut Criterion) {
    let mut group = c.benchmark_group("read_aces");
    group.sample_size(10).measurement_time(Duration::from_secs(5));
    group.throughput(Throughput::Elements(7374));
    let clf = shared("laser/aces.clf");
    group.bench_function("carmen", |b| b.iter(|| read_log(&clf, ReadOptions::default()).unwrap()));
    let bag = shared("rosbag2/aces");
    group.bench_function("rosbag2", |b| b.iter(|| read_bag(&bag, &Topics::default()).unwrap()));
    group.finish();
}

// The macro generates an undocumented public function.
#[allow(missing_docs)]
mod group {
    use super::*;
    criterion_group!(benches, sources);
}
criterion_main!(group::benches);
