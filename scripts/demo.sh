#!/usr/bin/env bash
# The main job: the paper's experiment (Fig. 5) through the whole service.
#   build; start fusiond (docker/fusiond.pbtxt) on loopback; two simulated sensors (SR-3000
#   and STOC stereo) publish a board at 1.75 m and a floor over DDS; wait for the map; print
#   the planes found, a few queries and a path check; write the snapshot and a picture;
#   stop everything cleanly. Output goes to demo-output/ (FUSION_DEMO_OUT overrides).
set -euo pipefail
source "$(dirname "$0")/common.sh"

ensure_packages
build

OUT="${FUSION_DEMO_OUT:-$ROOT/demo-output}"
mkdir -p "$OUT"
rm -f "$OUT"/map.ot "$OUT"/map.bt "$OUT"/map.png "$OUT"/*.log
DOMAIN="${FUSION_DDS_DOMAIN:-$((1 + $$ % 200))}"
BIN="$BUILD_DIR"
FUSIONCTL="$BIN/clients/fusionctl"
PIDS=()
cleanup() {
  for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT

log "starting fusiond (config docker/fusiond.pbtxt, DDS domain $DOMAIN, loopback only)"
"$BIN/service/fusiond" --config "$ROOT/docker/fusiond.pbtxt" --listen 127.0.0.1:0 \
  --dds-domain "$DOMAIN" --snapshot "$OUT/map.ot" --log-level warn >"$OUT/fusiond.log" 2>&1 &
FUSIOND_PID=$!
PIDS+=("$FUSIOND_PID")
ADDRESS=""
for _ in $(seq 200); do
  ADDRESS="$(sed -n 's/^fusiond listening on \(.*\)$/\1/p' "$OUT/fusiond.log")"
  [ -n "$ADDRESS" ] && break
  kill -0 "$FUSIOND_PID" 2>/dev/null || { cat "$OUT/fusiond.log"; exit 1; }
  sleep 0.1
done
[ -n "$ADDRESS" ] || { echo "fusiond did not report its address"; cat "$OUT/fusiond.log"; exit 1; }
export FUSIOND_ADDRESS="$ADDRESS"
log "fusiond listening on $ADDRESS: $("$FUSIONCTL" health)"

SR_FRAMES=30
STOC_FRAMES=15
log "publishing $SR_FRAMES SR-3000 and $STOC_FRAMES stereo frames of the paper's board scene"
"$BIN/clients/fusion-sim-sensor" --preset sr3000 --rate 10 --frames "$SR_FRAMES" \
  --domain "$DOMAIN" --wait-readers 1 >"$OUT/sensor-sr3000.log" 2>&1 &
SR_PID=$!
"$BIN/clients/fusion-sim-sensor" --preset stoc --rate 5 --frames "$STOC_FRAMES" \
  --domain "$DOMAIN" --wait-readers 1 >"$OUT/sensor-stoc.log" 2>&1 &
STOC_PID=$!
PIDS+=("$SR_PID" "$STOC_PID")
wait "$SR_PID" "$STOC_PID"

# Wait for the worker: every received cloud integrated (or dropped or rejected, counted),
# then the map version stops moving (the last render is published). The publishers have
# finished, so what has not arrived by now was lost by best-effort DDS.
last_received=-1
for _ in $(seq 120); do
  counts="$("$FUSIONCTL" sensors | awk 'NR > 1 && $1 != "rejected" {r += $5; d += $6 + $7 + $8; i += $6}
    END {print r, d, i}')"
  read -r received done integrated <<<"$counts"
  printf '  clouds received %s of %s published, integrated %s\n' "$received" \
    $((SR_FRAMES + STOC_FRAMES)) "$integrated"
  [ "$received" -eq "$last_received" ] && [ "$done" -eq "$received" ] && break
  last_received="$received"
  sleep 0.5
done
previous=""
for _ in $(seq 30); do  # a render of a stationary period takes about a second here
  version="$("$FUSIONCTL" stats | awk '$1 == "map_version" {print $2}')"
  [ "$version" = "$previous" ] && break
  previous="$version"
  sleep 2
done

log "sensors"
"$FUSIONCTL" sensors
log "map statistics"
"$FUSIONCTL" stats
log "planes (Hough transform; world frame x forward, y left, z up; the paper's board is at"
log "d = 1750 mm with its normal along x, the floor 0.41 m below the sensors)"
"$FUSIONCTL" planes --max 4
log "occupancy: in front of the board, on the board, behind it"
"$FUSIONCTL" points 1.0,0,0 1.75,0,0 2.2,0,0
log "ray cast along the optical axis"
"$FUSIONCTL" ray 0 0 0 1 0 0 --max-range 5 --ignore-unknown
if /usr/bin/python3 -c "import grpc" 2>/dev/null; then
  log "Python planner client: is the straight path to (2.5, 0, 0) clear?"
  PYTHONPATH="$BIN/clients/python" /usr/bin/python3 "$ROOT/clients/python/path_check.py" \
    --server "$ADDRESS" --from 0.5,0,0 --to 2.5,0,0 || true
fi
log "snapshot and picture"
"$FUSIONCTL" snapshot "$OUT/map.bt"
"$FUSIONCTL" render "$OUT/map.png" --azimuth -150 --elevation 25

log "stopping fusiond (SIGTERM: drain, save, exit)"
kill -TERM "$FUSIOND_PID"
STATUS=0
wait "$FUSIOND_PID" || STATUS=$?
PIDS=()
grep -E "snapshot|error|warn" "$OUT/fusiond.log" | tail -3 || true
[ "$STATUS" -eq 0 ] || { echo "fusiond exited with status $STATUS"; exit "$STATUS"; }
log "done: $OUT/map.png (picture), $OUT/map.bt and $OUT/map.ot (OctoMap), logs in $OUT/"
