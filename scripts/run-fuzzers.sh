#!/usr/bin/env bash
# Builds the libFuzzer targets (preset `fuzz`), writes their seed corpora and runs each for
# SECONDS_PER_TARGET seconds (default 30); exits non-zero on the first finding, whose input
# libFuzzer writes to build/<preset>/findings/. Corpora grow in build/<preset>/corpus/ across runs.
# Usage: scripts/run-fuzzers.sh [SECONDS_PER_TARGET [TARGET...]]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-30}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(bvh_file ray_file scene_file builtin_spec pipeline)

# BVHOPT_FUZZ_PRESET=sanitize runs the fuzzers of the sanitizer build (CI builds them there,
# one clang build for both); by default the preset `fuzz`, which builds only the fuzzers.
preset=${BVHOPT_FUZZ_PRESET:-fuzz}
cmake --preset "$preset" >/dev/null
cmake --build --preset "$preset"
build=build/$preset
corpus=$build/corpus
findings=$build/findings
mkdir -p "$corpus" "$findings"
./$build/fuzz/fuzz_seed_corpus "$corpus"
# Each input is written to a temporary file (the readers take paths): in memory, where the
# machine has it, that is about four times the executions of a disk-backed /tmp.
if [ -z "${TMPDIR:-}" ] && [ -d /dev/shm ] && [ -w /dev/shm ]; then export TMPDIR=/dev/shm; fi
export LSAN_OPTIONS="suppressions=$PWD/fuzz/lsan.supp${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
export ASAN_OPTIONS="suppressions=$PWD/fuzz/asan.supp${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export UBSAN_OPTIONS="print_stacktrace=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
# More libFuzzer flags for every target, e.g. BVHOPT_FUZZ_FLAGS="-entropic=0" (about 25 %
# more executions of the pipeline target, whose inputs are cheap to score).
read -r -a extra <<<"${BVHOPT_FUZZ_FLAGS:-}"
reproducible=()
if [ -n "${BVHOPT_FUZZ_RUNS:-}" ]; then
  reproducible=(-runs="$BVHOPT_FUZZ_RUNS" -seed="${BVHOPT_FUZZ_SEED:-1}")
fi
for t in "${targets[@]}"; do
  echo "== fuzzing $t for ${seconds} s"
  # Inputs that once failed (fuzz/corpus/<target>/) are replayed first, with the seeds.
  regressions=()
  [ -d "fuzz/corpus/$t" ] && regressions=("fuzz/corpus/$t")
  status=0
  ./$build/fuzz/"${t}_fuzzer" -max_total_time="$seconds" "${reproducible[@]}" "${extra[@]}" -rss_limit_mb=2048 -timeout=25 \
    -artifact_prefix="$findings/${t}-" -print_final_stats=1 "$corpus/$t" "${regressions[@]}" \
    >"$findings/$t.log" 2>&1 || status=$?
  grep -E "^stat::(number_of_executed_units|peak_rss_mb)" "$findings/$t.log" || true
  if [ "$status" -ne 0 ]; then
    tail -n 60 "$findings/$t.log" >&2
    echo "fuzzer $t found a problem (exit $status); input in $findings/, log $findings/$t.log" >&2
    exit 1
  fi
done
