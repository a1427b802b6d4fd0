#!/usr/bin/env bash
# Installs the Debian packages bvhopt needs, only those missing. Run as root on Debian 12.
set -euo pipefail
packages=(
  g++ cmake ninja-build pkg-config ccache
  libassimp-dev libtbb-dev libcli11-dev nlohmann-json3-dev libstb-dev fonts-dejavu-core
  libgtest-dev libgmock-dev libbenchmark-dev
  libembree-dev python3 python3-matplotlib
  python3-dev pybind11-dev python3-numpy python3-pytest
  clang-14 libclang-rt-14-dev
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  if [ "$(id -u)" -ne 0 ]; then
    echo "error: these packages are missing and installing them needs root: ${missing[*]}" >&2
    exit 1
  fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
