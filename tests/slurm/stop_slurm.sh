#!/usr/bin/env bash
# Stop the test cluster of tests/slurm/start_slurm.sh: `scontrol shutdown` ends
# slurmctld and slurmd, then munged is ended by the pid in its pid file.
# Idempotent: does nothing where nothing runs. Removes /etc/slurm/slurm.conf (only
# the one start_slurm.sh wrote): with a config but no slurmctld, every `scontrol`
# call waits ~10 s, and snakemake-executor-plugin-slurm runs `scontrol show config`
# whenever snakemake starts, so every later snakemake call would stall. Leaves the
# packages and the munge key in place.
set -uo pipefail
CONF=/etc/slurm/slurm.conf
MARKER="# written by tests/slurm/start_slurm.sh (finger-rehab-workflow test cluster)"
export PATH="/usr/sbin:/usr/bin:/sbin:/bin:$PATH"
log() { echo "[stop_slurm] $*" >&2; }

[ "$(id -u)" -eq 0 ] || { log "not root: nothing to do"; exit 0; }
if [ -f "$CONF" ] && ! grep -qF "$MARKER" "$CONF"; then
    log "$CONF was not written by start_slurm.sh; not stopping a real SLURM installation"
    exit 0
fi

wait_gone() {  # pid name: up to 15 s, then SIGKILL
    local pid=$1 name=$2
    for _ in $(seq 150); do
        [ "$(cat /proc/"$pid"/comm 2>/dev/null)" = "$name" ] || return 0
        sleep 0.1
    done
    log "$name (pid $pid) still running after 15 s: SIGKILL"
    kill -9 "$pid" 2>/dev/null || true
}

pids=()
for name in slurmctld slurmd; do
    pid=$(cat /run/$name.pid 2>/dev/null || true)
    if [ -n "$pid" ] && [ "$(cat /proc/"$pid"/comm 2>/dev/null)" = "$name" ]; then pids+=("$pid:$name"); fi
done
if [ ${#pids[@]} -gt 0 ]; then
    command -v scontrol >/dev/null 2>&1 && timeout 20 scontrol shutdown 2>/dev/null || true
    for pn in "${pids[@]}"; do
        pid=${pn%%:*}; name=${pn#*:}
        # scontrol shutdown needs slurmctld up; a lone slurmd gets SIGTERM
        [ "$(cat /proc/"$pid"/comm 2>/dev/null)" = "$name" ] && sleep 1
        [ "$(cat /proc/"$pid"/comm 2>/dev/null)" = "$name" ] && kill "$pid" 2>/dev/null
        wait_gone "$pid" "$name"
        log "$name (pid $pid) stopped"
    done
    rm -f /run/slurmctld.pid /run/slurmd.pid
fi

pid=$(cat /run/munge/munged.pid 2>/dev/null || true)
if [ -n "$pid" ] && [ "$(cat /proc/"$pid"/comm 2>/dev/null)" = "munged" ]; then
    kill "$pid" 2>/dev/null || true
    wait_gone "$pid" munged
    log "munged (pid $pid) stopped"
fi
if [ -f "$CONF" ]; then rm -f "$CONF"; log "removed $CONF"; fi
exit 0
