#!/usr/bin/env python3
"""Checks the manifests of scripts/kubernetes/manifests.sh without a cluster.

    scripts/kubernetes/check.py DIR [--commands]

Parses every DIR/NN-*.yaml (PyYAML) and checks what the bake relies on: one
batch/v1 Job per file, rounds as Indexed Jobs whose N pods run --shard
$(JOB_COMPLETION_INDEX)/N with the same N as completions, merges as plain
Jobs listing parts 0 … N−1, restartPolicy Never, the claim mounted in every
pod. Exit 1 naming the file and the problem. With --commands, prints each
pod's command in apply order as JSON lines (the index substituted), for a
test to run them on one machine.
"""
import json
import pathlib
import re
import sys

import yaml


def fail(path, problem):
    sys.exit(f"{path}: {problem}")


def pod_commands(path, job):
    spec = job.get("spec") or fail(path, "no spec")
    pod = spec["template"]["spec"]
    if pod.get("restartPolicy") != "Never":
        fail(path, "restartPolicy must be Never (a Job retries failed pods itself)")
    [container] = pod["containers"]
    claims = {v["name"] for v in pod.get("volumes", []) if v.get("persistentVolumeClaim", {}).get("claimName")}
    if not claims or {m["name"] for m in container.get("volumeMounts", [])} != claims:
        fail(path, "the pod must mount its PersistentVolumeClaim")
    command = container["command"]
    if not all(isinstance(a, str) for a in command):
        fail(path, "every command argument must be a string")
    indexed = spec.get("completionMode") == "Indexed"
    shard = [a for a in command if re.fullmatch(r"\$\(JOB_COMPLETION_INDEX\)/\d+", a)]
    if indexed:
        n = spec.get("completions")
        if shard != [f"$(JOB_COMPLETION_INDEX)/{n}"]:
            fail(path, f"an Indexed Job of {n} completions must run --shard $(JOB_COMPLETION_INDEX)/{n}, not {shard}")
        if not 1 <= spec.get("parallelism", 1) <= n:
            fail(path, "parallelism must be 1 … completions")
        return [[a.replace("$(JOB_COMPLETION_INDEX)", str(k)) for a in command] for k in range(n)]
    if shard or "merge" not in command:
        fail(path, "a plain Job must be a merge")
    return [command]


def main():
    if len(sys.argv) not in (2, 3) or sys.argv[2:] not in ([], ["--commands"]):
        sys.exit(__doc__)
    files = sorted(pathlib.Path(sys.argv[1]).glob("[0-9][0-9]-*.yaml"))
    if not files:
        fail(sys.argv[1], "no manifests")
    names, commands, shards = set(), [], None
    for path in files:
        docs = list(yaml.safe_load_all(path.read_text()))
        if len(docs) != 1 or docs[0].get("apiVersion") != "batch/v1" or docs[0].get("kind") != "Job":
            fail(path, "must hold one batch/v1 Job")
        name = docs[0]["metadata"]["name"]
        if name in names or not re.fullmatch(r"[a-z0-9]([-a-z0-9]{0,61}[a-z0-9])?", name):
            fail(path, f"job name {name!r} repeated or not a DNS label")
        names.add(name)
        pods = pod_commands(path, docs[0])
        if docs[0]["spec"].get("completionMode") == "Indexed":
            shards = len(pods)
        elif shards is None or sum(a.endswith(".prtp") for a in pods[0]) != shards:
            fail(path, f"a merge must follow a round and list its {shards} parts")
        commands += pods
    if "--commands" in sys.argv:
        for command in commands:
            print(json.dumps(command))
    else:
        print(f"{len(files)} manifests, {len(commands)} pods: ok", file=sys.stderr)


if __name__ == "__main__":
    main()
