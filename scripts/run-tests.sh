#!/usr/bin/env bash
# Set-up and the whole test suite: install what is missing, build in Release, run CTest.
# The shared scenes are read from $BVHOPT_SCENES (default ../shared/scenes beside the repository).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake --preset release -DBVHOPT_BUILD_TESTS=ON >/dev/null
cmake --build --preset release
echo "== set up and built in $SECONDS s; the tests:"
ctest --preset release -j 2 --no-tests=error "$@"
