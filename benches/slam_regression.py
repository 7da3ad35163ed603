#!/usr/bin/env python3
"""SLAM's regression check: the development suite against the recorded table.

Runs `squall study` on the development logs (and the simulated office) at a
few seeds and compares, log by log, the median and the worst relation error
with the table recorded in docs/results/slam-regression.csv for the same
seeds. A log whose median or worst moves by more than its recorded seed
spread (the largest minus the smallest error over every recorded seed) fails
the check, whichever way it moved: worse is a regression, better means the
table is out of date and must be recorded again (`--record`). A run that
fails, or scores worse than the raw odometry, fails the check too.

It takes minutes (not a CI test): run it before a change to SLAM lands,
and say in the closing note that it passed.

    benches/slam_regression.py                  # seeds 1-3, compare
    benches/slam_regression.py --seeds 1-10 --record   # write the table

Needs only Python 3's standard library and a release build of squall
(`cargo build --release`; the binary is found in $CARGO_TARGET_DIR or
target/).
"""

import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TABLE = ROOT / "docs" / "results" / "slam-regression.csv"
DATA = ROOT.parent / "shared" / "data" / "laser"
LOGS = ["aces", "intel", "mit-csail", "fr079"]
SIM_WORLDS = ["office"]
FIELDS = ["run", "seed", "status", "error_m", "span_0_10_m", "odometry_m", "cpu_secs", "peak_rss_mb"]


def squall_binary():
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    binary = target / "release" / "squall"
    if not binary.exists():
        sys.exit(f"slam_regression: no release build at {binary}: run `cargo build --release` first")
    return binary


def seeds_of(text):
    out = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def run_study(binary, seeds, jobs, out):
    """Runs the suite; returns {run: {seed: row}} from the study's CSV."""
    logs = ",".join(str(DATA / f"{name}.clf") for name in LOGS)
    command = [
        str(binary), "study", "--logs", logs, "--sim-worlds", ",".join(SIM_WORLDS),
        "--seeds", ",".join(map(str, seeds)), "--jobs", str(jobs), "--out", str(out),
    ]
    print("slam_regression:", " ".join(command), flush=True)
    done = subprocess.run(command, cwd=ROOT)
    if done.returncode not in (0, 1):
        sys.exit(f"slam_regression: the study exited {done.returncode}")
    rows = {}
    with open(out / "study.csv", newline="") as f:
        for r in csv.DictReader(f):
            name = run_name(r)
            rows.setdefault(name, {})[int(r["seed"])] = {
                "run": name,
                "seed": r["seed"],
                "status": r["status"],
                "error_m": r["trans_error_m"],
                "span_0_10_m": r["span_0_10_m"],
                "odometry_m": r["odometry_trans_error_m"],
                "cpu_secs": r["cpu_secs"],
                "peak_rss_mb": r["peak_rss_mb"],
                "worse": r["worse_than_odometry"],
            }
    return rows


def run_name(row):
    """A log's name (`fr079`), or a simulated world's with its odometry
    (`office-poor`)."""
    return Path(row["log"]).name.removesuffix(".gz").removesuffix(".clf")


def read_table():
    table = {}
    with open(TABLE, newline="") as f:
        for r in csv.DictReader(f):
            table.setdefault(r["run"], {})[int(r["seed"])] = r
    return table


def write_table(rows):
    tmp = TABLE.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        for name in sorted(rows):
            for seed in sorted(rows[name]):
                w.writerow(rows[name][seed])
    tmp.replace(TABLE)
    print(f"slam_regression: recorded {TABLE.relative_to(ROOT)}")


def compare(rows, table):
    failures = []
    print(f"{'run':<12} {'median':>8} {'recorded':>9} {'worst':>8} {'recorded':>9} {'spread':>7}  verdict")
    for name in sorted(rows):
        got = rows[name]
        bad = [s for s, r in got.items() if r["status"] != "ok" or r["worse"] == "true"]
        if bad:
            failures.append(f"{name}: seeds {bad} failed or scored worse than the odometry")
        recorded = table.get(name)
        if not recorded:
            failures.append(f"{name}: not in the recorded table (run with --record)")
            continue
        seeds = [s for s in got if s in recorded and got[s]["status"] == "ok"]
        if not seeds:
            failures.append(f"{name}: none of its seeds is recorded")
            continue
        new = [float(got[s]["error_m"]) for s in seeds]
        old = [float(recorded[s]["error_m"]) for s in seeds]
        every = [float(r["error_m"]) for r in recorded.values() if r["status"] == "ok"]
        spread = max(every) - min(every)
        verdict = "ok"
        for what, a, b in (("median", statistics.median(new), statistics.median(old)), ("worst", max(new), max(old))):
            if abs(a - b) > spread:
                way = "worse" if a > b else "better (record the table again)"
                verdict = f"{what} {way}"
                failures.append(f"{name}: {what} {a:.4f} m against {b:.4f} m recorded, beyond the seed spread {spread:.4f} m: {way}")
        print(
            f"{name:<12} {statistics.median(new):8.4f} {statistics.median(old):9.4f} "
            f"{max(new):8.4f} {max(old):9.4f} {spread:7.4f}  {verdict}"
        )
    return failures


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-3", help="seeds to run, e.g. 1-3 or 1,4,7 (default 1-3)")
    ap.add_argument("--jobs", type=int, default=2, help="runs at once (default 2)")
    ap.add_argument("--record", action="store_true", help="write the table instead of comparing")
    ap.add_argument("--out", type=Path, help="keep the study here (default: a temporary folder)")
    args = ap.parse_args()
    binary = squall_binary()
    seeds = seeds_of(args.seeds)
    with tempfile.TemporaryDirectory(prefix="slam-regression-") as tmp:
        out = args.out or Path(tmp) / "study"
        rows = run_study(binary, seeds, args.jobs, out)
    if args.record:
        write_table(rows)
        return 0
    failures = compare(rows, read_table())
    if failures:
        print("\nslam_regression: FAILED", file=sys.stderr)
        for f in failures:
            print("  " + f, file=sys.stderr)
        return 1
    print("\nslam_regression: every log within its recorded seed spread")
    return 0


if __name__ == "__main__":
    sys.exit(main())
