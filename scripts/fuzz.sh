#!/usr/bin/env bash
# libFuzzer targets of tests/fuzz (docs/fuzzing.md), built with clang into build-fuzz/.
#   scripts/fuzz.sh build              configure (once) and build every target
#   scripts/fuzz.sh seeds              write seed corpora to build-fuzz/corpus/<target>/
#   scripts/fuzz.sh run [SECONDS] [T..] each target SECONDS (default 20), fails on any crash
#   scripts/fuzz.sh long [RUNS] [T..]   the long run: RUNS executions per target (default 10 M),
#                                      at most FUSION_FUZZ_LONG_SECONDS (default 1200) each
#   scripts/fuzz.sh list               the target names
# Targets run FUSION_JOBS (default 2) at a time. Crash inputs land in build-fuzz/artifacts/<target>/;
# logs in build-fuzz/logs/. FUSION_FUZZ_BUILD_DIR overrides build-fuzz, FUSION_SHARED_DATA the
# real samples (../shared/data).
set -euo pipefail
source "$(dirname "$0")/common.sh"

FUZZ_DIR="${FUSION_FUZZ_BUILD_DIR:-$ROOT/build-fuzz}"
SHARED="${FUSION_SHARED_DATA:-$ROOT/../shared/data}"
REGRESSIONS="$ROOT/tests/fuzz/regressions"
DICTS="$ROOT/tests/fuzz/dicts"
# Limits of every run: a crash, a leak, a 10 s input or 2 GB of memory fail it.
FUZZ_FLAGS=(-rss_limit_mb=2048 -timeout=10 -print_final_stats=1)

usage() { sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'; }

all_targets() {
  local f
  for f in "$ROOT"/tests/fuzz/fuzz_*.cc; do
    f="${f##*/fuzz_}"
    echo "${f%.cc}"
  done
}

# Line tables are enough for symbolized crash reports and compile much faster than -g;
# no -DNDEBUG: assertions stay on while fuzzing.
FLAGS=(-DCMAKE_C_FLAGS_RELWITHDEBINFO="-O2 -gline-tables-only"
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -gline-tables-only")

build_fuzzers() {
  # Debian's clang brings libFuzzer and the sanitizer runtimes (libclang-common-14-dev).
  PACKAGES+=(clang)
  ensure_packages
  if [ ! -f "$FUZZ_DIR/build.ninja" ]; then
    log "configuring $FUZZ_DIR (clang, address+undefined, libFuzzer)"
    CC=clang CXX=clang++ cmake -S "$ROOT" -B "$FUZZ_DIR" -G Ninja \
      -DCMAKE_BUILD_TYPE=RelWithDebInfo -DFUSION_SANITIZER=address -DFUSION_BUILD_FUZZERS=ON \
      -DFUSION_BUILD_BENCHMARKS=OFF "${FLAGS[@]}" >/dev/null
  fi
  log "building the fuzz targets (-j$JOBS)"
  cmake --build "$FUZZ_DIR" -j "$JOBS" --target fusion_fuzzers
}

write_seeds() {
  local shared=()
  if [ -d "$SHARED" ]; then
    shared=("$SHARED")
  else
    log "$SHARED not found: real-data seeds skipped, synthetic seeds only"
  fi
  "$FUZZ_DIR/tests/fuzz/fusion_fuzz_seeds" "$FUZZ_DIR/corpus" "$ROOT" "${shared[@]}"
}

# Scratch directories of fuzz processes that no longer run (a crash skips their cleanup).
remove_stale_scratch() {
  local d pid
  for d in "${TMPDIR:-/tmp}"/fusion-fuzz-*; do
    [ -d "$d" ] || continue
    pid="${d##*/fusion-fuzz-}"
    pid="${pid%%-*}"
    kill -0 "$pid" 2>/dev/null || rm -rf "$d"
  done
}

# fuzz_one TARGET FLAG...: runs one target over its corpus and regressions; logs to logs/TARGET.log.
fuzz_one() {
  local target="$1"
  shift
  local corpus="$FUZZ_DIR/corpus/$target" artifacts="$FUZZ_DIR/artifacts/$target"
  local extra=() rc=0
  mkdir -p "$corpus" "$artifacts" "$FUZZ_DIR/logs"
  [ -f "$DICTS/$target.dict" ] && extra+=("-dict=$DICTS/$target.dict")
  [ -d "$REGRESSIONS/$target" ] && extra+=("$REGRESSIONS/$target")
  "$FUZZ_DIR/tests/fuzz/fuzz_$target" "${FUZZ_FLAGS[@]}" "$@" -artifact_prefix="$artifacts/" \
    "$corpus" "${extra[@]}" >"$FUZZ_DIR/logs/$target.log" 2>&1 || rc=$?
  return "$rc"
}

# summary TARGET RC SECONDS: one line from the target's final stats.
summary() {
  local log="$FUZZ_DIR/logs/$1.log" runs rate
  runs=$(grep -ao 'stat::number_of_executed_units:[[:space:]]*[0-9]*' "$log" | tail -1 | awk '{print $2}' || true)
  rate=$(grep -ao 'stat::average_exec_per_sec:[[:space:]]*[0-9]*' "$log" | tail -1 | awk '{print $2}' || true)
  printf '%-12s %12s execs %8s exec/s %6ss  %s\n' "$1" "${runs:-?}" "${rate:-?}" "$3" \
    "$([ "$2" -eq 0 ] && echo ok || echo "FAILED (rc $2, see $log)")"
}

# fuzz_all "FLAG..." TARGET...: JOBS targets at a time; fails if any target fails.
fuzz_all() {
  local flags="$1"
  shift
  local targets=("$@") t
  local results="$FUZZ_DIR/logs/results.txt"
  mkdir -p "$FUZZ_DIR/logs"
  : >"$results"
  for t in "${targets[@]}"; do
    while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do wait -n || true; done
    # shellcheck disable=SC2086
    (start=$SECONDS; rc=0; fuzz_one "$t" $flags || rc=$?
     summary "$t" "$rc" "$((SECONDS - start))" | tee -a "$results"; exit "$rc") &
  done
  while [ "$(jobs -rp | wc -l)" -gt 0 ]; do wait -n || true; done
  remove_stale_scratch
  if grep -q FAILED "$results"; then
    log "crashes found: inputs in $FUZZ_DIR/artifacts/"
    return 1
  fi
  log "no crashes ($(wc -l <"$results") targets)"
}

targets_or_all() { if [ $# -gt 0 ]; then printf '%s\n' "$@"; else all_targets; fi; }

cmd="${1:-help}"
[ $# -gt 0 ] && shift
case "$cmd" in
  build) build_fuzzers ;;
  seeds) build_fuzzers; write_seeds ;;
  run)
    seconds="${1:-20}"
    [ $# -gt 0 ] && shift
    build_fuzzers
    [ -d "$FUZZ_DIR/corpus" ] || write_seeds
    mapfile -t selected < <(targets_or_all "$@")
    log "fuzzing ${#selected[@]} targets for ${seconds} s each, $JOBS at a time"
    fuzz_all "-max_total_time=$seconds" "${selected[@]}"
    ;;
  long)
    runs="${1:-10000000}"
    [ $# -gt 0 ] && shift
    build_fuzzers
    [ -d "$FUZZ_DIR/corpus" ] || write_seeds
    mapfile -t selected < <(targets_or_all "$@")
    log "long run: $runs executions per target (at most ${FUSION_FUZZ_LONG_SECONDS:-1200} s each), $JOBS at a time ($(date -u +%FT%TZ))"
    fuzz_all "-runs=$runs -max_total_time=${FUSION_FUZZ_LONG_SECONDS:-1200}" "${selected[@]}"
    ;;
  list) all_targets ;;
  -h | --help | help) usage ;;
  *) usage >&2; exit 2 ;;
esac
