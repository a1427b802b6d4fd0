#!/usr/bin/env bash
# Bakes every shared scene with `bvhopt bake --quality best` into OUT_DIR/<scene>.bvh, the
# trees trace_bench --baked OUT_DIR traces as "our best tree" (spatial splits allowed).
#   scripts/bake-shared-scenes.sh OUT_DIR [bake options, e.g. --threads 2]
# The scenes are read from $BVHOPT_SCENES (default ../shared/scenes beside the repository);
# bvhopt from $BVHOPT (default build/release/bvhopt).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 1 ]; then
  echo "usage: $0 OUT_DIR [bake options]" >&2
  exit 2
fi
out=$1
shift
scenes=${BVHOPT_SCENES:-../shared/scenes}
bvhopt=${BVHOPT:-build/release/bvhopt}
[ -x "$bvhopt" ] || { echo "$0: no $bvhopt (build the release preset first)" >&2; exit 1; }
[ -f "$scenes/MANIFEST.tsv" ] || { echo "$0: no $scenes/MANIFEST.tsv (set BVHOPT_SCENES)" >&2; exit 1; }
mkdir -p "$out"
# The manifest's first column names each scene file; its first line is the header.
tail -n +2 "$scenes/MANIFEST.tsv" | cut -f1 | while read -r file; do
  [ -n "$file" ] || continue
  stem=${file%.*}
  echo "== $file"
  "$bvhopt" bake "$scenes/$file" --quality best -o "$out/$stem.bvh" "$@" | grep -E "^(written|memory)"
done
