#!/usr/bin/env bash
# Install the system libraries that the Python packages we use load at run time.
# open3d-cpu (the `pointcloud` extra) needs libusb-1.0.
set -euo pipefail
missing=()
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so'; then missing+=(libusb-1.0-0); fi
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "installing system libraries: ${missing[*]}"
  DEBIAN_FRONTEND=noninteractive apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
else
  echo "missing system libraries; run: sudo apt-get install -y ${missing[*]}" >&2
fi
