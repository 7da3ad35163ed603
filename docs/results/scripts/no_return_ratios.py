#!/usr/bin/env python3
"""The no-return detector's statistic on CARMEN logs (decision 0037).

For each log: scans sampled every 0.5 m of odometry travel, beams binned by
centimetre; for every bin, the beams in its window (±5 bins) against the
beams its surroundings (±1 m, leaving out ±15 bins) hold in a window of that
width, plus one: core::no_return's ratio. Prints the largest ratio below
the declared range that is not a code (a surface) and the ratio of each
code (where the window sits on the log's no-return readings, above or below
the declared range), then the leave-one-log-out check of the threshold.

    docs/results/scripts/no_return_ratios.py LOG.clf[:DECLARED] ...

Standard library only.
"""
import math
import sys
from collections import Counter

STEP, HALF, FAR, NEAR, RATIO = 0.5, 5, 100, 15, 25.0


def ratios(path):
    last, hist, scans = None, Counter(), 0
    for line in open(path):
        p = line.split()
        if not p or p[0] != "FLASER":
            continue
        n = int(p[1])
        x, y = float(p[n + 5]), float(p[n + 6])
        if last is not None and math.hypot(x - last[0], y - last[1]) < STEP:
            continue
        last, scans = (x, y), scans + 1
        for v in p[2 : 2 + n]:
            hist[int(float(v) * 100)] += 1
    out = []
    for b in sorted(hist):
        if b < 10:
            continue
        inside = sum(hist.get(b + d, 0) for d in range(-HALF, HALF + 1))
        around = [hist.get(b + d, 0) for d in range(-FAR, FAR + 1) if abs(d) > NEAR and b + d >= 0]
        per_window = sum(around) * (2 * HALF + 1) / max(len(around), 1)
        out.append((inside / (per_window + 1), b / 100, inside))
    return scans, out


def main():
    rows = []
    for arg in sys.argv[1:]:
        path, _, declared = arg.partition(":")
        scans, rs = ratios(path)
        # The log's codes: windows of at least 20 beams holding 25x their
        # surroundings; everything else is a surface.
        codes = [r for r in rs if r[0] >= RATIO and r[2] >= 20]
        code_at = sorted({round(r[1], 1) for r in codes})
        surfaces = [r for r in rs if all(abs(r[1] - c) > 0.3 for c in code_at)]
        top = max(surfaces)
        lowest_code = min((max(r[0] for r in codes if abs(r[1] - c) <= 0.3) for c in code_at), default=None)
        name = path.split("/")[-1]
        rows.append((name, top[0], lowest_code))
        code_text = f"{lowest_code:.0f}" if lowest_code else "none"
        print(f"{name:<18} samples {scans:5d}  surface max {top[0]:5.1f} (at {top[1]:.2f} m)  codes at {code_at} m, weakest {code_text}")
    print("\nleave one log out: the interval the other logs leave for the threshold")
    for k, (name, surface, code) in enumerate(rows):
        rest = rows[:k] + rows[k + 1 :]
        lo = max(r[1] for r in rest)
        hi = min((r[2] for r in rest if r[2]), default=float("inf"))
        inside = lo < RATIO < hi
        holds = surface < RATIO and (code is None or code > RATIO)
        print(f"  without {name:<18} ({lo:.1f}, {hi:.0f}): {RATIO:.0f} inside: {inside}; {name} classified right at {RATIO:.0f}: {holds}")


if __name__ == "__main__":
    main()
