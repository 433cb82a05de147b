#!/usr/bin/env bash
# Builds and runs the whole test suite (unit + integration) with ctest.
#   scripts/test.sh             everything
#   scripts/test.sh -L unit     only one label (any ctest arguments pass through)
set -euo pipefail
source "$(dirname "$0")/common.sh"

ensure_packages
build
log "running tests"
cd "$BUILD_DIR"
rm -rf test-tmp && mkdir -p test-tmp  # the tests' scratch files (TEST_TMPDIR)
ctest --output-on-failure -j "$JOBS" --timeout 300 "$@"
