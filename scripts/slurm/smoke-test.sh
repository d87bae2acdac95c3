#!/usr/bin/env bash
# A real Slurm on this machine, end to end (docs/scale.md "On Slurm"): as
# root, installs Debian's slurm-wlm and munge (apt-get), writes a one-node
# slurm.conf for this machine's cores and memory, starts munged, slurmctld
# and slurmd, submits the demo cabin's (cleaned) sharded bake (N shards, 3 bounces)
# through scripts/slurm/submit.sh, waits for its last merge and `cmp`s the
# bundle with a single-process bake. Prints the install, start-up and bake
# times; exit 0 only when the bytes are identical, 77 when the packages
# cannot be installed (skipped).
#
#   sudo scripts/slurm/smoke-test.sh            (from the repository root)
#
# Environment: PRTBAKE (default target/release/prtbake), SMOKE (work folder,
# default /tmp/prtbake-slurm-smoke, wiped first), N (default 4), RAYS
# (default 32), TIMEOUT (seconds to wait for the jobs, default 900). The
# daemons it started are stopped at the end; the packages stay installed.
set -euo pipefail
cd "$(dirname "$0")/../.."
[ "$(id -u)" -eq 0 ] || { echo "$0: run as root (it installs packages and starts daemons)" >&2 && exit 2; }
command -v apt-get >/dev/null || { echo "$0: needs apt-get (Debian or Ubuntu)" >&2 && exit 2; }
prtbake=$(realpath -m "${PRTBAKE:-target/release/prtbake}")
[ -x "$prtbake" ] || { echo "$0: no binary at $prtbake (cargo build --release, or set PRTBAKE)" >&2 && exit 2; }
smoke=${SMOKE:-/tmp/prtbake-slurm-smoke} n=${N:-4} rays=${RAYS:-32} timeout=${TIMEOUT:-900}
clock() { date +%s.%N; }
since() { echo "$1" "$(clock)" | awk '{ printf "%.1f", $2 - $1 }'; }

# 1. Install (skipped when present; the time says which).
t0=$(clock)
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    # Exit 77 (skipped) when the packages cannot be had, e.g. offline.
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null) ||
        { echo "notice: $0: could not install slurm-wlm and munge; skipped" >&2 && exit 77; }
fi
install_s=$(since "$t0")
echo "install: ${install_s} s" >&2

# 2. Configure and start: one node, this machine, as root, no cgroups (so
# it runs in containers without systemd): processes tracked by parent id,
# no task binding, cores as the consumable resource.
t1=$(clock)
rm -rf "$smoke" && mkdir -p "$smoke"/{state,spool,log}
host=$(hostname -s) cpus=$(nproc) mem_mib=$(($(awk '/MemTotal/ { print $2 }' /proc/meminfo) / 1024 - 1024))
export SLURM_CONF=$smoke/slurm.conf
cat >"$SLURM_CONF" <<CONF
ClusterName=prtbake-smoke
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$smoke/state
SlurmdSpoolDir=$smoke/spool
SlurmctldPidFile=$smoke/slurmctld.pid
SlurmdPidFile=$smoke/slurmd.pid
SlurmctldLogFile=$smoke/log/slurmctld.log
SlurmdLogFile=$smoke/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
NodeName=$host CPUs=$cpus RealMemory=$mem_mib State=UNKNOWN
PartitionName=smoke Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
if [ ! -s /etc/munge/munge.key ]; then
    mkdir -p /etc/munge && mungekey --create --keyfile /etc/munge/munge.key
    chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
fi
mkdir -p /run/munge /var/log/munge /var/lib/munge && chown munge:munge /run/munge /var/log/munge /var/lib/munge
started=()
stop() {
    local pid
    for pid in ${started[@]+"${started[@]}"}; do kill "$pid" 2>/dev/null || true; done
    for pid in ${started[@]+"${started[@]}"}; do
        for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    done
}
passed=0
finish() {
    stop
    if [ "$passed" -eq 1 ] && [ -z "${KEEP:-}" ]; then rm -rf "$smoke"; fi
}
trap finish EXIT
pid_of() { local i; for i in $(seq 50); do [ -s "$1" ] && cat "$1" && return; sleep 0.1; done; echo "$0: $2 did not start" >&2 && exit 1; }
if ! munge -n >/dev/null 2>&1; then
    rm -f /run/munge/munged.pid
    runuser -u munge -- /usr/sbin/munged
    started+=("$(pid_of /run/munge/munged.pid munged)")
fi
slurmctld && started+=("$(pid_of "$smoke/slurmctld.pid" slurmctld)")
slurmd && started+=("$(pid_of "$smoke/slurmd.pid" slurmd)")
for i in $(seq 60); do
    case $(sinfo -h -o %T 2>/dev/null) in idle*) break ;; esac
    [ "$i" -lt 60 ] || { echo "$0: the node did not come up; see $smoke/log" >&2 && exit 1; }
    sleep 1
done
startup_s=$(since "$t1")
echo "start-up: ${startup_s} s" >&2
echo "slurm: $(sinfo -h -o '%P %D %c %m %T') (SLURM_CONF=$SLURM_CONF)" >&2

# 3. The demo cabin, baked through Slurm and in one process.
# Cleaned once here: with `bake --clean` every shard of every round would
# clean the 333k-triangle cabin again (docs/scale.md, Limits).
"$prtbake" generate cabin -o "$smoke/cabin-raw.glb"
"$prtbake" clean "$smoke/cabin-raw.glb" -o "$smoke/cabin.glb" >/dev/null
args=(--window glass --rays "$rays" --bounces 3)
t2=$(clock)
last=$(WORK=$smoke/shards PRTBAKE=$prtbake scripts/slurm/submit.sh "$smoke/cabin.glb" "$smoke/slurm.prtb" "$n" "${args[@]}")
while squeue -h -j "$last" 2>/dev/null | grep -q .; do
    [ "$(since "$t2" | cut -d. -f1)" -lt "$timeout" ] || { echo "$0: jobs still queued after ${timeout}s:" >&2 && squeue >&2 && exit 1; }
    sleep 1
done
slurm_s=$(since "$t2")
[ -f "$smoke/slurm.prtb" ] || { echo "$0: no bundle; the jobs' logs:" >&2 && tail -n 5 "$smoke"/shards/logs/*.out >&2 && exit 1; }
t3=$(clock)
"$prtbake" bake "$smoke/cabin.glb" -o "$smoke/single.prtb" --quiet "${args[@]}"
single_s=$(since "$t3")
bytes=$(stat -c %s "$smoke/single.prtb")
if cmp "$smoke/slurm.prtb" "$smoke/single.prtb"; then same=identical; else same=DIFFERENT; fi
echo "install ${install_s} s, slurm start-up ${startup_s} s, bake through slurm (N = $n, 3 bounces, $rays rays, adaptive: a pilot and 4 rounds, 5 arrays + 5 merges) ${slurm_s} s, single process ${single_s} s; bundles $same ($bytes bytes)"
[ "$same" = identical ] && passed=1
[ "$passed" -eq 1 ]
