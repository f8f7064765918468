#!/bin/bash
# A one-node Slurm cluster in a directory, for tests and trying `lodstream slurm` on one machine:
#   tools/slurm_local_cluster.sh start DIR   starts munged, slurmctld and slurmd (as root) with their
#                                            state, sockets, logs and slurm.conf in DIR; prints
#                                            "SLURM_CONF=DIR/slurm.conf" on success (exit 0)
#   tools/slurm_local_cluster.sh stop DIR    stops the three daemons by their pid files
# Exit 77 with one line on stderr when the cluster cannot start here (not root, Slurm or MUNGE missing,
# a daemon that does not come up): callers skip with a notice.
set -u
cmd=${1:-}
dir=${2:-}
[ -n "$cmd" ] && [ -n "$dir" ] || { echo "usage: $0 start|stop DIR" >&2; exit 64; }

stop() {
  for d in slurmd slurmctld munged; do
    [ -f "$dir/$d.pid" ] || continue
    pid=$(cat "$dir/$d.pid" 2>/dev/null)
    [ -n "$pid" ] && kill "$pid" 2>/dev/null
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -0 "$pid" 2>/dev/null && kill -9 "$pid" 2>/dev/null
    rm -f "$dir/$d.pid"
  done
}

if [ "$cmd" = stop ]; then stop; exit 0; fi
[ "$cmd" = start ] || { echo "usage: $0 start|stop DIR" >&2; exit 64; }

skip() { echo "slurm_local_cluster: cannot start a cluster here: $*" >&2; stop; exit 77; }
[ "$(id -u)" = 0 ] || skip "not root"
for b in munged mungekey slurmctld slurmd sbatch sinfo; do
  command -v "$b" >/dev/null || skip "$b not installed (tools/install-deps.sh --test installs slurm-wlm and munge)"
done
mkdir -p "$dir/state" "$dir/spool" "$dir/munge"
dir=$(cd "$dir" && pwd)
chmod 700 "$dir/munge"
# Free ports: the test may run beside a real cluster or another test's.
port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
ctld_port=$(port)
slurmd_port=$(port)
host=$(hostname -s)
cpus=$(nproc)
mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)

mungekey --create --keyfile="$dir/munge/munge.key" --force >/dev/null 2>&1 || skip "mungekey failed"
chmod 400 "$dir/munge/munge.key"
munged --force --socket="$dir/munge/munge.sock" --key-file="$dir/munge/munge.key" --pid-file="$dir/munged.pid" \
  --log-file="$dir/munged.log" --seed-file="$dir/munge/munge.seed" >/dev/null 2>&1 || skip "munged did not start (see $dir/munged.log)"

cat > "$dir/slurm.conf" <<CONF
ClusterName=lodstream-test
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$dir/munge/munge.sock
CredType=cred/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MinJobAge=600
SlurmdTimeout=60
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$dir/slurm.conf
slurmctld -f "$dir/slurm.conf" -i >/dev/null 2>&1 || skip "slurmctld did not start (see $dir/slurmctld.log)"
slurmd -f "$dir/slurm.conf" >/dev/null 2>&1 || skip "slurmd did not start (see $dir/slurmd.log)"
for _ in $(seq 100); do
  state=$(sinfo -h -o %T 2>/dev/null | head -1)
  case "$state" in idle*|mixed*|allocated*) echo "SLURM_CONF=$dir/slurm.conf"; exit 0 ;; esac
  sleep 0.2
done
skip "the node did not come up (state '${state:-none}'; see $dir/slurmctld.log, $dir/slurmd.log)"
