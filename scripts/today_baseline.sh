#!/bin/bash
# The baseline estimator the speed-accuracy chart compares with (commit
# ea47cd5, estimator 1: centroid samples on small triangles, --samples-per-vertex 2),
# swept over rays on chart --real's three scenes and scored against the same
# converged references (docs/speed-accuracy.md, "Baseline: the centroid estimator").
#
# usage: scripts/today_baseline.sh [DATA [CACHE [OUT]]]
#   DATA  ../shared/data          (the Ferrari and the grey-white room)
#   CACHE docs/chart              (chart --real's output folder with its references;
#                                  missing references are baked there first: ~1.5 h)
#   OUT   target/today-baseline   (the old build, the meshes, the bundles, scores.txt)
# About 5 minutes of old bakes on 2 cores after a 4-minute build.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${1:-../shared/data}
CACHE=${2:-docs/chart}
OUT=${3:-target/today-baseline}
COMMIT=ea47cd5
# OUT is this script's alone: an existing folder it did not make is refused,
# so that its bundles, JSON and worktree never replace anybody's files.
MARK=.today-baseline
if [ -e "$OUT" ] && [ ! -e "$OUT/$MARK" ] && [ -n "$(ls -A "$OUT" 2>/dev/null)" ]; then
    echo "$0: $OUT exists and is not a folder this script made (no $MARK in it); choose another OUT" >&2
    exit 2
fi
mkdir -p "$OUT" "$CACHE"
touch "$OUT/$MARK"
OUT=$(cd "$OUT" && pwd)

if [ ! -d "$OUT/src" ]; then
    git worktree add --detach "$OUT/src" "$COMMIT" >&2
fi
(cd "$OUT/src" && CARGO_TARGET_DIR="$OUT/target" cargo build --release --bin prtbake >&2)
OLD=$OUT/target/release/prtbake
cargo build --release --example real_score >&2
SCORE=target/release/examples/real_score

# The cleaned cabin and room exactly as the chart bakes them (the old code
# reads the OBJ's vertices in order; its own --clean differs).
$SCORE "$DATA" "$CACHE" cabin export "$OUT/cabin.obj"
$SCORE "$DATA" "$CACHE" room export "$OUT/room.obj"

common=(--order 3 --bounces 3 --channels 1 --quantize f32 --threads 2 --json)
sweep() { # scene input rays… -- extra args
    local scene=$1 input=$2
    shift 2
    local rays=()
    while [ "$1" != -- ]; do rays+=("$1"); shift; done
    shift
    for r in "${rays[@]}"; do
        echo "today's code: $scene, $r rays" >&2
        "$OLD" bake "$input" -o "$OUT/$scene-$r.prtb" "${common[@]}" --rays "$r" "$@" > "$OUT/$scene-$r.json"
    done
}
sweep cabin "$OUT/cabin.obj" 24 48 96 192 384 768 -- --window glass
sweep room "$OUT/room.obj" 32 64 128 256 512 1024 --
sweep ferrari "$DATA/car-ferrari458/ferrari_nodraco.glb" 32 64 128 256 512 -- --window Glass_Gray

# Seconds as the chart counts them: the bake with its BVH build, not load or write.
for scene in ferrari room cabin; do
    for json in $(ls "$OUT"/$scene-*.json | sort -V); do
        python3 -c 'import json, sys; d = json.load(open(sys.argv[1])); s = d["stats"]
print(sys.argv[1], "seconds %.2f points %d rays_traced %d" % (s["seconds"] + d["bvh_build_seconds"], s["points"], s["rays_traced"]))' "$json"
    done
    $SCORE "$DATA" "$CACHE" $scene score $(ls "$OUT"/$scene-*.prtb | sort -V)
done | tee "$OUT/scores.txt"
