#!/usr/bin/env bash
# A sharded bake on this machine, run the way a scheduler runs it
# (docs/scale.md "Sharded bakes"): each round's N shards as separate
# processes, in parallel, then the merge (with adaptive allocation, bake's
# default, a pilot stage first); the bundle is byte-identical to
# `prtbake bake MESH -o OUT [bake args…]` in one process.
#
#   scripts/shards-local.sh MESH OUT.prtb N [bake args…]
#
# Environment:
#   PRTBAKE  the binary (default: prtbake on PATH, else target/release/prtbake)
#   JOBS     shards run at once (default: the number of cores)
#   RUNNER   parallel or xargs (default: GNU parallel when installed, else xargs -P)
#   WORK     folder for parts, layers and hit records (default: OUT without
#            .prtb, plus .shards; kept, so a failed round's commands can be re-run)
# Each shard runs with --threads 1 unless the bake args give --threads.
set -euo pipefail

usage() {
    echo "usage: $0 MESH OUT.prtb N [bake args…]" >&2
    exit 2
}
[ $# -ge 3 ] || usage
mesh=$1 out=$2 n=$3
shift 3
bake_args=("$@")
. "$(dirname "$0")/shard-args.sh"
prtbake=${PRTBAKE:-$(command -v prtbake || echo target/release/prtbake)}
read_plan "$prtbake" bake "$mesh" "$out" "$n" "$@"
n=$shards
[ "$threads_given" -eq 1 ] || bake_args+=(--threads 1)

work=${WORK:-${out%.prtb}.shards}
jobs=${JOBS:-$(nproc 2>/dev/null || echo 2)}
runner=${RUNNER:-$(command -v parallel >/dev/null && echo parallel || echo xargs)}
mkdir -p "$work/hits"

# Runs the commands of $1 (one per line), $jobs at a time; fails if any fails.
run_all() {
    case $runner in
        parallel) parallel --will-cite --halt now,fail=1 -j "$jobs" <"$1" ;;
        xargs) tr '\n' '\0' <"$1" | xargs -0 -P "$jobs" -n 1 bash -c ;;
        *) echo "$0: RUNNER must be parallel or xargs" >&2 && exit 2 ;;
    esac
}

pilot_args=()
if [ "$pilot" -eq 1 ]; then
    # Adaptive allocation's pilot: bounce 0 at the base points, merged into
    # the pilot that decides, the same in every shard, where extra points go.
    mkdir -p "$work/pilot"
    parts=()
    for ((k = 0; k < n; k++)); do
        part="$work/pilot/part-$k.prtp"
        parts+=("$part")
        printf '%q ' "$prtbake" bake "$mesh" --shard "$k/$n" --round pilot -o "$part" --quiet "${bake_args[@]}"
        echo
    done >"$work/pilot/commands.sh"
    echo "pilot: $n shards ($runner, $jobs at once)" >&2
    run_all "$work/pilot/commands.sh"
    "$prtbake" merge "${parts[@]}" -o "$work/pilot.prta"
    pilot_args=(--pilot "$work/pilot.prta")
fi

for ((round = 0; round <= bounces; round++)); do
    layer_args=()
    if [ "$round" -gt 0 ]; then
        layer_args=(--layer "$work/r$((round - 1)).prtl")
    fi
    mkdir -p "$work/r$round"
    # Shard K's command, exactly as a scheduler's array task K runs it.
    parts=()
    for ((k = 0; k < n; k++)); do
        part="$work/r$round/part-$k.prtp"
        parts+=("$part")
        printf '%q ' "$prtbake" bake "$mesh" --shard "$k/$n" --round "$round" ${layer_args[@]+"${layer_args[@]}"} \
            ${pilot_args[@]+"${pilot_args[@]}"} --shard-dir "$work/hits" -o "$part" --quiet "${bake_args[@]}"
        echo
    done >"$work/r$round/commands.sh"
    echo "round $round of $bounces: $n shards ($runner, $jobs at once)" >&2
    run_all "$work/r$round/commands.sh"
    if [ "$round" -eq "$bounces" ]; then
        target=$out
    else
        target="$work/r$round.prtl"
    fi
    "$prtbake" merge "${parts[@]}" ${layer_args[@]+"${layer_args[@]}"} -o "$target"
done
# A merge that exits 0 wrote the bundle; say so only when it is there.
[ -s "$out" ] || { echo "$0: the last merge left no $out" >&2 && exit 1; }
echo "wrote $out" >&2
