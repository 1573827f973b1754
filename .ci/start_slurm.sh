#!/usr/bin/env bash
# A single-node Slurm cluster on this machine (Debian's slurm-wlm + munge), for the tests marked
# `slurm` (tests/test_slurm.py): slurmctld and slurmd on localhost, one partition holding every
# core. Needs root and apt; idempotent (a cluster already answering is left as it is).
# Exits non-zero when it cannot start one; .ci/run then carries on and those tests skip.
set -euo pipefail

log() { echo "start_slurm: $*"; }

if sinfo -h -o %t 2>/dev/null | grep -qE '^(idle|mix|alloc)'; then
    log "a Slurm cluster already answers: $(sinfo -h -o '%P %D %t %C' | head -1)"
    exit 0
fi
if [[ $(id -u) -ne 0 ]]; then
    log "not root: cannot install or start Slurm"; exit 1
fi
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    command -v apt-get >/dev/null || { log "no apt-get: cannot install slurm-wlm"; exit 1; }
    log "installing slurm-wlm and munge"
    export DEBIAN_FRONTEND=noninteractive
    timeout 600 apt-get update -qq
    timeout 900 apt-get install -y -qq slurm-wlm munge >/dev/null
fi

# munge: the key the package made (or a new one), the daemon as its own user.
[[ -s /etc/munge/munge.key ]] || mungekey --create --keyfile=/etc/munge/munge.key
chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
mkdir -p /run/munge /var/log/munge /var/lib/munge
chown munge:munge /run/munge /var/log/munge /var/lib/munge
if ! pgrep -x munged >/dev/null; then
    runuser -u munge -- munged
fi
munge -n | unmunge >/dev/null

# slurm.conf from what slurmd finds on this machine (its own NodeName/CPUs/RealMemory line).
node_line=$(slurmd -C | head -1)
node=$(sed -E 's/^NodeName=([^ ]+).*/\1/' <<<"$node_line")
mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
cat >/etc/slurm/slurm.conf <<EOF
# Written by .ci/start_slurm.sh: a one-node test cluster.
ClusterName=ci
SlurmctldHost=$node(127.0.0.1)
SlurmUser=root
AuthType=auth/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
ReturnToService=2
# scancel sends SIGTERM, then SIGKILL after KillWait: submitit's job wrapper ignores SIGTERM,
# so a short wait makes a cancelled job end within seconds (tests/test_slurm.py cancels one).
KillWait=1
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
$node_line NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=debug Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF

pgrep -x slurmctld >/dev/null || slurmctld
pgrep -x slurmd >/dev/null || slurmd
for _ in $(seq 60); do
    state=$(sinfo -h -N -o %t 2>/dev/null | head -1 || true)
    case "$state" in
        idle|mix|alloc) log "node $node is $state: $(sinfo -h -o '%P %D %C (cores A/I/O/T)')"
                        exit 0 ;;
        down*|drain*) scontrol update nodename="$node" state=resume 2>/dev/null || true ;;
    esac
    sleep 1
done
log "the node did not come up (last state: ${state:-none}); see /var/log/slurm/"
exit 1
