#!/usr/bin/env bash
# Installs the project's dependencies from Debian 12 packages. Idempotent: packages already
# present are left alone. Run as root (or with sudo).
#
# Usage: bash scripts/install_deps.sh [--serve]
#   --serve  only what building everything and serving needs (scripts/run.sh, the Dockerfile's
#            build stage): compilers, the libraries, GoogleTest and Google Benchmark (the
#            configuration includes the tests), gnuplot and the console's scripts. Without it,
#            also what the tests and checks use (scripts/test.sh, CI): Python and its packages, a
#            headless browser, nginx, Prometheus, clang-format, mkdocs, ROS 1's Python bag writer
#            and ccache (CI's two builds share the tests' objects through it). On a fresh machine
#            the serving set is about a third of the download.
set -euo pipefail

serve_packages=(
  build-essential cmake ninja-build pkg-config git mold
  libopencv-dev libeigen3-dev libspdlog-dev libxxhash-dev zlib1g-dev libtinyxml2-dev
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  librocksdb-dev prometheus-cpp-dev libssl-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev libyaml-cpp-dev nlohmann-json3-dev
  libcpp-httplib-dev libjs-three libjs-chart.js
  librosbag-storage-dev libsensor-msgs-dev libzstd-dev liblz4-dev libsqlite3-dev gnuplot-nox
)
test_packages=(
  python3-grpcio python3-protobuf python3-venv python3-setuptools python3-wheel
  python3-numpy python3-opencv python3-yaml
  nginx openssl
  prometheus
  chromium chromium-driver python3-selenium
  clang-format
  mkdocs mkdocs-material
  python3-rosbag python3-sensor-msgs
  ccache
)

case "${1:-}" in
  --serve) packages=("${serve_packages[@]}") ;;
  "") packages=("${serve_packages[@]}" "${test_packages[@]}") ;;
  *) echo "usage: bash scripts/install_deps.sh [--serve]" >&2; exit 2 ;;
esac

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#packages[@]} packages already installed"
  exit 0
fi

sudo_cmd=()
[ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
echo "install_deps: installing ${missing[*]}"
"${sudo_cmd[@]}" apt-get update -q
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
echo "install_deps: installed ${#missing[@]} packages and what they need"
