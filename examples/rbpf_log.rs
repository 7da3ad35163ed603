//! The serial RBPF (`squall::bolts::slam`) on a CARMEN log, scored on its
//! relations, as a library user would call it:
//!
//!     cargo run --release --example rbpf_log -- LOG RELATIONS [MAX_URANGE_M] [MAX_SCANS]
//!     cargo run --release --example rbpf_log -- ../shared/data/laser/aces.clf \
//!         ../shared/data/laser/aces.relations 50
//!
//! It prints the relation metric of two trajectories: the best particle's
//! estimate at each scan (online), and the final best particle's lineage at
//! processed scans composed with odometry in between (how GMapping results
//! are usually scored).

use std::io::Write;

use anyhow::Context;
use squall::bolts::slam::{filter::Rbpf, options::SlamOptions};
use squall::core::eval::relations;
use squall::core::trajectory::Trajectory;
use squall::spouts::carmen::{ReadOptions, read_front_scans};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (log, rel) = match (args.get(1), args.get(2)) {
        (Some(l), Some(r)) => (l, r),
        _ => anyhow::bail!("usage: rbpf_log LOG RELATIONS [MAX_URANGE_M] [MAX_SCANS]"),
    };
    let max_urange: f64 = args.get(3).map_or(Ok(80.0), |s| s.parse()).context("MAX_URANGE_M")?;
    let max_scans: usize = args.get(4).map_or(Ok(usize::MAX), |s| s.parse()).context("MAX_SCANS")?;
    let scans: Vec<_> =
        read_front_scans(log.as_ref(), ReadOptions::default())?.into_iter().take(max_scans).collect();
    let mut filter =
        Rbpf::new(SlamOptions { max_urange, ..SlamOptions::default() }, 42).map_err(anyhow::Error::msg)?;
    let mut online = Trajectory::default();
    let started = std::time::Instant::now();
    let mut processed = 0;
    for s in &scans {
        processed += usize::from(filter.process(s).is_some());
        online.push(s.stamp, filter.estimate(&s.odometry).context("no particles")?);
    }
    let ms = started.elapsed().as_secs_f64() * 1e3 / processed.max(1) as f64;
    let mut last = Trajectory::default();
    for (stamp, pose) in filter.lineage_poses(scans.iter().map(|s| (s.stamp, s.odometry))) {
        last.push(stamp, pose);
    }
    let relations = relations::read_relations(rel.as_ref())?;
    // Written, not printed: a closed pipe (`| head`) ends the example with
    // an error rather than a panic.
    let mut out = std::io::stdout().lock();
    writeln!(out, "{} scans, {processed} processed, {ms:.1} ms per processed scan", scans.len())?;
    for (name, t) in [("online best estimate", &online), ("final best lineage", &last)] {
        let s = relations::score(t, &relations);
        writeln!(
            out,
            "{name}: {}/{} relations, {:.4} ± {:.4} m, {:.3} ± {:.3} deg",
            s.matched, s.total, s.trans_mean, s.trans_std, s.rot_mean_deg, s.rot_std_deg
        )?;
    }
    Ok(())
}
