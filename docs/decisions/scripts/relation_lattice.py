"""What a benchmark relation file can measure over short spans: how far
each relation is from the raw odometry between its two scans, and how
the relation's own two scans, matched to each other, score on it.

Analysis only; squall does not run it and CI does not need it (python3
with numpy and scipy; it borrows the point-to-line ICP of
smoother_prototype.py beside it). Usage:

  python3 relation_lattice.py LOG.clf LOG.relations [STEP] [TRAJECTORY.tum]

STEP (metres, default 0.05) is the lattice tested for the relation minus
odometry offsets. Prints, for the relations spanning under 10 s: the
share whose offset from the odometry is 0, one step, a diagonal step,
two steps or (2, 1) steps (each within 15% of a step); the mean error of
the odometry, of ICP between the relation's own two scans (from the
odometry's guess), and of TRAJECTORY if given, on all of them, on those
that are copies of the odometry (offset under 1e-5 m) and on the rest.
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import smoother_prototype as sp  # noqa: E402


def error(truth, estimate):
    d = sp.rel(truth, tuple(estimate))
    return math.hypot(d[0], d[1])


def main():
    clf, relations = sys.argv[1], sys.argv[2]
    step = float(sys.argv[3]) if len(sys.argv) > 3 else 0.05
    trajectory = sp.load_tum(sys.argv[4]) if len(sys.argv) > 4 else None
    odo = sp.load_odo(clf)
    scans = sp.load_scans(clf)
    rows = []
    for line in open(relations):
        f = line.split()
        if len(f) < 8:
            continue
        t1, t2 = round(float(f[0]), 3), round(float(f[1]), 3)
        if abs(t2 - t1) >= 10 or t1 not in odo or t2 not in odo:
            continue
        truth = (float(f[2]), float(f[3]), float(f[7]))
        guess = sp.rel(odo[t1], odo[t2])
        offset = math.hypot(truth[0] - guess[0], truth[1] - guess[1])
        matched = sp.icp_pl(scans[t2], scans[t1], tuple(guess))
        row = [offset, error(truth, guess), error(truth, matched if matched is not None else guess)]
        if trajectory is not None:
            if t1 not in trajectory or t2 not in trajectory:
                continue
            row.append(error(truth, sp.rel(trajectory[t1], trajectory[t2])))
        rows.append(row)
    a = np.array(rows)
    print(f"{len(a)} relations under 10 s")
    for k, name in ((0, "0"), (1, "1 step"), (math.sqrt(2), "diagonal"), (2, "2 steps"), (math.sqrt(5), "(2, 1)")):
        share = np.abs(a[:, 0] - k * step) < 0.15 * step
        print(f"  offset from odometry {name} ({k * step:.4f} m): {share.sum()} ({100 * share.mean():.0f}%)")
    copies = a[:, 1] < 1e-5
    names = ["odometry", "ICP of the relation's own scans"] + (["trajectory"] if trajectory is not None else [])
    for i, name in enumerate(names):
        c = a[:, 1 + i]
        print(f"  {name}: all {c.mean():.4f}, copies ({copies.sum()}) {c[copies].mean():.4f}, "
              f"others ({(~copies).sum()}) {c[~copies].mean():.4f} m")


if __name__ == "__main__":
    main()
