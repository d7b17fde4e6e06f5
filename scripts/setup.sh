#!/usr/bin/env bash
# Set up curate on a fresh machine: system library for open3d, the CPU build of torch
# (before anything else, or pip pulls a multi-GB CUDA build), then curate and its test tools.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && ! dpkg -s libusb-1.0-0 >/dev/null 2>&1; then
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
fi
"$PY" -m pip install -q --disable-pip-version-check "torch==2.13.0"
# ray: `curate batch --executor ray` and its test (wheel ~80 MB, ~250 MB installed, ~25 s)
"$PY" -m pip install -q --disable-pip-version-check -e ".[test,ray]"
