# Sourced by submit.sh and submit-sun.sh: the binary, the shared folder, and
# the sbatch calls for one round (an array) and its merge.
#
# Environment (both scripts):
#   WORK         folder every node sees, for parts, layers, hit records and
#                logs (default: OUT without .prtb, plus .shards)
#   PRTBAKE      the binary as the nodes see it (default: prtbake on PATH,
#                else target/release/prtbake; made absolute)
#   CPUS         cores per job: --cpus-per-task and prtbake --threads (default 1;
#                the bytes do not depend on it)
#   SBATCH_ARGS  more sbatch options for every job (partition, account,
#                --time, --mem), split on spaces
#   AFTER        a job id the first round waits for (afterok), e.g. the
#                transfer's last merge before the sun masks
here=$(cd "$(dirname "$0")" && pwd)
. "$here/../shard-args.sh"
command -v sbatch >/dev/null || { echo "$0: sbatch not found (is Slurm installed?)" >&2 && exit 2; }
prtbake=$(realpath -m "${PRTBAKE:-$(command -v prtbake || echo target/release/prtbake)}")
[ -x "$prtbake" ] || { echo "$0: no prtbake binary at $prtbake (set PRTBAKE)" >&2 && exit 2; }
cpus=${CPUS:-1}
read -r -a sbatch_args <<<"${SBATCH_ARGS:-}"
dependency=${AFTER:+--dependency=afterok:$AFTER}

# work_dir OUT: the shared folder for OUT's parts, absolute, with its logs folder.
work_dir() {
    local work
    work=$(realpath -m "${WORK:-${1%.prtb}.shards}")
    mkdir -p "$work/logs"
    echo "$work"
}

# submit_array NAME N COMMAND…: N array tasks of COMMAND ({K} = the index)
# after $dependency; prints the array's job id.
submit_array() {
    local name=$1 n=$2
    shift 2
    sbatch --parsable --job-name="prtbake-$name" --array="0-$((n - 1))" ${dependency:+"$dependency"} \
        --cpus-per-task="$cpus" --output="$work/logs/$name-%a.out" ${sbatch_args[@]+"${sbatch_args[@]}"} \
        "$here/task.sbatch" "$prtbake" "$@" --threads "$cpus" | cut -d';' -f1
}

# submit_merge NAME ARRAY_ID COMMAND…: one job after every task of ARRAY_ID
# succeeded; prints its job id.
submit_merge() {
    local name=$1 after=$2
    shift 2
    sbatch --parsable --job-name="prtbake-$name" --dependency="afterok:$after" \
        --cpus-per-task="$cpus" --output="$work/logs/$name.out" ${sbatch_args[@]+"${sbatch_args[@]}"} \
        "$here/task.sbatch" "$prtbake" "$@" --threads "$cpus" | cut -d';' -f1
}
