#!/usr/bin/env bash
# Installs recogd as a systemd service from a built tree: the "runtime" component of
# `cmake --install` with the prefix /usr/local (the binaries recogd and recog to /usr/local/bin,
# the bundled vocabularies to /usr/local/share/recog/vocabularies), the configuration example to
# /etc/recogd/recogd.yaml (an existing one is kept), the unit to
# /etc/systemd/system/recogd.service and the user entry to /etc/sysusers.d/recogd.conf; then
# creates the recogd user (systemd-sysusers) and reloads systemd. Start it with: systemctl enable
# --now recogd. Run as root, after a Release build (bash scripts/run.sh, or
# RECOG_CMAKE_ARGS=-DCMAKE_BUILD_TYPE=Release bash scripts/build.sh).
#
# Usage: bash deploy/systemd/install.sh [--root DIR]
#   --root DIR  install under DIR instead of / (for testing or image building; DESTDIR of
#               cmake --install); creates no user and does not touch systemd
#
# Environment:
#   RECOG_BUILD_DIR  build folder holding bin/recogd and bin/recog (default: build)
set -euo pipefail
cd "$(dirname "$0")/../.."

usage() { echo "usage: bash deploy/systemd/install.sh [--root DIR]"; }

root=/
while [ $# -gt 0 ]; do
  case $1 in
    --root) [ $# -ge 2 ] || { echo "install: --root needs a directory" >&2; exit 2; }
            root=$2; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "install: unknown argument '$1'" >&2; usage >&2; exit 2 ;;
  esac
done
[ "$root" = / ] || root=$(realpath -m "$root")
dest=${root%/}  # "" for /, so that paths read "$dest/usr/local/bin"

build_dir=${RECOG_BUILD_DIR:-build}
for bin in recogd recog; do
  [ -x "$build_dir/bin/$bin" ] || {
    echo "install: $build_dir/bin/$bin not found: build first (bash scripts/build.sh)" >&2
    exit 1
  }
done
if [ "$root" = / ] && [ "$(id -u)" -ne 0 ]; then
  echo "install: run as root (or use --root DIR)" >&2
  exit 1
fi

echo "install: into ${root}"
DESTDIR=$dest cmake --install "$build_dir" --prefix /usr/local --component runtime
install -d -m 0755 "$dest/etc/recogd" "$dest/etc/systemd/system" "$dest/etc/sysusers.d"
if [ -e "$dest/etc/recogd/recogd.yaml" ]; then
  echo "install: kept the existing $dest/etc/recogd/recogd.yaml" \
    "(compare it with deploy/config/recogd.yaml)"
else
  install -m 0644 deploy/config/recogd.yaml "$dest/etc/recogd/recogd.yaml"
fi
install -m 0644 deploy/systemd/recogd.service "$dest/etc/systemd/system/recogd.service"
install -m 0644 deploy/systemd/recogd.sysusers.conf "$dest/etc/sysusers.d/recogd.conf"

if [ "$root" != / ]; then
  echo "install: done under $root (no user created, systemd not reloaded)"
  exit 0
fi

if command -v systemd-sysusers >/dev/null; then
  systemd-sysusers /etc/sysusers.d/recogd.conf
else
  echo "install: systemd-sysusers not found; create the user with:"
  echo "  useradd --system --user-group --home-dir /var/lib/recogd --shell /usr/sbin/nologin recogd"
fi
# systemctl needs a running systemd (not the case in most containers and chroots).
if command -v systemctl >/dev/null && [ -d /run/systemd/system ]; then
  systemctl daemon-reload
  echo "install: done; start it with: systemctl enable --now recogd"
else
  echo "install: done; systemd is not running here: on the target, run"
  echo "  systemctl daemon-reload && systemctl enable --now recogd"
fi
