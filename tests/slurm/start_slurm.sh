#!/usr/bin/env bash
# Start a real single-node SLURM cluster on this machine (Debian 12, as root) for
# tests/test_slurm.py: munged, slurmctld and slurmd, one node `localhost`, one
# default partition. Installs Debian's slurm-wlm and munge with apt-get if missing.
# Idempotent: when the cluster already answers with the node idle, it does nothing.
# Settings: ../shared/notes/slurm-single-node.md (no cgroups, no slurmdbd).
#
# Prints `STATE=started` or `STATE=running` (already up) as its last line.
# Exit codes (tests/test_slurm.py skips on 2-4 and fails on anything else):
#   0 cluster up            2 not root                 3 packages missing and
#   4 a slurm.conf this script did not write exists      apt-get absent or failed
#   1 anything else (a daemon did not start: see /var/log/slurm/*.log)
#
# Environment: SLURM_TEST_PARTITION (default `debug`), SLURM_TEST_APT_TIMEOUT
# (seconds per apt-get call, default 240), SLURM_TEST_START_TIMEOUT (default 60).
set -euo pipefail

PARTITION=${SLURM_TEST_PARTITION:-debug}
APT_TIMEOUT=${SLURM_TEST_APT_TIMEOUT:-240}
START_TIMEOUT=${SLURM_TEST_START_TIMEOUT:-60}
CONF=/etc/slurm/slurm.conf
MARKER="# written by tests/slurm/start_slurm.sh (finger-rehab-workflow test cluster)"
LOGDIR=/var/log/slurm
SPOOL=/var/spool/slurm-test
export PATH="/usr/sbin:/usr/bin:/sbin:/bin:$PATH"

log() { echo "[start_slurm] $*" >&2; }
die() { local code=$1; shift; log "ERROR: $*"; exit "$code"; }

[ "$(id -u)" -eq 0 ] || die 2 "not root (uid $(id -u)): cannot install packages or start slurmctld/slurmd/munged"

# --- packages -----------------------------------------------------------------
have_all() { command -v slurmctld && command -v slurmd && command -v sinfo && command -v munged; } >/dev/null 2>&1
if ! have_all; then
    command -v apt-get >/dev/null 2>&1 || die 3 "slurm-wlm/munge not installed and apt-get is absent"
    t0=$(date +%s)
    log "installing slurm-wlm and munge with apt-get (timeout ${APT_TIMEOUT}s per call)"
    export DEBIAN_FRONTEND=noninteractive
    timeout "$APT_TIMEOUT" apt-get update -qq >/tmp/start_slurm_apt.log 2>&1 \
        || die 3 "apt-get update failed or timed out: $(tail -3 /tmp/start_slurm_apt.log | tr '\n' ' ')"
    timeout "$APT_TIMEOUT" apt-get install -y -qq --no-install-recommends slurm-wlm munge >>/tmp/start_slurm_apt.log 2>&1 \
        || die 3 "apt-get install slurm-wlm munge failed or timed out: $(tail -3 /tmp/start_slurm_apt.log | tr '\n' ' ')"
    have_all || die 3 "slurm-wlm/munge installed but slurmctld/slurmd/sinfo/munged not found"
    log "apt-get install took $(( $(date +%s) - t0 )) s"
fi

# --- already up? --------------------------------------------------------------
node_state() { sinfo -h -N -n localhost -o %T 2>/dev/null | head -1; }
if [ -f "$CONF" ] && grep -qF "$MARKER" "$CONF" && scontrol ping 2>/dev/null | grep -q UP; then
    case "$(node_state)" in
        idle*|mixed*|allocated*|completing*) log "cluster already up"; echo "STATE=running"; exit 0 ;;
    esac
fi
if [ -f "$CONF" ] && ! grep -qF "$MARKER" "$CONF"; then
    die 4 "$CONF exists and was not written by this script; not touching a real SLURM installation"
fi

# --- munge ----------------------------------------------------------------------
mkdir -p /etc/munge /run/munge /var/lib/munge /var/log/munge
if [ ! -s /etc/munge/munge.key ]; then
    log "writing a munge key"
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
chown munge:munge /etc/munge/munge.key /run/munge /var/lib/munge /var/log/munge
chmod 400 /etc/munge/munge.key
chmod 700 /etc/munge
chmod 755 /run/munge   # client tools fail if the socket directory is not world-readable
munge_ok() { munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; }
if ! munge_ok; then
    rm -f /run/munge/munge.socket.2 /run/munge/munge.socket.2.lock  # stale socket of a killed munged
    runuser -u munge -- /usr/sbin/munged
    for _ in $(seq 50); do munge_ok && break; sleep 0.1; done
    munge_ok || die 1 "munged did not start (see /var/log/munge/munged.log)"
    log "munged started (pid $(cat /run/munge/munged.pid 2>/dev/null || echo '?'))"
fi

# --- slurm.conf ---------------------------------------------------------------
CPUS=$(nproc)
MEM_MB=$(awk '/^MemTotal:/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)  # below the machine's
mkdir -p /etc/slurm "$LOGDIR" "$SPOOL/ctld" "$SPOOL/d"
cat >"$CONF" <<EOF
$MARKER
# A single-node cluster without cgroups or a database: linuxproc process tracking,
# no task plugin, no accounting (sacct cannot report; use squeue), job completion
# records in a text file, finished jobs kept visible to squeue for 10 minutes.
ClusterName=localtest
SlurmctldHost=localhost
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/filetxt
JobCompLoc=$LOGDIR/jobcomp.log
MailProg=/bin/true
MinJobAge=600
ReturnToService=2
InactiveLimit=0
KillWait=10
Waittime=0
SlurmctldTimeout=60
SlurmdTimeout=120
StateSaveLocation=$SPOOL/ctld
SlurmdSpoolDir=$SPOOL/d
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=$LOGDIR/slurmctld.log
SlurmdLogFile=$LOGDIR/slurmd.log
NodeName=localhost CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=$PARTITION Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
chmod 644 "$CONF"

# --- daemons --------------------------------------------------------------------
# Stale daemons of an earlier run (pid files written by this config) are ended by pid.
for name in slurmd slurmctld; do
    pidf=/run/$name.pid
    if [ -f "$pidf" ]; then
        pid=$(cat "$pidf")
        if [ -n "$pid" ] && [ "$(cat /proc/"$pid"/comm 2>/dev/null)" = "$name" ]; then
            log "ending stale $name (pid $pid)"
            kill "$pid" || true
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        fi
        rm -f "$pidf"
    fi
done

# A fresh test cluster: the state an earlier, interrupted run left in the spool
# (saved jobs, vestigial job scripts) would bring its jobs back and keep the node
# 'mixed' instead of idle, so the spool is emptied and both daemons start clean (-c).
rm -rf "${SPOOL:?}/ctld" "${SPOOL:?}/d"
mkdir -p "$SPOOL/ctld" "$SPOOL/d"

deadline=$(( $(date +%s) + START_TIMEOUT ))
slurmctld -c -i
until scontrol ping 2>/dev/null | grep -q UP; do
    [ "$(date +%s)" -lt "$deadline" ] || die 1 "slurmctld not up after ${START_TIMEOUT}s: $(tail -5 $LOGDIR/slurmctld.log | tr '\n' ' ')"
    sleep 0.2
done
slurmd -c -N localhost
until node_state | grep -q '^idle'; do
    [ "$(date +%s)" -lt "$deadline" ] || die 1 "node not idle after ${START_TIMEOUT}s (state '$(node_state)'): $(tail -5 $LOGDIR/slurmd.log | tr '\n' ' ')"
    case "$(node_state)" in
        down*|drain*) scontrol update nodename=localhost state=resume 2>/dev/null || true ;;
    esac
    sleep 0.2
done
log "cluster up: partition $PARTITION, node localhost with $CPUS CPUs and ${MEM_MB} MB"
echo "STATE=started"
