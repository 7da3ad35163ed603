#!/usr/bin/env python3
"""How far a trajectory is off when it comes back to a place it passed.

For every `--every`-th pose of the ground truth that lies within
`--within` metres of a pose at least `--loop` metres of path before it
(the latest such), the trajectory's relative pose between the two is
compared with the ground truth's. The errors are what a loop search
must cover to find the loop: they are reported per 50 m of path between
the two visits, median and worst, in position and heading.

Both files are TUM (`t x y z qx qy qz qw`, as `squall slam` and `squall
sim` write them); poses are paired by stamp (to the millisecond).

    benches/revisit_drift.py --trajectory slam/trajectory.tum \\
        --ground-truth sim/ground_truth.tum

Pure Python, no dependencies: the numbers in decision 0039 come from it.
"""

import argparse
import math
import sys


def load(path):
    """The poses of a TUM file by stamp: (x, y, heading)."""
    poses = {}
    with open(path) as f:
        for number, line in enumerate(f, 1):
            if line.startswith("#") or not line.strip():
                continue
            fields = line.split()
            if len(fields) != 8:
                sys.exit(f"{path}:{number}: expected `t x y z qx qy qz qw`, got {len(fields)} fields")
            t, x, y, _, _, _, qz, qw = map(float, fields)
            poses[round(t, 3)] = (x, y, 2.0 * math.atan2(qz, qw))
    return poses


def relative(a, b):
    """Pose b in the frame of pose a."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    c, s = math.cos(a[2]), math.sin(a[2])
    turn = b[2] - a[2]
    return (c * dx + s * dy, -s * dx + c * dy, math.atan2(math.sin(turn), math.cos(turn)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trajectory", required=True)
    parser.add_argument("--ground-truth", required=True)
    parser.add_argument("--every", type=int, default=10, help="every this many poses (default 10)")
    parser.add_argument("--within", type=float, default=1.0, help="a return: within this, metres (default 1)")
    parser.add_argument("--loop", type=float, default=30.0, help="of at least this much path, metres (default 30)")
    args = parser.parse_args()
    trajectory, truth = load(args.trajectory), load(args.ground_truth)
    stamps = sorted(t for t in trajectory if t in truth)[:: max(1, args.every)]
    if len(stamps) < 2:
        sys.exit("revisit_drift: the two files share fewer than two stamps")
    path = [0.0]
    for before, after in zip(stamps, stamps[1:]):
        a, b = truth[before], truth[after]
        path.append(path[-1] + math.hypot(b[0] - a[0], b[1] - a[1]))
    bins = {}
    for j, now in enumerate(stamps):
        here = truth[now]
        earlier = None
        for i in range(j):
            if path[j] - path[i] < args.loop:
                break
            there = truth[stamps[i]]
            if math.hypot(here[0] - there[0], here[1] - there[1]) < args.within:
                earlier = i
        if earlier is None:
            continue
        then = stamps[earlier]
        true, seen = relative(truth[then], here), relative(trajectory[then], trajectory[now])
        position = math.hypot(true[0] - seen[0], true[1] - seen[1])
        heading = abs(math.atan2(math.sin(true[2] - seen[2]), math.cos(true[2] - seen[2])))
        bins.setdefault(int((path[j] - path[earlier]) // 50) * 50, []).append((position, heading))
    if not bins:
        print("no returns: the ground truth never comes back within", args.within, "m")
        return
    for start in sorted(bins):
        errors = bins[start]
        positions = sorted(e[0] for e in errors)
        headings = sorted(math.degrees(e[1]) for e in errors)
        print(
            f"path {start}–{start + 50} m: {len(errors)} returns; position median {positions[len(positions) // 2]:.2f}"
            f" worst {positions[-1]:.2f} m; heading median {headings[len(headings) // 2]:.1f}"
            f" worst {headings[-1]:.1f}°"
        )


if __name__ == "__main__":
    main()
