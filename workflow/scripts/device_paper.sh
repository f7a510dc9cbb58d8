#!/usr/bin/env bash
# Run the paper profile on a CUDA node and pack its summaries into OUTDIR (no large datasets).
# Needs an environment with the lock's packages importable (e.g. PYTHONPATH to a --target install).
#   bash workflow/scripts/device_paper.sh OUTDIR [snakemake args...]
# PALPATION_MPS=1 runs the jobs under NVIDIA MPS (a private control daemon, quit on exit): the GPU jobs running at
# once (both loops, a Sim set, trainings) then share the SMs instead of taking turns, which the loops' small calls
# need, and six GPU jobs may run at once (--resources gpu=6) on 20 counted cores (--cores 20, so that five trainings of
# four threads run at once: the clip-length trainings and the twin ablation's no longer wait for each other's cores;
# later arguments override both). No setting of the card changes (docs/twin.md "The photo loop's host work, and the
# paper profile under MPS").
set -uo pipefail
out=$1; shift
gpu_jobs=()
if [ "${PALPATION_MPS:-0}" = 1 ]; then
  gpu_jobs=(--resources gpu=6 --cores 20)
  export CUDA_MPS_PIPE_DIRECTORY="$(mktemp -d /tmp/mps.XXXXXX)" CUDA_MPS_LOG_DIRECTORY="$out/mps_log"  # a socket path: short
  mkdir -p "$CUDA_MPS_LOG_DIRECTORY"
  nvidia-cuda-mps-control -d || { echo "PALPATION_MPS=1: nvidia-cuda-mps-control -d failed (see $out/mps_log)" >&2; exit 1; }
  trap 'echo quit | nvidia-cuda-mps-control' EXIT
  echo "MPS control daemon started (pipe $CUDA_MPS_PIPE_DIRECTORY)"
fi
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
# a copied tree may carry stale git metadata: pass PALPATION_GIT_COMMIT=<sha> to record the right commit
start=$(date +%s)
timeout -s INT "${SNAKE_TIMEOUT:-0}" python3 -m snakemake --workflow-profile workflow/profiles/paper --cores 16 --keep-going "${gpu_jobs[@]}" "$@" \
  > "$out/snakemake.log" 2>&1
rc=$?
echo "snakemake rc=$rc after $(( $(date +%s) - start )) s"
grep -E "steps \(|Error|Exiting" "$out/snakemake.log" | tail -5
tar czf "$out/paper_results.tgz" --exclude='*.npz' --exclude='*.npy' --exclude='*.pt' --exclude='*.mp4' --exclude=results/judge/sim \
  results/train/report results/maps results/calibration results/loop results/README.md results/bench results/data/summary.csv \
  results/data/summary.md results/logs results/judge results/loop_slides $(ls -d results/train/*/L*/seed*/metrics.json 2>/dev/null) \
  2>/dev/null
exit $rc
