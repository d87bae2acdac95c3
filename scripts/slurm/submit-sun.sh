#!/usr/bin/env bash
# Sun masks submitted to Slurm (docs/scale.md "On Slurm"): one job array of N
# sun shards, then one merge job after every shard succeeded
# (--dependency=afterok); byte-identical to `prtbake sun INPUT -o OUT.prtb
# [sun args…]` in one process.
#
#   scripts/slurm/submit-sun.sh MESH_OR_BUNDLE OUT.prtb N [sun args…]
#
# INPUT may be the bundle a transfer bake is still writing: pass that bake's
# last merge as AFTER, e.g.
#   AFTER=$(scripts/slurm/submit.sh car.glb car.prtb 8 --bounces 3) \
#       scripts/slurm/submit-sun.sh car.prtb car-sun.prtb 8
# Prints the merge's job id on stdout. Environment: see submit-lib.sh.
set -euo pipefail
[ $# -ge 3 ] || { echo "usage: $0 MESH_OR_BUNDLE OUT.prtb N [sun args…]" >&2 && exit 2; }
input=$(realpath -m "$1") out=$(realpath -m "$2") n=$3
shift 3
. "$(dirname "$0")/submit-lib.sh"
read_plan "$prtbake" sun "$input" "$out" "$n" "$@"
n=$shards
[ "$threads_given" -eq 0 ] || { echo "$0: give CPUS=T, not --threads (each job's threads are its cores)" >&2 && exit 2; }
[ -f "$input" ] || [ -n "${AFTER:-}" ] || { echo "$0: no input at $input (or set AFTER to the job that writes it)" >&2 && exit 2; }
work=$(work_dir "$out")
mkdir -p "$work/sun"
parts=()
for ((k = 0; k < n; k++)); do parts+=("$work/sun/part-$k.prtp"); done
array=$(submit_array sun "$n" sun "$input" --shard "{K}/$n" -o "$work/sun/part-{K}.prtp" --quiet "$@")
merge=$(submit_merge merge-sun "$array" merge "${parts[@]}" -o "$out")
echo "sun masks: shards job $array (N = $n), merge job $merge -> $out" >&2
echo "$merge"
