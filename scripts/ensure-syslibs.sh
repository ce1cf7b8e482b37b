#!/usr/bin/env bash
# Install the system libraries that the Python packages of `make test` load at run
# time, saying which, why and how. Only `make test` runs this: the demo loads none.
#
# Each entry: the shared library, the Debian/Ubuntu package holding it, and why.
set -euo pipefail
libs=(
  "libusb-1.0.so|libusb-1.0-0|open3d-cpu, which the point-cloud tests use, loads it"
)
missing=() why=()
for entry in "${libs[@]}"; do
  IFS='|' read -r lib package reason <<< "$entry"
  if ldconfig -p 2> /dev/null | grep -q "$lib"; then
    echo "==> system library ${lib%.so} is installed ($reason)"
  else
    missing+=("$package")
    why+=("$package: $reason")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get > /dev/null; then
  echo "==> running apt-get as root to install the system package(s) ${missing[*]} (${why[*]})"
  DEBIAN_FRONTEND=noninteractive apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" > /dev/null
else
  echo "==> missing system packages: ${why[*]}; the tests that need them fail until you run:" >&2
  echo "    sudo apt-get install -y ${missing[*]}" >&2
fi
