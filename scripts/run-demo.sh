#!/usr/bin/env bash
# Set-up and main job: install what is missing, build in Release, run `bvhopt demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake --preset release >/dev/null
cmake --build --preset release --target bvhopt_cli
./build/release/bvhopt demo "$@"
