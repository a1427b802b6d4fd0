#!/usr/bin/env bash
# Prints the deterministic outputs of the pipeline (costs, passes, moves and each tree's
# file checksum) for every builder and optimizer on the built-in scene and every shared
# scene, one line each. Run it before and after a change that must not change any tree,
# and diff the two outputs. Timings are left out on purpose.
#   scripts/determinism-snapshot.sh [BVHOPT_BINARY] > snapshot.txt
set -euo pipefail
bin=${1:-build/release/bvhopt}
scenes_dir=${BVHOPT_SCENES:-$(git -C "$(dirname "$0")" worktree list --porcelain 2>/dev/null | sed -n "1s/^worktree //p")/../shared/scenes}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fields() { python3 -c 'import json,sys; d=json.load(sys.stdin); print(" ".join(f"{k}={d[k]}" for k in sys.argv[1:] if k in d))' "$@"; }
scenes=("builtin?triangles=30000")
if [ -d "$scenes_dir" ]; then
  for f in "$scenes_dir"/*.obj "$scenes_dir"/*.ply "$scenes_dir"/*.glb; do [ -f "$f" ] && scenes+=("$f"); done
fi
for scene in "${scenes[@]}"; do
  name=$(basename "$scene")
  for builder in sweep binned spatial-median object-median; do
    for leaf in 1 4; do
      out="$work/$builder-$leaf.bvh"
      line=$("$bin" build "$scene" --builder "$builder" --leaf-size "$leaf" --threads 2 -o "$out" --json | fields cost ocost nodes max_depth)
      echo "$name build $builder leaf=$leaf $line sha=$(sha256sum <"$out" | cut -c1-16)"
    done
  done
  "$bin" build "$scene" --builder binned --bins 64 --threads 2 -o "$work/binned64.bvh" --json >/dev/null
  echo "$name build binned bins=64 sha=$(sha256sum <"$work/binned64.bvh" | cut -c1-16)"
  "$bin" build "$scene" --evh --threads 2 -o "$work/evh.bvh" --json >/dev/null
  echo "$name build sweep evh sha=$(sha256sum <"$work/evh.bvh" | cut -c1-16)"
  start="$work/sweep-1.bvh"
  for spec in "hill-climb" "anneal --schedule-passes 100 --passes 150" \
              "insertion --form sequential --passes 40" "insertion --form parallel --passes 40" \
              "insertion --form hybrid --passes 60"; do
    out="$work/opt.bvh"
    # shellcheck disable=SC2086
    line=$("$bin" optimize "$start" --method $spec --seed 3 --threads 2 -o "$out" --json | fields cost_before cost_after passes moves ocost stop_reason)
    echo "$name optimize $spec $line sha=$(sha256sum <"$out" | cut -c1-16)"
    if [ "$spec" = "insertion --form hybrid --passes 60" ]; then
      line=$("$bin" compact "$out" -o "$work/compact.bvh" --json | fields cost_before cost_after leaves_after)
      echo "$name compact $line sha=$(sha256sum <"$work/compact.bvh" | cut -c1-16)"
      "$bin" stats "$work/compact.bvh" --json | fields cost ocost leaves max_depth | sed "s/^/$name stats /"
    fi
  done
done
