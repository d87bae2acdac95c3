#!/usr/bin/env bash
# Kubernetes manifests for a sharded bake (docs/scale.md "On Kubernetes"): per
# round (round b = bounce b, 0 … B) one Indexed Job of N pods, pod K running
# shard $JOB_COMPLETION_INDEX/N, then one merge Job; every pod mounts one
# PersistentVolumeClaim holding the mesh, the parts, layers and hit records,
# and the bundle. Apply the files in name order, each after the previous
# Job completed: scripts/kubernetes/apply.sh DIR. The bundle is
# byte-identical to `prtbake bake MESH -o OUT.prtb [bake args…]` in one process.
#
#   scripts/kubernetes/manifests.sh MESH OUT.prtb N [bake args…]
#
# MESH and OUT are paths inside the volume as the pods see it (under MOUNT).
# Writes DIR/NN-<job>.yaml and prints DIR. Environment:
#   DIR       where the manifests go (default: k8s-NAME)
#   NAME      the Jobs' name prefix (default: OUT's file name, lower case, [a-z0-9-])
#   IMAGE     a container image with prtbake and sh (default: prtbake:latest)
#   PRTBAKE   the binary in the image (default: prtbake)
#   PLANNER   a prtbake on this machine that reads the bake's arguments
#             (default: prtbake on PATH, else target/release/prtbake)
#   PVC       the PersistentVolumeClaim (ReadWriteMany when pods land on
#             several nodes; default: prtbake-work)
#   MOUNT     where the pods mount it (default: /data)
#   WORK      folder for parts, layers and hit records (default: OUT without .prtb, plus .shards)
#   CPUS      cores per pod: its cpu request and prtbake --threads (default 1)
#   MEMORY    memory request per pod (default 2Gi)
#   PARALLELISM  pods of a round at once (default N)
#   RETRIES   failed pods tolerated per shard: backoffLimit = RETRIES × N (default 2)
set -euo pipefail
[ $# -ge 3 ] || { echo "usage: $0 MESH OUT.prtb N [bake args…]" >&2 && exit 2; }
mesh=$1 out=$2 n=$3
shift 3
bake_args=("$@")
. "$(dirname "$0")/../shard-args.sh"
read_plan "$(planner_binary)" bake "$mesh" "$out" "$n" "$@"
n=$shards
[ "$threads_given" -eq 0 ] || { echo "$0: give CPUS=T, not --threads (each pod's threads are its cores)" >&2 && exit 2; }
base=$(basename "${out%.prtb}" | tr 'A-Z_.' 'a-z--' | tr -cd 'a-z0-9-')
name=${NAME:-${base:-bake}}
# Job names are DNS labels: at most 63 characters, the longest being NAME-merge-pilot or NAME-merge-rB.
longest="$name-merge-r$bounces"
if [ "$pilot" -eq 1 ] && [ ${#longest} -lt $((${#name} + 12)) ]; then longest="$name-merge-pilot"; fi
if [ ${#longest} -gt 63 ]; then
    echo "$0: job name '$longest' is ${#longest} characters, over Kubernetes' 63: set NAME to a shorter prefix" >&2
    exit 2
fi
dir=${DIR:-k8s-$name}
image=${IMAGE:-prtbake:latest} prtbake=${PRTBAKE:-prtbake} pvc=${PVC:-prtbake-work} mount=${MOUNT:-/data}
work=${WORK:-${out%.prtb}.shards}
cpus=${CPUS:-1} memory=${MEMORY:-2Gi} parallelism=${PARALLELISM:-$n} retries=${RETRIES:-2}
mkdir -p "$dir"
rm -f "$dir"/[0-9][0-9]-*.yaml

# A JSON string (valid YAML): every value the manifests quote.
q() {
    local s=${1//\\/\\\\}
    s=${s//\"/\\\"}
    printf '"%s"' "$s"
}
# A JSON list of the arguments.
list() {
    local sep= arg
    printf '['
    for arg in "$@"; do printf '%s%s' "$sep" "$(q "$arg")" && sep=', '; done
    printf ']'
}

# job FILE JOB COMMENT COMPLETIONS COMMAND…: one Job whose pod makes the
# folders of its outputs and runs COMMAND; COMPLETIONS > 0 makes it an
# Indexed Job of that many pods.
job() {
    local file=$1 job=$2 comment=$3 completions=$4
    shift 4
    {
        echo "# $comment"
        echo "apiVersion: batch/v1"
        echo "kind: Job"
        echo "metadata:"
        echo "  name: $(q "$job")"
        echo "  labels: {app.kubernetes.io/name: prtbake, prtbake/bake: $(q "$name")}"
        echo "spec:"
        if [ "$completions" -gt 0 ]; then
            echo "  completionMode: Indexed"
            echo "  completions: $completions"
            echo "  parallelism: $parallelism"
            echo "  backoffLimit: $((retries * completions))"
        else
            echo "  backoffLimit: $retries"
        fi
        echo "  template:"
        echo "    metadata:"
        echo "      labels: {app.kubernetes.io/name: prtbake, prtbake/bake: $(q "$name")}"
        echo "    spec:"
        echo "      restartPolicy: Never"
        echo "      containers:"
        echo "        - name: prtbake"
        echo "          image: $(q "$image")"
        # sh makes the output folders, then execs prtbake; Kubernetes expands
        # \$(JOB_COMPLETION_INDEX) in the arguments to the pod's index.
        echo "          command: $(list sh -c "mkdir -p $folders && exec \"\$@\"" "$work" "$@")"
        echo "          resources: {requests: {cpu: $(q "$cpus"), memory: $(q "$memory")}}"
        echo "          volumeMounts: [{name: work, mountPath: $(q "$mount")}]"
        echo "      volumes: [{name: work, persistentVolumeClaim: {claimName: $(q "$pvc")}}]"
    } >"$dir/$file"
}

# The folders every pod may write into, relative to WORK ($0 in the pod's sh).
folders='"$0/hits"'
for ((round = 0; round <= bounces; round++)); do folders+=" \"\$0/r$round\""; done

step=0
pilot_args=()
if [ "$pilot" -eq 1 ]; then
    # Adaptive allocation's pilot stage: an Indexed Job at the base points and
    # its merge into the pilot every round reads.
    folders+=' "$0/pilot"'
    index='$(JOB_COMPLETION_INDEX)'
    job "00-pilot.yaml" "$name-pilot" "pilot of adaptive allocation: $n shards, pod K runs --shard K/$n" "$n" \
        "$prtbake" bake "$mesh" --shard "$index/$n" --round pilot -o "$work/pilot/part-$index.prtp" --threads "$cpus" --quiet "${bake_args[@]}"
    parts=()
    for ((k = 0; k < n; k++)); do parts+=("$work/pilot/part-$k.prtp"); done
    job "01-merge-pilot.yaml" "$name-merge-pilot" "merge of the pilot: after every pod of $name-pilot completed" 0 \
        "$prtbake" merge "${parts[@]}" -o "$work/pilot.prta" --threads "$cpus"
    pilot_args=(--pilot "$work/pilot.prta")
    step=2
fi
for ((round = 0; round <= bounces; round++)); do
    layer_args=()
    [ "$round" -eq 0 ] || layer_args=(--layer "$work/r$((round - 1)).prtl")
    index='$(JOB_COMPLETION_INDEX)'
    job "$(printf %02d $step)-r$round.yaml" "$name-r$round" "round $round of $bounces: $n shards, pod K runs --shard K/$n" "$n" \
        "$prtbake" bake "$mesh" --shard "$index/$n" --round "$round" ${layer_args[@]+"${layer_args[@]}"} \
        ${pilot_args[@]+"${pilot_args[@]}"} --shard-dir "$work/hits" -o "$work/r$round/part-$index.prtp" --threads "$cpus" --quiet "${bake_args[@]}"
    parts=()
    for ((k = 0; k < n; k++)); do parts+=("$work/r$round/part-$k.prtp"); done
    target=$out
    [ "$round" -eq "$bounces" ] || target="$work/r$round.prtl"
    job "$(printf %02d $((step + 1)))-merge-r$round.yaml" "$name-merge-r$round" "merge of round $round: after every pod of $name-r$round completed" 0 \
        "$prtbake" merge "${parts[@]}" ${layer_args[@]+"${layer_args[@]}"} -o "$target" --threads "$cpus"
    step=$((step + 2))
done
echo "$dir"
