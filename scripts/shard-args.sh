# Sourced by the sharded-bake launchers (shards-local.sh, slurm/submit.sh,
# slurm/submit-sun.sh, kubernetes/manifests.sh): the plan of a sharded bake,
# read by prtbake itself from the launcher's operands and arguments, so every
# number means what it means to prtbake (`--bounces 010` is 10, `N=08` is 8)
# and a bad argument stops the launcher before any job.

# read_plan PRTBAKE KIND INPUT OUT N [ARGS…]: runs
# `PRTBAKE KIND INPUT -o OUT ARGS… --plan-shards N` (KIND bake or sun) and
# sets shards, bounces (0 for sun), pilot (1 when the bake allocates
# adaptively: a pilot stage before round 0) and threads_given; exits 2 with
# prtbake's message when it refuses them.
read_plan() {
    local planner=$1 kind=$2 input=$3 plan_out=$4 plan_n=$5 text key value
    shift 5
    text=$("$planner" "$kind" "$input" -o "$plan_out" "$@" --plan-shards "$plan_n") || {
        echo "$0: prtbake refused the $kind arguments (above)" >&2
        exit 2
    }
    shards= bounces=0 pilot=0 threads_given=0
    while IFS='=' read -r key value; do
        case $key in
            shards) shards=$value ;;
            bounces) bounces=$value ;;
            pilot) pilot=$value ;;
            threads_given) threads_given=$value ;;
        esac
    done <<<"$text"
    case $shards in '' | *[!0-9]*) echo "$0: $planner printed no plan (is it prtbake?)" >&2 && exit 2 ;; esac
}

# The prtbake on this machine that reads the plan where the jobs run another
# (Kubernetes pods): PLANNER, else prtbake on PATH, else this checkout's
# target/release/prtbake.
planner_binary() {
    local here
    here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
    echo "${PLANNER:-$(command -v prtbake || echo "$here/target/release/prtbake")}"
}
