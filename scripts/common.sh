# Shared by scripts/demo.sh and scripts/test.sh: packages and the build.
# shellcheck shell=bash

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD_DIR="${FUSION_BUILD_DIR:-$ROOT/build}"
JOBS="${FUSION_JOBS:-2}"

PACKAGES=(build-essential cmake ninja-build pkg-config
  cyclonedds-dev cyclonedds-tools libeigen3-dev liboctomap-dev octomap-tools
  libprotobuf-dev protobuf-compiler libgrpc++-dev protobuf-compiler-grpc
  libspdlog-dev googletest libgtest-dev libgmock-dev libbenchmark-dev
  libpng-dev python3-grpcio docker-compose prometheus-cpp-dev prometheus
  libsqlite3-dev libzstd-dev liblz4-dev libfastrtps-dev libfastcdr-dev fastddsgen)

log() { printf '\033[1m==> %s\033[0m\n' "$*"; }

# Installs whatever of PACKAGES is missing (Debian 12, as root or with sudo).
ensure_packages() {
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  log "installing ${missing[*]}"
  local sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

# Configures (once) and builds incrementally. Extra arguments are CMake -D options.
build() {
  if [ ! -f "$BUILD_DIR/build.ninja" ]; then
    log "configuring $BUILD_DIR"
    cmake -S "$ROOT" -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@"
  fi
  log "building (-j$JOBS)"
  cmake --build "$BUILD_DIR" -j "$JOBS"
}
