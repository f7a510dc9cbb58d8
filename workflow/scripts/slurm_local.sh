#!/usr/bin/env bash
# A single-node SLURM cluster on this machine, to run the workflow through the SLURM executor for real
# (issue 16): Debian's slurm-wlm and munge, one node with this machine's cores and memory, one partition
# `local`, jobs accounted in a job-completion log (no slurmdbd). Needs root.
#   workflow/scripts/slurm_local.sh start     install (apt) if needed, write the config, start the daemons
#   workflow/scripts/slurm_local.sh stop      stop the daemons
# Then: snakemake --workflow-profile workflow/profiles/slurm-local
set -euo pipefail
CONF=/etc/slurm/slurm.conf
SPOOL=/var/spool/slurm
LOGS=/var/log/slurm

start() {
  if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
  fi
  mkdir -p /etc/slurm "$SPOOL/ctld" "$SPOOL/d" "$LOGS" /run/munge /var/lib/munge /var/log/munge /etc/munge
  [ -s /etc/munge/munge.key ] || dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  chown -R munge:munge /etc/munge /run/munge /var/lib/munge /var/log/munge 2>/dev/null || true
  chmod 400 /etc/munge/munge.key
  pgrep -x munged >/dev/null || munged --force
  local host cpus mem
  host=$(hostname -s)
  cpus=$(nproc)
  mem=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024 ))
  cat > "$CONF" <<CONF
ClusterName=palpation-local
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$SPOOL/ctld
SlurmdSpoolDir=$SPOOL/d
SlurmctldLogFile=$LOGS/slurmctld.log
SlurmdLogFile=$LOGS/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$LOGS/jobcomp.log
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MpiDefault=none
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
  pgrep -x slurmctld >/dev/null || slurmctld
  pgrep -x slurmd >/dev/null || slurmd
  for _ in $(seq 30); do
    sinfo -h -o "%T" 2>/dev/null | grep -qE "idle|mixed" && { sinfo; return 0; }
    sleep 1
  done
  echo "slurm_local.sh: the node did not come up; see $LOGS/slurmctld.log and $LOGS/slurmd.log" >&2
  return 1
}

stop() {
  pkill -x slurmd || true
  pkill -x slurmctld || true
}

case "${1:-start}" in
  start) start ;;
  stop) stop ;;
  *) echo "usage: $0 start|stop" >&2; exit 2 ;;
esac
