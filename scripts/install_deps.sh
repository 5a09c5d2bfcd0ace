#!/usr/bin/env bash
# Installs every build and test dependency of the project from Debian 12 packages.
# Idempotent: packages already present are left alone. Run as root (or with sudo).
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libopencv-dev libeigen3-dev libspdlog-dev libxxhash-dev zlib1g-dev libtinyxml2-dev
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  librocksdb-dev prometheus-cpp-dev libssl-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev libyaml-cpp-dev nlohmann-json3-dev
  python3-grpcio python3-protobuf python3-venv python3-setuptools python3-wheel
  python3-numpy python3-opencv python3-yaml
  nginx openssl
  prometheus gnuplot-nox
  libcpp-httplib-dev libjs-three libjs-chart.js chromium chromium-driver python3-selenium
  clang-format
  mkdocs mkdocs-material
  librosbag-storage-dev libsensor-msgs-dev python3-rosbag python3-sensor-msgs
)

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
