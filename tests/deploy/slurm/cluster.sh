#!/usr/bin/env bash
# A real two-node Slurm cluster on one machine, for tests: two network namespaces joined by a
# veth pair are the nodes' hosts (nodea at 10.78.0.1, nodeb at 10.78.0.2), each runs its own
# slurmd; nodea also runs slurmctld; one munged serves both (its socket is a file, which every
# namespace sees). Daemons run as root with their state, logs and config under DIR.
#
#   cluster.sh up DIR      generates DIR/slurm.conf and the munge key, starts the daemons and
#                          waits until both nodes are idle; exit 77 with the reason when this
#                          machine cannot (not root, no ip, Slurm or munge not installed)
#   cluster.sh on NODE CMD runs CMD on nodea or nodeb (its network namespace), with SLURM_CONF
#   cluster.sh down DIR    stops every daemon and every process of a job, deletes the namespaces
#
# The processes see the machine's whole file system, so the run directory is "shared storage"
# as on a cluster. Namespaces are entered with nsenter, not `ip netns exec`, which would mount
# a fresh /sys and hide the cgroup file systems slurmd needs.
set -euo pipefail

cmd=${1:-}
dir=${2:-}
[[ -n $cmd ]] || { sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 2; }

skip() { echo "cluster.sh: cannot make a cluster here: $*" >&2; exit 77; }

state_of() { # DIR -> sources DIR/cluster.env
  [[ -f $1/cluster.env ]] || { echo "cluster.sh: no cluster in $1 (run: cluster.sh up $1)" >&2; exit 1; }
  # shellcheck disable=SC1091
  source "$1/cluster.env"
}

on_node() { # node command...
  local node=$1
  shift
  local ns
  ns=$([[ $node == nodea ]] && echo "$NS_A" || echo "$NS_B")
  SLURM_CONF="$DIR/slurm.conf" nsenter --net="/run/netns/$ns" "$@"
}

case $cmd in
  up)
    [[ -n $dir ]] || { echo "usage: cluster.sh up DIR" >&2; exit 2; }
    [[ $(id -u) == 0 ]] || skip "needs root (network namespaces, slurmd)"
    for tool in ip nsenter slurmctld slurmd munged sbatch; do
      command -v "$tool" > /dev/null || skip "no $tool (apt-get install slurm-wlm munge iproute2)"
    done
    mkdir -p "$dir"
    DIR=$(cd "$dir" && pwd)
    chmod 700 "$DIR"
    NS_A="indrive-slurm-a-$$" NS_B="indrive-slurm-b-$$"
    cat > "$DIR/cluster.env" << EOF
DIR=$DIR
NS_A=$NS_A
NS_B=$NS_B
EOF
    ip netns add "$NS_A" || skip "ip netns add failed (no CAP_SYS_ADMIN?)"
    ip netns add "$NS_B"
    ip link add "sa$$" type veth peer name "sb$$"
    ip link set "sa$$" netns "$NS_A"
    ip link set "sb$$" netns "$NS_B"
    ip -n "$NS_A" addr add 10.78.0.1/24 dev "sa$$"
    ip -n "$NS_B" addr add 10.78.0.2/24 dev "sb$$"
    for ns in "$NS_A" "$NS_B"; do ip -n "$ns" link set lo up; done
    ip -n "$NS_A" link set "sa$$" up
    ip -n "$NS_B" link set "sb$$" up
    # Multicast over the link, as on one LAN: a run with DDS Security discovers by multicast.
    ip -n "$NS_A" route add 224.0.0.0/4 dev "sa$$"
    ip -n "$NS_B" route add 224.0.0.0/4 dev "sb$$"

    head -c 1024 /dev/urandom > "$DIR/munge.key"
    chmod 400 "$DIR/munge.key"
    munged --socket="$DIR/munge.sock" --key-file="$DIR/munge.key" --pid-file="$DIR/munged.pid" \
      --log-file="$DIR/munged.log" --seed-file="$DIR/munge.seed" --force
    cpus=$(env -u OMP_NUM_THREADS -u OMP_THREAD_LIMIT nproc)  # nproc obeys OMP_NUM_THREADS
    memory=$(($(awk '/MemTotal/ { print $2 }' /proc/meminfo) / 1024 / 2))
    mkdir -p "$DIR/ctld"
    # The controller's name must be this machine's host name (slurmctld checks it); its address
    # is nodea's. No cgroups, accounting or MPI: a test cluster of one machine's processes.
    cat > "$DIR/slurm.conf" << EOF
ClusterName=indrive-test
SlurmctldHost=$(hostname -s)(10.78.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$DIR/munge.sock
CredType=cred/munge
StateSaveLocation=$DIR/ctld
SlurmdSpoolDir=$DIR/spool-%n
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd-%n.pid
SlurmctldLogFile=$DIR/slurmctld.log
SlurmdLogFile=$DIR/slurmd-%n.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerParameters=sched_interval=2
ReturnToService=2
MpiDefault=none
KillWait=30
SlurmdParameters=config_overrides
NodeName=nodea NodeAddr=10.78.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
NodeName=nodeb NodeAddr=10.78.0.2 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=test Nodes=nodea,nodeb Default=YES MaxTime=INFINITE OverSubscribe=FORCE:4 State=UP
EOF
    on_node nodea slurmctld -i
    on_node nodea slurmd -N nodea
    on_node nodeb slurmd -N nodeb
    for _ in $(seq 60); do
      idle=$(on_node nodea sinfo -h -N -t idle -o %N 2> /dev/null | sort -u | paste -sd,)
      [[ $idle == nodea,nodeb ]] && { echo "cluster.sh: nodea and nodeb idle ($DIR/slurm.conf)"; exit 0; }
      sleep 1
    done
    echo "cluster.sh: the nodes did not become idle in 60 s; the daemons' logs:" >&2
    tail -n 20 "$DIR"/slurm*.log >&2 || true
    exit 1
    ;;
  on)
    node=$dir
    shift 2
    state_of "${CLUSTER_DIR:?set CLUSTER_DIR to the DIR of cluster.sh up}"
    on_node "$node" "$@"
    ;;
  down)
    [[ -n $dir && -f $dir/cluster.env ]] || exit 0
    state_of "$dir"
    # The jobs first (their steps' processes outlive a stopped slurmd), then the daemons.
    on_node nodea scancel --full --user=root 2> /dev/null || true
    for _ in $(seq 60); do
      [[ -z $(on_node nodea squeue -h -o %i 2> /dev/null) ]] && break
      sleep 1
    done
    pids=()
    for pid_file in "$DIR"/slurmd-*.pid "$DIR/slurmctld.pid" "$DIR/munged.pid"; do
      [[ -f $pid_file ]] && pids+=("$(cat "$pid_file")")
    done
    kill "${pids[@]}" 2> /dev/null || true
    for _ in $(seq 20); do
      alive=0
      for pid in "${pids[@]}"; do kill -0 "$pid" 2> /dev/null && alive=1; done
      [[ $alive == 0 ]] && break
      sleep 0.5
    done
    ip netns del "$NS_A" 2> /dev/null || true
    ip netns del "$NS_B" 2> /dev/null || true
    rm -f "$DIR/cluster.env"
    ;;
  *) echo "cluster.sh: unknown command '$cmd': up, on or down" >&2; exit 2 ;;
esac
