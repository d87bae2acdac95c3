#!/usr/bin/env bash
# Applies a sharded bake's manifests (scripts/kubernetes/manifests.sh) in
# name order, each Job after the previous one completed (a round's Indexed
# Job, then its merge, then the next round). Stops at a failed Job, naming
# it: delete it (kubectl delete job NAME) and run this again; Jobs that
# already completed are kept, and shards and merges are idempotent.
#
#   scripts/kubernetes/apply.sh DIR        (POLL seconds between checks, default 10)
set -euo pipefail
[ $# -eq 1 ] && [ -d "$1" ] || { echo "usage: $0 DIR (from manifests.sh)" >&2 && exit 2; }
poll=${POLL:-10}
for file in "$1"/[0-9][0-9]-*.yaml; do
    job=$(sed -n 's/^  name: "\(.*\)"$/\1/p' "$file" | head -n 1)
    kubectl apply -f "$file"
    while :; do
        state=$(kubectl get job "$job" -o 'jsonpath={.status.conditions[?(@.status=="True")].type}')
        case " $state " in
            *" Complete "*) echo "$job: complete" >&2 && break ;;
            *" Failed "*) echo "$0: job $job failed (kubectl describe job $job; kubectl logs job/$job)" >&2 && exit 1 ;;
        esac
        sleep "$poll"
    done
done
