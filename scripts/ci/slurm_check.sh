#!/usr/bin/env bash
# Runs a sharded sweep, and a run sharded over frame ranges (--chunk-frames), through a real
# one-node Slurm cluster started here, and checks that each merged result is byte-identical
# to the same sweep or run on one machine.
#
# Installs Debian's slurm-wlm and munge when missing (apt-get, with sudo -n when not root);
# prints "SKIPPED: <reason>" and exits 0 when they cannot be installed or the cluster
# cannot start. Everything runs in a temporary folder: munged with its own key and socket,
# slurmctld and slurmd (2 CPUs) with a generated slurm.conf on ports of their own; all
# are stopped at the end. Usage: scripts/ci/slurm_check.sh [path/to/lidar-noise]
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$PWD
bin=$(realpath "${1:-target/debug/lidar-noise}")
[ -x "$bin" ] || { echo "slurm_check: $bin is not built (cargo build --bin lidar-noise)"; exit 1; }

skip() { echo "SKIPPED: $*"; exit 0; }

need=()
for tool in slurmctld slurmd sbatch squeue munged; do
  command -v "$tool" >/dev/null || need+=("$tool")
done
if [ ${#need[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then sudo=(); elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then sudo=(sudo -n); else
    skip "Slurm is not installed (${need[*]} missing) and neither root nor passwordless sudo is available to apt-get install slurm-wlm munge"
  fi
  log=$(mktemp)
  if ! { "${sudo[@]}" apt-get update -qq && DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq slurm-wlm munge; } >"$log" 2>&1; then
    tail -n 5 "$log"
    skip "apt-get install slurm-wlm munge failed (output above)"
  fi
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/lidar-noise-slurm.XXXXXX")
chmod 700 "$work"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for f in "$work"/*.pid; do [ -f "$f" ] && kill "$(cat "$f")" 2>/dev/null || true; done
  sleep 0.5
  rm -rf "$work"
}
trap cleanup EXIT

# munge, with a key and socket of its own (a system munged, if any, is left alone).
dd if=/dev/urandom of="$work/munge.key" bs=1024 count=1 status=none
chmod 400 "$work/munge.key"
socket="$work/munge.socket"
if ! munged --force --key-file="$work/munge.key" --socket="$socket" \
  --pid-file="$work/munged.pid" --log-file="$work/munged.log" --seed-file="$work/munged.seed" \
  >"$work/munged.out" 2>&1; then
  cat "$work/munged.out"
  skip "munged did not start"
fi

host=$(hostname -s)
# Ports of our own, away from a system Slurm's 6817/6818.
ctld_port=$((20000 + RANDOM % 20000))
cat >"$work/slurm.conf" <<CONF
ClusterName=lidarnoisecheck
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$((ctld_port + 1))
SlurmUser=$(id -un)
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$socket
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 State=UNKNOWN
PartitionName=check Nodes=$host Default=YES MaxTime=10 State=UP
CONF
mkdir -p "$work/state" "$work/spool"
export SLURM_CONF="$work/slurm.conf"
if ! slurmctld -i >"$work/slurmctld.out" 2>&1; then
  cat "$work/slurmctld.out"; tail -n 20 "$work/slurmctld.log" 2>/dev/null || true
  skip "slurmctld did not start"
fi
if ! slurmd >"$work/slurmd.out" 2>&1; then
  cat "$work/slurmd.out"; tail -n 20 "$work/slurmd.log" 2>/dev/null || true
  skip "slurmd did not start"
fi
# Wait for the node to register.
for _ in $(seq 1 60); do
  state=$(sinfo -h -N -o '%T' 2>/dev/null | head -n 1 || true)
  case "$state" in idle*|mix*|alloc*) break ;; esac
  sleep 0.5
done
case "$state" in
  idle*|mix*|alloc*) echo "slurm_check: one-node cluster up ($host, 2 CPUs, state $state)" ;;
  *) tail -n 20 "$work/slurmctld.log" "$work/slurmd.log" 2>/dev/null || true
     skip "the Slurm node did not come up (state '${state:-none}')" ;;
esac

# The sweep: two captures x two rates x two seeds, frame 0 (8 cells).
args=("$root/fixtures/crossroad.pcap" "$root/fixtures/parking.pcap"
  --vary rain.rate_mm_h=0,3 --seeds 1..2 --frames 0)
"$bin" --quiet sweep "${args[@]}" -o "$work/single"

out="$work/sharded"
export LIDAR_NOISE="$bin"
jid=$(sbatch --parsable --chdir="$work" --array=0-2 "$root/scripts/dev/slurm/sweep.sbatch" "${args[@]}" -o "$out")
mid=$(sbatch --parsable --chdir="$work" --dependency=afterok:"$jid" "$root/scripts/dev/slurm/merge.sbatch" "${args[@]}" -o "$out")
echo "slurm_check: submitted array job $jid (3 shards) and merge job $mid (afterok)"
for _ in $(seq 1 180); do
  [ -z "$(squeue -h -j "$jid,$mid" 2>/dev/null)" ] && break
  sleep 0.5
done
if [ -n "$(squeue -h -j "$jid,$mid" 2>/dev/null)" ]; then
  squeue; scancel "$jid" "$mid" || true
  echo "slurm_check: FAILED: the jobs did not finish within 90 s"; exit 1
fi
for f in "$work"/lidar-noise-*.out; do echo "--- $(basename "$f")"; cat "$f"; done
for k in 0 1 2; do
  grep -q "sweep --shard $k/3" "$work/lidar-noise-sweep-${jid}_$k.out" \
    || { echo "slurm_check: FAILED: shard $k/3 did not run"; exit 1; }
done
[ -f "$out/index.html" ] || { echo "slurm_check: FAILED: the merge job wrote no index.html"; exit 1; }
# Every file, hidden ones (manifest, lock) included.
if diff -r "$work/single" "$out"; then
  echo "slurm_check: OK: the Slurm array + merge output is byte-identical to the single-machine sweep ($(find "$out" -type f | wc -l) files)"
else
  echo "slurm_check: FAILED: the merged output differs from the single-machine sweep"; exit 1
fi

# The run: two captures with their partial sweeps (3 + 2 frames) in chunks of one frame,
# five units over three tasks, then the dependent merge.
rargs=("$root/fixtures/crossroad.pcap" "$root/fixtures/parking.pcap" --keep-partial)
"$bin" --quiet run "${rargs[@]}" -o "$work/run-single"
rout="$work/run-sharded"
rjid=$(sbatch --parsable --export=ALL,CHUNK_FRAMES=1 --chdir="$work" --array=0-2 \
  "$root/scripts/dev/slurm/run.sbatch" "${rargs[@]}" -o "$rout")
rmid=$(sbatch --parsable --export=ALL,CHUNK_FRAMES=1 --chdir="$work" \
  --dependency=afterok:"$rjid" "$root/scripts/dev/slurm/run-merge.sbatch" "${rargs[@]}" -o "$rout")
echo "slurm_check: submitted run array job $rjid (3 shards, --chunk-frames 1) and merge job $rmid (afterok)"
for _ in $(seq 1 180); do
  [ -z "$(squeue -h -j "$rjid,$rmid" 2>/dev/null)" ] && break
  sleep 0.5
done
if [ -n "$(squeue -h -j "$rjid,$rmid" 2>/dev/null)" ]; then
  squeue; scancel "$rjid" "$rmid" || true
  echo "slurm_check: FAILED: the run jobs did not finish within 90 s"; exit 1
fi
for f in "$work"/lidar-noise-run-*.out; do echo "--- $(basename "$f")"; cat "$f"; done
for k in 0 1 2; do
  grep -q "run --shard $k/3" "$work/lidar-noise-run-${rjid}_$k.out" \
    || { echo "slurm_check: FAILED: run shard $k/3 did not run"; exit 1; }
done
[ -f "$rout/parking/summary.json" ] || { echo "slurm_check: FAILED: the run merge job wrote no summary.json"; exit 1; }
if diff -r "$work/run-single" "$rout"; then
  echo "slurm_check: OK: the Slurm run array (--chunk-frames 1) + merge output is byte-identical to the single-machine run ($(find "$rout" -type f | wc -l) files)"
else
  echo "slurm_check: FAILED: the merged run output differs from the single-machine run"; exit 1
fi
