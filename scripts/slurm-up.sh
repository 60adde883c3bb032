#!/usr/bin/env bash
# Starts a one-node Slurm cluster on this machine for the farm tests (tests/farm_slurm.rs)
# and benches/farm.sh: Debian's slurm-wlm and munge, installed when missing, daemons
# started straight from the shell (no systemd), as root. Idempotent and quiet: a second
# run finds the cluster up and returns at once. Exits non-zero with one line when the
# cluster cannot be started; prints nothing on success.
#
#   scripts/slurm-up.sh          start (or check) the cluster
#   scripts/slurm-up.sh --down   stop its daemons
#
# The cluster is ours alone: ClusterName `subfield`, its own state, log and spool
# folders under /var/lib/subfield-slurm (slurmctld refuses a StateSaveLocation that
# holds another cluster's state), the short host name as the only node with all CPUs,
# one default partition `debug`.
set -euo pipefail

ROOT=/var/lib/subfield-slurm
CONF=/etc/slurm/slurm.conf
say() { echo "slurm-up: $*" >&2; }

if [ "${1:-}" = "--down" ]; then
    pkill -x slurmd 2>/dev/null || true
    pkill -x slurmctld 2>/dev/null || true
    exit 0
fi

if [ "$(id -u)" -ne 0 ]; then
    say "must run as root (the daemons run as root without systemd)"
    exit 1
fi

if ! command -v slurmctld >/dev/null 2>&1 || ! command -v munged >/dev/null 2>&1; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >/dev/null 2>&1 || true
    if ! apt-get install -y -qq slurm-wlm munge >/dev/null 2>&1; then
        say "cannot install slurm-wlm and munge with apt-get"
        exit 1
    fi
fi

host=$(hostname -s)
cpus=$(nproc)

# munge: a 1 KiB key owned by munge, the daemon running as munge.
if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
chown munge:munge /etc/munge/munge.key
chmod 400 /etc/munge/munge.key
mkdir -p /run/munge /var/log/munge /var/lib/munge
chown munge:munge /run/munge /var/log/munge /var/lib/munge
chmod 755 /run/munge
if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    pkill -x munged 2>/dev/null || true
    rm -f /run/munge/munge.socket.2 /run/munge/munged.pid
    if command -v runuser >/dev/null 2>&1; then
        runuser -u munge -- /usr/sbin/munged --force
    else
        su -s /bin/sh munge -c "/usr/sbin/munged --force"
    fi
    for _ in $(seq 1 50); do
        munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break
        sleep 0.1
    done
    if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
        say "munged does not answer (munge -n | unmunge fails)"
        exit 1
    fi
fi

mkdir -p "$ROOT/state" "$ROOT/spool" "$ROOT/log" /etc/slurm
want=$(cat <<CONF
# Written by subfield's scripts/slurm-up.sh: a one-node cluster for tests.
ClusterName=subfield
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$ROOT/state
SlurmdSpoolDir=$ROOT/spool
SlurmctldPidFile=$ROOT/slurmctld.pid
SlurmdPidFile=$ROOT/slurmd.pid
SlurmctldLogFile=$ROOT/log/slurmctld.log
SlurmdLogFile=$ROOT/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
KillWait=5
MaxArraySize=100001
NodeName=$host CPUs=$cpus State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
)
if [ ! -f "$CONF" ] || [ "$(cat "$CONF")" != "$want" ]; then
    printf '%s\n' "$want" > "$CONF"
    # A new configuration: restart the daemons so they read it.
    pkill -x slurmd 2>/dev/null || true
    pkill -x slurmctld 2>/dev/null || true
    sleep 1
fi

if ! pgrep -x slurmctld >/dev/null 2>&1; then
    /usr/sbin/slurmctld
fi
if ! pgrep -x slurmd >/dev/null 2>&1; then
    /usr/sbin/slurmd
fi

# Up when the node is idle (or allocated/mixed: jobs of a run before this one).
for _ in $(seq 1 100); do
    state=$(sinfo -h -n "$host" -o %T 2>/dev/null | head -n1 || true)
    case "$state" in
        idle*|mixed*|allocated*|completing*) exit 0 ;;
        down*|drain*)
            scontrol update NodeName="$host" State=RESUME >/dev/null 2>&1 || true ;;
    esac
    sleep 0.2
done
say "the node $host did not come up (sinfo says '${state:-nothing}'); see $ROOT/log/"
exit 1
