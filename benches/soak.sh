#!/usr/bin/env bash
# Soak bench (not in CI): the SLAM main job twice (as fast as it goes, and
# paced at real time as a robot would feed it) and a 10x real-time
# overload topology, each for about 30 minutes, side by side. Every 10 s
# it samples each process's resident memory (VmRSS) and open file
# descriptors; at the end it prints, per job, the least-squares slope of
# each over the run's second half (after the maps and queues have filled)
# and over the whole run, and the job's own end (exit code, status,
# counters), so that a leak or a drifting counter shows.
#
#   benches/soak.sh [OUT_DIR] [MINUTES]     # defaults: out/soak, 30
#   SOAK_JOBS="slam paced" benches/soak.sh  # some of: slam paced overload
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/soak}"
minutes="${2:-30}"
secs=$((minutes * 60))
squall="${SQUALL:-target/release/squall}"
jobs="${SOAK_JOBS:-slam paced overload}"
mkdir -p "$out"

# Samples PID every 10 s into CSV until it exits: seconds, rss_kib, fds.
sample() {
  local pid="$1" csv="$2" start
  start=$(date +%s)
  echo "secs,rss_kib,fds" >"$csv"
  while kill -0 "$pid" 2>/dev/null; do
    rss=$(awk '/^VmRSS:/ { print $2 }' "/proc/$pid/status" 2>/dev/null || true)
    fds=$(ls "/proc/$pid/fd" 2>/dev/null | wc -l)
    [ -n "$rss" ] && echo "$(($(date +%s) - start)),$rss,$fds" >>"$csv"
    sleep 10
  done
}

pids=()
# The SLAM main job on a longer simulated run, 90 simulated seconds per
# wall second asked for: alone here the 600 s office takes 3.3 s (180x);
# beside the other jobs the scans take most of the time asked for, the
# back end's loop closing at the end the rest.
if [[ " $jobs " == *" slam "* ]]; then
  "$squall" slam --set "source.params.duration_secs=$((secs * 90))" --out "$out/slam" \
    >"$out/slam.stdout" 2>"$out/slam.stderr" &
  pids+=("slam:$!")
fi
# The SLAM main job as a robot feeds it: the simulated office written as
# a log of the soak's length, replayed at its recorded rate (10 scans/s).
if [[ " $jobs " == *" paced "* ]]; then
  "$squall" sim --duration "$secs" --out "$out/paced-log" >/dev/null
  "$squall" slam --log "$out/paced-log/sim.clf" --set source.params.rate=1.0 --out "$out/paced" \
    >"$out/paced.stdout" 2>"$out/paced.stderr" &
  pids+=("paced:$!")
fi
# Overload: the source offers 100 000 probes/s; the sink, 100 us asleep
# per probe, takes well under a tenth of that; both queues drop the
# oldest. Every probe must end received or dropped.
if [[ " $jobs " == *" overload "* ]]; then
  "$squall" run examples/topologies/probe.toml \
    --set "source.params.count=$((secs * 100000))" --set source.params.rate_hz=100000 \
    --set sink.params.delay_us=100 --set relay.inputs.0.policy='"drop_oldest"' \
    --set sink.inputs.0.policy='"drop_oldest"' --quiet --out "$out/overload" \
    >"$out/overload.stdout" 2>"$out/overload.stderr" &
  pids+=("overload:$!")
fi
for entry in "${pids[@]}"; do
  sample "${entry#*:}" "$out/${entry%%:*}.csv" &
done
set +e
rcs=()
for entry in "${pids[@]}"; do
  wait "${entry#*:}"
  rcs+=("${entry%%:*}=$?")
done
wait
set -e

python3 - "$out" "${rcs[@]}" <<'PY'
import csv, json, sys
out, rcs = sys.argv[1], dict(arg.split("=") for arg in sys.argv[2:])

def slope(xs, ys):
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx else 0.0

for job in rcs:
    rows = [(int(r["secs"]), int(r["rss_kib"]), int(r["fds"])) for r in csv.DictReader(open(f"{out}/{job}.csv"))]
    half = rows[len(rows) // 2:]
    t, rss, fds = zip(*rows)
    th, rssh, fdsh = zip(*half)
    m = json.load(open(f"{out}/{job}/metrics.json"))
    comps = {c["name"]: c for c in m["components"]}
    print(f"{job}: exit {rcs[job]}, status {m['status']}, {t[-1]} s, {len(rows)} samples")
    print(f"  rss MiB: first {rss[0]/1024:.1f}, half-way {rssh[0]/1024:.1f}, last {rss[-1]/1024:.1f}, max {max(rss)/1024:.1f}")
    print(f"  rss slope MiB/h: second half {slope(th, rssh) * 3600 / 1024:.2f}, whole run {slope(t, rss) * 3600 / 1024:.2f}")
    print(f"  fds: min {min(fds)}, max {max(fds)}, slope per hour (second half) {slope(th, fdsh) * 3600:.2f}")
    for name, c in comps.items():
        print(f"  {name}: received {c['received']}, emitted {c['emitted']}, dropped {c['dropped']}, undelivered {c['undelivered']}")
PY
