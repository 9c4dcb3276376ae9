#!/usr/bin/env bash
# A one-node Slurm on this machine, for trying out `tools/campaign.py --scheduler slurm`
# and for the `cluster` CTest test. Every daemon talks over the loopback address only.
#
#   tools/local_slurm.sh start    install Debian's slurmctld, slurmd, slurm-client and munge if
#                                 missing, write the configuration, start munged, slurmctld and
#                                 slurmd, wait until the node is idle
#   tools/local_slurm.sh stop     cancel the jobs still queued, stop the three daemons it started
#                                 (by their pid files, nothing else)
#   tools/local_slurm.sh status   the daemons, sinfo and squeue
#   tools/local_slurm.sh env      prints `export SLURM_CONF=...`: eval "$(tools/local_slurm.sh env)"
#
# Everything lives in one folder of its own, $FETICONTACT_SLURM_DIR (default: build/local-slurm
# in the repository): slurm.conf, a munge key and socket, state, spool, pid and log files (the
# last three in /run/feticontact-slurm-* when that folder's path is too long for sockets). A
# configuration under /etc/slurm or /etc/munge is never read or written; clients find this one
# through SLURM_CONF (sbatch, squeue, ... and tools/campaign.py).
#
# Needs root (munged runs as the munge user, slurmd as root) and, if the packages are missing,
# apt-get. Exit status: 0 ok; 1 error; 77 when Slurm cannot be started on this machine (not
# root, no apt-get, packages not installable), which the test reports as skipped; `status`
# exits 3 when the daemons are not running.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DIR=${FETICONTACT_SLURM_DIR:-$ROOT/build/local-slurm}
CONF=$DIR/slurm.conf
PACKAGES=(slurmctld slurmd slurm-client munge)
CANNOT=77
# Unix sockets (munged's; slurmd's spool holds one per job step, named <node>_<job>.<step>) must
# have paths under 108 bytes: they live in DIR, or in /run/feticontact-slurm-<checksum of DIR>
# when DIR's path is too long for that
SOCKETS=$DIR
if [ $((${#DIR} + $(hostname -s | wc -c))) -gt 70 ]; then
  SOCKETS=/run/feticontact-slurm-$(printf %s "$DIR" | cksum | cut -d' ' -f1)
fi
MUNGE=$SOCKETS/munge

say() { echo "local_slurm: $*" >&2; }
cannot() { say "cannot start Slurm here: $*"; exit $CANNOT; }

pid_of() { # the pid in a pid file if that process is alive and is the named program
  local file=$1 name=$2 pid
  [ -s "$file" ] || return 1
  pid=$(tr -dc 0-9 <"$file")
  [ -n "$pid" ] && [ -r "/proc/$pid/comm" ] || return 1
  [ "$(cat "/proc/$pid/comm")" = "$name" ] || return 1
  echo "$pid"
}

install_packages() {
  local missing=() p
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  command -v apt-get >/dev/null || cannot "packages ${missing[*]} missing and no apt-get"
  say "installing Debian packages: ${missing[*]}"
  # The packages must not start system-wide services (they would read /etc and outlive us):
  # a policy-rc.d that forbids it, only for the time of the installation, if there is none.
  local policy=/usr/sbin/policy-rc.d made_policy=0
  if [ ! -e $policy ]; then
    printf '#!/bin/sh\n# temporary, tools/local_slurm.sh: no service starts while installing\nexit 101\n' >$policy
    chmod 755 $policy
    made_policy=1
  fi
  local apt=(env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends)
  local ok=0
  if "${apt[@]}" "${missing[@]}" >"$DIR/apt.log" 2>&1; then
    ok=1
  elif env DEBIAN_FRONTEND=noninteractive apt-get update -qq >>"$DIR/apt.log" 2>&1 &&
    "${apt[@]}" "${missing[@]}" >>"$DIR/apt.log" 2>&1; then
    ok=1
  fi
  [ $made_policy -eq 1 ] && rm -f $policy
  [ $ok -eq 1 ] || { tail -5 "$DIR/apt.log" >&2; cannot "apt-get could not install ${missing[*]} (see $DIR/apt.log)"; }
}

port_free() { ! (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }

write_config() {
  local node cpus mem_kb mem port=6817
  node=$(hostname -s)
  cpus=$(nproc --all)
  mem_kb=$(awk '/^MemTotal:/ {print $2}' /proc/meminfo)
  mem=$((mem_kb / 1024 * 95 / 100)) # MiB, a little under what slurmd measures
  while ! { port_free $port && port_free $((port + 1)); }; do
    port=$((port + 2))
    [ $port -lt 6900 ] || { say "no free port pair in 6817-6899"; exit 1; }
  done
  cat >"$CONF" <<EOF
# One-node Slurm on the loopback address, written by tools/local_slurm.sh (feticontact).
# Clients use it through SLURM_CONF=$CONF
ClusterName=feticontact
SlurmctldHost=$node(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
CommunicationParameters=NoCtldInAddrAny,NoInAddrAny
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$MUNGE/munge.socket.2
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$SOCKETS/spool
SlurmctldPidFile=$DIR/run/slurmctld.pid
SlurmdPidFile=$DIR/run/slurmd.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
PlugStackConfig=$DIR/plugstack.conf
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
MpiDefault=none
# no accounting (sacct does not work), as on many small clusters
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
ReturnToService=2
# finished jobs stay visible to squeue/scontrol for an hour
MinJobAge=3600
KillWait=10
InactiveLimit=0
SlurmctldTimeout=30
SlurmdTimeout=60
NodeName=$node NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=local Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF
  : >"$DIR/plugstack.conf"
  echo "$node"
}

start_munge() {
  # munge/ holds the socket (everyone may connect), munge/private/ the key, seed and log
  local m=$MUNGE p=$MUNGE/private
  if pid_of "$DIR/run/munged.pid" munged >/dev/null; then return 0; fi
  id munge >/dev/null 2>&1 || cannot "no munge user (package munge not installed?)"
  mkdir -p "$p"
  chmod 755 "$m"
  chmod 700 "$p"
  if [ ! -s "$p/munge.key" ]; then
    dd if=/dev/urandom of="$p/munge.key" bs=1024 count=1 status=none
  fi
  chmod 400 "$p/munge.key"
  chown -R munge:munge "$m"
  rm -f "$m/munge.socket.2" "$m/munge.socket.2.lock" "$m/munged.pid"
  runuser -u munge -- /usr/sbin/munged --key-file="$p/munge.key" --socket="$m/munge.socket.2" \
    --pid-file="$m/munged.pid" --log-file="$p/munged.log" --seed-file="$p/munged.seed" ||
    { tail -5 "$p/munged.log" >&2 || true; say "munged did not start"; exit 1; }
  for _ in $(seq 50); do
    [ -S "$m/munge.socket.2" ] && [ -s "$m/munged.pid" ] && break
    sleep 0.1
  done
  # munged writes its pid file in a folder the munge user owns; the copy in run/ is the one used
  cp "$m/munged.pid" "$DIR/run/munged.pid"
  pid_of "$DIR/run/munged.pid" munged >/dev/null || { say "munged did not start (see $p/munged.log)"; exit 1; }
}

wait_idle() {
  local node=$1 state=""
  for _ in $(seq 120); do
    state=$(SLURM_CONF=$CONF sinfo -h -n "$node" -o %T 2>/dev/null | head -1 || true)
    case $state in
    idle | mixed | allocated) return 0 ;;
    down* | drain*) SLURM_CONF=$CONF scontrol update nodename="$node" state=resume >/dev/null 2>&1 || true ;;
    esac
    sleep 0.5
  done
  say "node $node not idle after 60 s (state '$state'); see $DIR/log/"
  return 1
}

cmd_start() {
  [ "$(id -u)" -eq 0 ] || cannot "needs root (munged runs as the munge user, slurmd as root)"
  mkdir -p "$DIR"/{state,run,log} "$SOCKETS/spool"
  install_packages
  local node
  if pid_of "$DIR/run/slurmctld.pid" slurmctld >/dev/null; then
    node=$(hostname -s)
    say "already running ($CONF)"
  else
    node=$(write_config)
    start_munge
    export SLURM_CONF=$CONF
    slurmctld -f "$CONF" || { tail -5 "$DIR/log/slurmctld.log" >&2; say "slurmctld did not start"; exit 1; }
  fi
  if ! pid_of "$DIR/run/slurmd.pid" slurmd >/dev/null; then
    SLURM_CONF=$CONF slurmd -f "$CONF" -N "$node" ||
      { tail -5 "$DIR/log/slurmd.log" >&2; say "slurmd did not start"; exit 1; }
  fi
  wait_idle "$node" || exit 1
  say "running: node $node idle; clients need SLURM_CONF=$CONF"
}

stop_daemon() { # name pidfile
  local pid
  pid=$(pid_of "$2" "$1") || { rm -f "$2"; return 0; }
  kill -TERM "$pid" 2>/dev/null || true
  for _ in $(seq 100); do
    [ -d "/proc/$pid" ] || break
    sleep 0.1
  done
  if [ -d "/proc/$pid" ]; then kill -KILL "$pid" 2>/dev/null || true; fi
  rm -f "$2"
  say "stopped $1 ($pid)"
}

cmd_stop() {
  if pid_of "$DIR/run/slurmctld.pid" slurmctld >/dev/null; then
    # end the jobs first, so that no slurmstepd outlives its slurmd
    local jobs
    jobs=$(SLURM_CONF=$CONF squeue -h -o %i 2>/dev/null || true)
    if [ -n "$jobs" ]; then
      say "cancelling jobs:" $jobs
      # shellcheck disable=SC2086
      SLURM_CONF=$CONF scancel $jobs 2>/dev/null || true
      for _ in $(seq 60); do
        [ -z "$(SLURM_CONF=$CONF squeue -h -o %i 2>/dev/null || true)" ] && break
        sleep 0.5
      done
    fi
  fi
  stop_daemon slurmd "$DIR/run/slurmd.pid"
  stop_daemon slurmctld "$DIR/run/slurmctld.pid"
  stop_daemon munged "$DIR/run/munged.pid"
}

cmd_status() {
  local name running=0 pid
  for name in munged slurmctld slurmd; do
    if pid=$(pid_of "$DIR/run/$name.pid" $name); then
      echo "$name: running, pid $pid"
      running=$((running + 1))
    else
      echo "$name: not running"
    fi
  done
  echo "SLURM_CONF=$CONF"
  if [ $running -eq 3 ]; then
    SLURM_CONF=$CONF sinfo || true
    SLURM_CONF=$CONF squeue || true
    return 0
  fi
  return 3
}

case ${1:-} in
start) cmd_start ;;
stop) cmd_stop ;;
status) cmd_status ;;
env) echo "export SLURM_CONF=$CONF" ;;
*)
  sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//' >&2
  exit 2
  ;;
esac
