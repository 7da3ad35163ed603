#!/usr/bin/env bash
# The cost of watching the SLAM main job (docs/results/watching-cost.md):
# ROUNDS rounds, each running, one after another,
#   before  the binary BEFORE (a build of the commit before watching existed), no flags;
#   off     the binary NOW, no flags;
#   on      NOW with --ui, --foxglove and --record;
#   client  the same with a Foxglove client (tests/clients/foxglove_check.py)
#           subscribed to every channel, at normal priority;
#   niced   the same with the client at nice 19 (a viewer that takes only
#           CPU the run leaves, as one on another machine would);
# and printing each run's wall time (the run's own, from metrics.json) and
# the squall process's CPU time (user + system, from GNU time).
# usage: watching_cost.sh BEFORE NOW ROUNDS
set -euo pipefail
before=$1 now=$2 rounds=${3:-5}
here=$(cd "$(dirname "$0")/../../.." && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
wall() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['wall_secs'])" "$1/metrics.json"; }
cpu() { awk '{ print $1 + $2 }' "$work/$1.cpu"; }
timed() { local name=$1; shift; /usr/bin/time -f "%U %S" -o "$work/$name.cpu" "$@"; }
echo "round,setting,wall_secs,cpu_secs"
for r in $(seq 1 "$rounds"); do
  timed before "$before" slam --out "$work/before" > /dev/null 2>&1
  echo "$r,before,$(wall "$work/before"),$(cpu before)"
  timed off "$now" slam --out "$work/off" > /dev/null 2>&1
  echo "$r,off,$(wall "$work/off"),$(cpu off)"
  timed on "$now" slam --out "$work/on" --ui 127.0.0.1:0 --foxglove 127.0.0.1:0 --record "$work/on.mcap" \
      > /dev/null 2>&1
  echo "$r,on,$(wall "$work/on"),$(cpu on)"
  for setting in client niced; do
    port=$(python3 -c "import socket; s=socket.socket(); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])")
    timed "$setting" "$now" slam --out "$work/$setting" --ui 127.0.0.1:0 --foxglove "127.0.0.1:$port" \
        --record "$work/$setting.mcap" > /dev/null 2>&1 &
    squall_pid=$!
    for _ in $(seq 1 100); do
      python3 -c "import socket; socket.create_connection(('127.0.0.1',$port),0.1)" 2> /dev/null && break
      sleep 0.02
    done
    priority=0
    [ "$setting" = niced ] && priority=19
    nice -n "$priority" python3 "$here/tests/clients/foxglove_check.py" live "ws://127.0.0.1:$port" /never \
        > /dev/null 2>&1 &
    client_pid=$!
    wait "$squall_pid"
    kill "$client_pid" 2> /dev/null || true
    echo "$r,$setting,$(wall "$work/$setting"),$(cpu "$setting")"
  done
  cmp "$work/before/trajectory.tum" "$work/on/trajectory.tum"
  cmp "$work/before/map.pgm" "$work/client/map.pgm"
done
