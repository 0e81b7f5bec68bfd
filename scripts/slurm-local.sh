#!/usr/bin/env bash
# Starts a one-node Slurm cluster on this machine (slurm-wlm and munge from
# Debian; loopback only; run as root) and runs a small sweep through sbatch:
# `edrnr sweep SPEC --slurm-script` writes a job array of shards and a merge
# step, submit.sh queues them, and the merged table is compared with the same
# sweep run in one process. The daemons are stopped at the end (--keep leaves
# them running; SLURM_CONF then names the config for sinfo, squeue, sbatch).
#
# Usage: scripts/slurm-local.sh [--keep] [--edrnr PATH] [--work DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
keep=0
edrnr="$root/build/edrnr"
work=$(mktemp -d /tmp/edrnr-slurm.XXXXXX)
while [ $# -gt 0 ]; do
  case "$1" in
    --keep) keep=1 ;;
    --edrnr) edrnr=$2; shift ;;
    --work) work=$2; shift ;;
    *) echo "slurm-local: unknown argument '$1' (usage: $0 [--keep] [--edrnr PATH] [--work DIR])" >&2; exit 2 ;;
  esac
  shift
done
[ "$(id -u)" -eq 0 ] || { echo "slurm-local: run as root (it starts munged, slurmctld and slurmd)" >&2; exit 1; }
[ -x "$edrnr" ] || { echo "slurm-local: no edrnr at '$edrnr' (build it, or give --edrnr PATH)" >&2; exit 1; }
mkdir -p "$work"

echo "== packages"
missing=()
for p in slurm-wlm munge; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >"$work/apt.log"
fi
echo "slurm-wlm $(dpkg-query -W -f="\${Version}" slurm-wlm), munge $(dpkg-query -W -f="\${Version}" munge)"

echo "== munge"
if [ ! -s /etc/munge/munge.key ]; then
  mungekey --create --keyfile=/etc/munge/munge.key 2>/dev/null || dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
mkdir -p /run/munge && chown munge:munge /run/munge
started_munge=0
if ! munge -n </dev/null >/dev/null 2>&1; then
  runuser -u munge -- /usr/sbin/munged
  started_munge=1
  sleep 1
fi
munge -n | unmunge >/dev/null && echo "munge: credentials work"

echo "== slurm (config $work/slurm.conf, loopback only)"
cpus=$(nproc)
mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)
mkdir -p "$work/spool/ctld" "$work/spool/d"
cat >"$work/slurm.conf" <<CONF
ClusterName=edrnr-local
SlurmctldHost=localhost(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
SlurmctldPort=6817
SlurmdPort=6818
StateSaveLocation=$work/spool/ctld
SlurmdSpoolDir=$work/spool/d
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=local Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$work/slurm.conf"
stop() {
  if [ "$keep" -eq 0 ]; then
    scontrol shutdown >/dev/null 2>&1 || true
    sleep 1
    for f in "$work/slurmd.pid" "$work/slurmctld.pid"; do
      [ -s "$f" ] && kill "$(cat "$f")" 2>/dev/null || true
    done
    if [ "$started_munge" -eq 1 ] && [ -s /run/munge/munged.pid ]; then
      kill "$(cat /run/munge/munged.pid)" 2>/dev/null || true
    fi
  else
    echo "slurm-local: the cluster keeps running: export SLURM_CONF=$SLURM_CONF"
  fi
}
trap stop EXIT
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF" -N localhost
for _ in $(seq 1 30); do
  state=$(sinfo -h -N -o '%T' 2>/dev/null | head -1 || true)
  [ "$state" = "idle" ] && break
  sleep 1
done
sinfo -N
[ "$state" = "idle" ] || { echo "slurm-local: the node did not come up (see $work/slurmd.log, $work/slurmctld.log)" >&2; exit 1; }

echo "== a small sweep through sbatch"
cat >"$work/spec.yaml" <<SPEC
base: edr_nr_40nm
vary:
  rp_rob.entries: [8, 16]
  simulator.clock_MHz: [100, 200, 380]
models:
  - {procedural: sphere, res: 64, channels: 8}
views:
  width: 32
  orbit: [30]
SPEC
"$edrnr" sweep "$work/spec.yaml" --out "$work/slurm-out" --slurm-script --shards 3
read -r array merge < <("$work/slurm-out/slurm/submit.sh")
echo "submitted: job array $array, merge job $merge"
for _ in $(seq 1 300); do
  [ -z "$(squeue -h -j "$array,$merge" 2>/dev/null)" ] && break
  sleep 1
done
sacct_state=$(scontrol show job "$merge" 2>/dev/null | grep -o 'JobState=[A-Z]*' || true)
echo "merge job: ${sacct_state:-finished}"
cat "$work/slurm-out/slurm/merge.log" || true

echo "== the same sweep in one process"
"$edrnr" sweep "$work/spec.yaml" --out "$work/local-out" --workers 1 --no-plot --quiet >/dev/null
if cmp -s "$work/slurm-out/results.csv" "$work/local-out/results.csv"; then
  echo "slurm-local: OK: the table from sbatch ($(($(wc -l <"$work/slurm-out/results.csv") - 1)) rows) equals the one-process table"
else
  echo "slurm-local: FAILED: the tables differ ($work/slurm-out/results.csv, $work/local-out/results.csv)" >&2
  exit 1
fi
