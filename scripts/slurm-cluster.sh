#!/usr/bin/env bash
# A throw-away one-node Slurm cluster on this machine (docs/guide/cohort.md, "A real Slurm on one
# machine"): munged, slurmctld and slurmd of Debian's slurm-wlm, run as root, every file —
# configuration, munge key, state, spool, logs, sockets — under DIR, nothing in /etc.
#
#   scripts/slurm-cluster.sh start DIR [WATCH_PID]   # prints `export SLURM_CONF=… PATH=DIR/bin:…`
#   scripts/slurm-cluster.sh stop DIR                # cancels the jobs, stops the daemons by PID,
#                                                    # kills what is left, removes DIR and cgroups
#
# The node has this machine's CPUs and memory (less 1 GB), one partition `cohort`, memory as a
# consumable resource (--mem enforced: a job step over it is killed and ends OUT_OF_MEMORY),
# and no accounting database: slurmctld keeps finished jobs for MinJobAge = 600 s, which is what
# squeue/scontrol and the executor plugin's `status_command: squeue` read. With WATCH_PID, a
# watchdog stops the daemons and removes DIR when that process ends (a test that panics or is
# killed leaves nothing running). Needs root and the packages slurmctld, slurmd, slurm-client,
# munge (scripts/test-setup.sh).
set -euo pipefail

die() { echo "slurm-cluster: $*" >&2; exit 1; }

# The processes of this cluster's jobs: every slurmstepd started by this cluster's slurmd (it
# inherits SLURM_CONF=DIR/slurm.conf from the daemon) and every process in the node's Slurm
# cgroups (proctrack/cgroup puts each job's processes there: job scripts, their children, srun
# and the steps' tasks). Zombies are dead already and left out. Never this script or its parent.
job_pids() {
  local conf="$1" host="$2" f pid
  {
    for f in /sys/fs/cgroup/*/slurm_"$host"; do
      if [ -d "$f" ]; then find "$f" -name cgroup.procs -exec cat {} + 2>/dev/null || true; fi
    done
    for f in /proc/[0-9]*; do
      if [ "$(cat "$f/comm" 2>/dev/null)" = slurmstepd ] &&
        tr '\0' '\n' 2>/dev/null <"$f/environ" | grep -qxF "SLURM_CONF=$conf"; then
        echo "${f#/proc/}"
      fi
    done
  } | sort -un | while read -r pid; do
    [ "$pid" != "$$" ] && [ "$pid" != "$PPID" ] || continue
    # The state is the field after the parenthesised command (which may hold spaces).
    f="$(cat "/proc/$pid/stat" 2>/dev/null)" || continue
    f="${f##*) }"
    if [ "${f%% *}" != Z ]; then echo "$pid"; fi
  done
  return 0
}

stop() {
  local dir="$1" pid f host conf ids left
  [ -d "$dir" ] || return 0
  dir="$(cd "$dir" && pwd)"
  host="$(hostname -s)"
  conf="$dir/slurm.conf"
  # The jobs first, while the daemons run: scancel makes slurmd signal every step (SIGTERM, then
  # SIGKILL after KillWait), slurmstepd waits for its processes, removes the job's cgroups and
  # exits. slurmstepd is not the daemon's child (it is re-parented to init), so stopping slurmd
  # alone would leave it, its job script and every child running.
  # Every client call is bounded: with the controller gone, squeue and scancel retry for minutes.
  if SLURM_CONF="$conf" timeout 5 scontrol ping 2>/dev/null | grep -q UP; then
    ids="$(SLURM_CONF="$conf" timeout 5 squeue -h -t PD,R,S,CG,CF,RQ,RS,RH,SE,SO,ST -o %i 2>/dev/null || true)"
    # shellcheck disable=SC2086 # one id a word
    [ -z "$ids" ] || SLURM_CONF="$conf" timeout 5 scancel $ids 2>/dev/null || true
    # KillWait is 5 s: the steps are gone within it, the jobs then leave COMPLETING.
    local until=$((SECONDS + 20))
    while [ "$SECONDS" -lt "$until" ]; do
      left="$(SLURM_CONF="$conf" timeout 5 squeue -h -t R,S,CG,CF -o %i 2>/dev/null || echo failed)"
      [ -z "$left" ] && [ -z "$(job_pids "$conf" "$host")" ] && break
      sleep 0.2
    done
  fi
  for f in watchdog slurmd slurmctld munged; do
    [ -f "$dir/pids/$f" ] || continue
    pid="$(cat "$dir/pids/$f")"
    # The watchdog runs this very function when its process ends (bash execs the last command
    # of `bash -c`, so this script may have the watchdog's PID): never kill ourselves.
    [ "$pid" = "$$" ] || [ "$pid" = "$PPID" ] || kill "$pid" 2>/dev/null || true
  done
  # slurmd and slurmctld exit within a second of SIGTERM. Wait by PID, then insist.
  for f in watchdog slurmd slurmctld munged; do
    [ -f "$dir/pids/$f" ] || continue
    pid="$(cat "$dir/pids/$f")"
    [ "$pid" != "$$" ] && [ "$pid" != "$PPID" ] || continue
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null || true
  done
  # What a cancel did not end (the controller was already gone, a step ignored its signals):
  # killed by PID until none is left.
  for _ in $(seq 50); do
    left="$(job_pids "$conf" "$host")"
    [ -n "$left" ] || break
    # shellcheck disable=SC2086 # one PID a word
    kill -9 $left 2>/dev/null || true
    sleep 0.1
  done
  [ -z "$left" ] || echo "slurm-cluster: processes left after stop: $left" >&2
  # The node's cgroups, deepest first; a cgroup whose last process has just died may refuse
  # for a moment.
  local cg
  for _ in $(seq 50); do
    left=""
    for cg in /sys/fs/cgroup/*/slurm_"$host"; do
      [ -d "$cg" ] || continue
      find "$cg" -depth -type d -exec rmdir {} + 2>/dev/null || true
      [ ! -d "$cg" ] || left="$left $cg"
    done
    [ -n "$left" ] || break
    sleep 0.1
  done
  [ -z "$left" ] || echo "slurm-cluster: cgroups left after stop:$left" >&2
  rm -rf "$dir"
}

start() {
  local dir="$1" watch="${2:-}"
  [ "$(id -u)" = 0 ] || die "needs root (the daemons run as root; sudo or a root CI job)"
  local p
  for p in slurmctld slurmd munged sbatch srun squeue scontrol; do
    command -v "$p" >/dev/null 2>&1 ||
      die "$p missing: run scripts/test-setup.sh (apt: slurmctld slurmd slurm-client munge)"
  done
  [ ! -e "$dir" ] || [ -z "$(ls -A "$dir")" ] || die "$dir exists and is not empty"
  [ ! -e /etc/slurm/slurm.conf ] ||
    die "/etc/slurm/slurm.conf exists: this machine has its own Slurm; use that, not a test cluster"
  # A second slurmd (or a job's slurmstepd) on this host would share the node's cgroups; a stale
  # one is a cluster whose stop never ran (its processes outlived a killed watchdog). Files left behind do not matter:
  # nothing outside DIR is read.
  # One name per pgrep: pgrep matches a process name (at most 15 characters) and refuses a
  # longer pattern, alternatives included.
  local running="" name
  for name in slurmd slurmctld slurmstepd slurmd-wlm slurmctld-wlm; do
    running="$running$(pgrep -a -x "$name" | tr '\n' ';' || true)"
  done
  [ -z "$running" ] || die "Slurm daemons already run here (stop them first): $running"
  mkdir -p "$dir"/{munge,state,spool,log,pids,bin}
  dir="$(cd "$dir" && pwd)"
  chmod 700 "$dir/munge"

  # munge: its own key and socket, no system files.
  dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
  chmod 400 "$dir/munge/munge.key"
  munged --foreground --force --key-file="$dir/munge/munge.key" \
    --socket="$dir/munge/munge.socket" --pid-file="$dir/munge/munged.pid" \
    --log-file="$dir/log/munged.log" --seed-file="$dir/munge/munged.seed" \
    >"$dir/log/munged.out" 2>&1 &
  echo $! >"$dir/pids/munged"

  local host cpus mem port
  host="$(hostname -s)"
  cpus="$(nproc)"
  mem=$(($(awk '/^MemTotal:/ { print int($2 / 1024) }' /proc/meminfo) - 1024))
  # Two free ports next to each other for slurmctld and slurmd.
  port="$(python3 -c 'import socket
for p in range(16817, 17817, 2):
    ok = True
    for q in (p, p + 1):
        s = socket.socket()
        try:
            s.bind(("127.0.0.1", q))
        except OSError:
            ok = False
        s.close()
    if ok:
        print(p); break')"
  [ -n "$port" ] || die "no two free ports between 16817 and 17817"

  cat >"$dir/slurm.conf" <<EOF
# Written by scripts/slurm-cluster.sh: a one-node test cluster, removed when it stops.
ClusterName=facesimtest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool/%n
SlurmctldPidFile=$dir/log/slurmctld.pid
SlurmdPidFile=$dir/log/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
# Jobs: processes tracked by the kernel's process tree; memory read every second, a step over
# its --mem killed (OverMemoryKill) and its job ending OUT_OF_MEMORY.
ProctrackType=proctrack/cgroup
TaskPlugin=task/cgroup
JobAcctGatherType=jobacct_gather/cgroup
JobAcctGatherFrequency=task=1
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SchedulerType=sched/backfill
MpiDefault=none
# No accounting database: finished jobs stay in slurmctld (squeue --states=all, scontrol show
# job) for MinJobAge seconds.
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MinJobAge=600
ReturnToService=2
KillWait=5
InactiveLimit=0
Waittime=0
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=cohort Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  cat >"$dir/cgroup.conf" <<EOF
CgroupPlugin=cgroup/v1
CgroupMountpoint=/sys/fs/cgroup
ConstrainCores=no
ConstrainRAMSpace=yes
ConstrainSwapSpace=no
EOF
  export SLURM_CONF="$dir/slurm.conf"
  # Slurm's clients find this file by SLURM_CONF. The executor plugin's job step strips every
  # SLURM_* variable from the srun it starts inside a job, which would then look in /etc/slurm
  # and /run/slurm/conf (a configless slurmd's cache), outside DIR. DIR/bin/srun puts it back;
  # DIR/bin goes first on the PATH that sbatch --export=ALL hands the job.
  local srun
  srun="$(command -v srun)"
  printf '#!/bin/sh\n# Written by scripts/slurm-cluster.sh: srun with this cluster'"'"'s configuration.\nSLURM_CONF=%s exec %s "$@"\n' \
    "$SLURM_CONF" "$srun" >"$dir/bin/srun"
  chmod 755 "$dir/bin/srun"

  # munged's socket first, then the controller, then the node daemon.
  for _ in $(seq 50); do [ -S "$dir/munge/munge.socket" ] && break; sleep 0.1; done
  [ -S "$dir/munge/munge.socket" ] || { cat "$dir/log/munged.out" >&2; stop "$dir"; die "munged did not start"; }
  slurmctld -D -i -f "$SLURM_CONF" >"$dir/log/slurmctld.out" 2>&1 &
  echo $! >"$dir/pids/slurmctld"
  for _ in $(seq 100); do scontrol ping 2>/dev/null | grep -q UP && break; sleep 0.1; done
  slurmd -D -f "$SLURM_CONF" >"$dir/log/slurmd.out" 2>&1 &
  echo $! >"$dir/pids/slurmd"
  local state=""
  for _ in $(seq 150); do
    state="$(sinfo -h -N -o %T 2>/dev/null || true)"
    [ "$state" = idle ] && break
    sleep 0.2
  done
  if [ "$state" != idle ]; then
    tail -n 5 "$dir"/log/*.log "$dir"/log/*.out >&2 || true
    stop "$dir"
    die "the node did not come up (state '${state:-none}')"
  fi
  if [ -n "$watch" ]; then
    # The watchdog: when WATCH_PID ends, the cluster goes with it.
    nohup bash -c 'while kill -0 "$1" 2>/dev/null; do sleep 1; done; "$2" stop "$3"' \
      slurm-watchdog "$watch" "$0" "$dir" >/dev/null 2>&1 &
    echo $! >"$dir/pids/watchdog"
  fi
  echo "export SLURM_CONF=$SLURM_CONF PATH=$dir/bin:\$PATH"
}

case "${1:-}" in
  start) [ $# -ge 2 ] || die "usage: $0 start DIR [WATCH_PID]"; start "$2" "${3:-}" ;;
  stop) [ $# -eq 2 ] || die "usage: $0 stop DIR"; stop "$2" ;;
  *) die "usage: $0 start DIR [WATCH_PID] | stop DIR" ;;
esac
