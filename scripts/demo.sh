#!/usr/bin/env bash
# The main job: build, start fusiond on loopback, show it alive, stop it cleanly.
set -euo pipefail
source "$(dirname "$0")/common.sh"

ensure_packages
build

DOMAIN="${FUSION_DDS_DOMAIN:-$((1 + $$ % 200))}"
OUT="$(mktemp -d)"
trap 'kill "${FUSIOND_PID:-}" 2>/dev/null || true; rm -rf "$OUT"' EXIT

log "starting fusiond (DDS domain $DOMAIN, loopback only)"
"$BUILD_DIR/service/fusiond" --listen 127.0.0.1:0 --dds-domain "$DOMAIN" >"$OUT/fusiond.out" 2>&1 &
FUSIOND_PID=$!
for _ in $(seq 100); do
  grep -q "listening on" "$OUT/fusiond.out" && break
  kill -0 "$FUSIOND_PID" 2>/dev/null || { cat "$OUT/fusiond.out"; exit 1; }
  sleep 0.1
done
ADDRESS="$(sed -n 's/^fusiond listening on \(.*\)$/\1/p' "$OUT/fusiond.out")"
[ -n "$ADDRESS" ] || { echo "fusiond did not report its address"; cat "$OUT/fusiond.out"; exit 1; }
log "fusiond listening on $ADDRESS"

FUSIONCTL="$BUILD_DIR/clients/fusionctl"
log "health check"
"$FUSIONCTL" --server "$ADDRESS" health
log "stats"
"$FUSIONCTL" --server "$ADDRESS" stats

log "stopping fusiond (SIGTERM)"
kill -TERM "$FUSIOND_PID"
STATUS=0
wait "$FUSIOND_PID" || STATUS=$?
FUSIOND_PID=""
cat "$OUT/fusiond.out"
log "fusiond exited with status $STATUS"
exit "$STATUS"
