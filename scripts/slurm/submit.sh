#!/usr/bin/env bash
# A sharded bake submitted to Slurm (docs/scale.md "On Slurm"): per round
# (round b = bounce b, 0 … B) one job array of N shards, then one merge job;
# each array waits for the previous merge and each merge for its whole array
# (--dependency=afterok), so the bundle is byte-identical to
# `prtbake bake MESH -o OUT.prtb [bake args…]` in one process.
#
#   scripts/slurm/submit.sh MESH OUT.prtb N [bake args…]
#
# Prints the last merge's job id on stdout (wait for it, or pass it as AFTER
# to submit-sun.sh); the job ids per round on stderr. Environment: see
# submit-lib.sh (WORK, PRTBAKE, CPUS, SBATCH_ARGS, AFTER). Paths are made
# absolute; WORK, MESH and OUT must be on storage every node sees.
set -euo pipefail
[ $# -ge 3 ] || { echo "usage: $0 MESH OUT.prtb N [bake args…]" >&2 && exit 2; }
mesh=$(realpath -m "$1") out=$(realpath -m "$2") n=$3
shift 3
bake_args=("$@")
. "$(dirname "$0")/submit-lib.sh"
read_plan "$prtbake" bake "$mesh" "$out" "$n" "$@"
n=$shards
[ "$threads_given" -eq 0 ] || { echo "$0: give CPUS=T, not --threads (each job's threads are its cores)" >&2 && exit 2; }
[ -f "$mesh" ] || { echo "$0: no mesh at $mesh" >&2 && exit 2; }
work=$(work_dir "$out")
mkdir -p "$work/hits"

pilot_args=()
if [ "$pilot" -eq 1 ]; then
    # Adaptive allocation's pilot stage: an array at the base points, merged
    # into the pilot every round reads.
    mkdir -p "$work/pilot"
    parts=()
    for ((k = 0; k < n; k++)); do parts+=("$work/pilot/part-$k.prtp"); done
    array=$(submit_array pilot "$n" bake "$mesh" --shard "{K}/$n" --round pilot -o "$work/pilot/part-{K}.prtp" --quiet "${bake_args[@]}")
    merge=$(submit_merge merge-pilot "$array" merge "${parts[@]}" -o "$work/pilot.prta")
    echo "pilot: shards job $array (N = $n), merge job $merge -> $work/pilot.prta" >&2
    dependency=--dependency=afterok:$merge
    pilot_args=(--pilot "$work/pilot.prta")
fi

for ((round = 0; round <= bounces; round++)); do
    layer_args=()
    [ "$round" -eq 0 ] || layer_args=(--layer "$work/r$((round - 1)).prtl")
    mkdir -p "$work/r$round"
    parts=()
    for ((k = 0; k < n; k++)); do parts+=("$work/r$round/part-$k.prtp"); done
    target=$out
    [ "$round" -eq "$bounces" ] || target="$work/r$round.prtl"
    array=$(submit_array "r$round" "$n" bake "$mesh" --shard "{K}/$n" --round "$round" ${layer_args[@]+"${layer_args[@]}"} \
        ${pilot_args[@]+"${pilot_args[@]}"} --shard-dir "$work/hits" -o "$work/r$round/part-{K}.prtp" --quiet "${bake_args[@]}")
    merge=$(submit_merge "merge-r$round" "$array" merge "${parts[@]}" ${layer_args[@]+"${layer_args[@]}"} -o "$target")
    echo "round $round of $bounces: shards job $array (N = $n), merge job $merge -> $target" >&2
    dependency=--dependency=afterok:$merge
done
echo "$merge"
