#!/usr/bin/env bash
# The transfer table (docs/transfer.md) on a CUDA machine in one call, resumable:
#   bash workflow/scripts/gpu_transfer.sh OUTDIR
# Every method of METHODS (conf/transfer/methods.yaml) x its configurations x SEEDS (0 1 2 3 4), the commands of
# workflow/scripts/transfer_commands.py: first the teachers (every method without recipe.pseudo_from), then the
# self-trained students (their teachers' scores exist by then), then workflow/scripts/transfer_table.py writes
# OUTDIR/transfer.csv (copy it to docs/results/ when the runs are kept). A training whose runs all exist under RUNS
# (results/transfer) is skipped; one cut short is redone whole.
# The run is detached (device_run.sh): LIMIT_S (default: until done) is how long this command waits; the same
# command again re-attaches to a run still going (OUTDIR/transfer.pid) or starts the next one. Exit 0: the table is
# written; 75: still running; 1: a training or the table failed (OUTDIR/logs/<method>_<config>.log).
# JOBS (default 3) trainings run at once on the card, each with CORES/JOBS CPU threads (CORES default: nproc);
# each trains its seeds together in one process (plus a batch worker per seed). DEVICE (cuda), CLIP_LEN (5), PYTHON
# (python3) and EXTRA (overrides of every training, e.g. data.sim=...; a method's own win) as named. OUTDIR gets the logs,
# transfer.csv / transfer.json and transfer_runs.tgz (every finished run's metrics.json, scores.npz, pr.npz).
set -uo pipefail
here=$(dirname "${BASH_SOURCE[0]}")
source "$here/device_run.sh"  # the detached, resumable run (pid guard, LIMIT_S)
out=${1:?usage: gpu_transfer.sh OUTDIR}
runs=${RUNS:-results/transfer} methods=${METHODS:-conf/transfer/methods.yaml} seeds=${SEEDS:-0 1 2 3 4}
jobs_n=${JOBS:-3} python=${PYTHON:-python3} clip_len=${CLIP_LEN:-5}
[[ "$jobs_n" =~ ^[1-9][0-9]*$ ]] || { echo "gpu_transfer: JOBS=$jobs_n must be a whole number >= 1" >&2; exit 2; }
pythonpath=${PYTHONPATH:-}
export PYTHONPATH="$PWD/src${pythonpath:+:$pythonpath}" PYTHONUNBUFFERED=1
commands() {  # the pending trainings of a stage, one shell line each
  "$python" "$here/transfer_commands.py" --methods "$methods" --runs-root "$runs" --seeds $seeds \
    --clip-len "$clip_len" \
    --device "${DEVICE:-cuda}" --python "$python" --extra "${EXTRA:-}" --pending --logs "$out/logs" --stage "$1"
}

if [ "${2:-}" = --inner ]; then  # the detached run itself
  threads=$(( ${CORES:-$(nproc)} / jobs_n )); [ "$threads" -ge 1 ] || threads=1
  export OMP_NUM_THREADS=$threads MKL_NUM_THREADS=$threads
  mkdir -p "$out/logs"
  for stage in teachers students; do
    commands "$stage" > "$out/$stage.cmds" || exit 1
    n=$(wc -l < "$out/$stage.cmds"); k=0
    echo "$stage: $n trainings to run, $jobs_n at once"
    while IFS= read -r cmd; do
      while [ "$(jobs -rp | wc -l)" -ge "$jobs_n" ]; do wait -n; done
      k=$((k + 1))
      ( t0=$(date +%s); bash -c "$cmd" < /dev/null; rc=$?
        echo "[$stage $k/$n] rc=$rc done in $(( $(date +%s) - t0 )) s: ${cmd%% > *}" | cut -c1-400
        log=${cmd##* > }; log=${log%% 2>&1}  # a failed training's own error line (the app's, Hydra's, Python's)
        [ "$rc" -eq 0 ] || echo "Error: ${log##*/}: $(grep -E "[Ee]rror|Could not" "$log" 2>/dev/null |
          grep -v HYDRA_FULL_ERROR | tail -1 | cut -c1-300)" ) &
    done < "$out/$stage.cmds"
    wait
    left=$(commands "$stage" | wc -l)
    [ "$left" -eq 0 ] || { echo "Error: $left $stage trainings unfinished (see $out/logs)"; exit 1; }
  done
  "$python" "$here/transfer_table.py" --runs-root "$runs" --methods "$methods" --seeds $seeds --clip-len "$clip_len" \
    --out "$out/transfer.csv"
  exit $?
fi

mkdir -p "$out"
out=$(cd "$out" && pwd)
commands teachers > /dev/null || exit 2  # a bad methods file fails here, before anything starts
"$python" "$here/transfer_commands.py" --methods "$methods" --extra "${EXTRA:-}" --check-data || exit 2  # and bad data
if ! device_attach "$out" transfer; then
  device_start "$out" transfer bash "${BASH_SOURCE[0]}" "$out" --inner
fi
echo "transfer table ($runs, JOBS=$jobs_n):"
device_wait "$out" transfer
rc=$DEVICE_RC
device_progress "$out" transfer 5
files=$(find "$runs" -path '*/seed*' \( -name metrics.json -o -name scores.npz -o -name pr.npz \) 2>/dev/null | sort)
[ -n "$files" ] && tar czf "$out/transfer_runs.tgz" $files
echo "$(echo "$files" | grep -c metrics.json) finished runs in $out/transfer_runs.tgz"
exit $rc
