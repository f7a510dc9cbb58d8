#!/usr/bin/env bash
# Run the paper profile on a CUDA node and pack its summaries into OUTDIR (no large datasets).
# Needs an environment with the lock's packages importable (e.g. PYTHONPATH to a --target install).
#   bash workflow/scripts/device_paper.sh OUTDIR [snakemake args...]
set -uo pipefail
out=$1; shift
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
# a copied tree may carry stale git metadata: pass PALPATION_GIT_COMMIT=<sha> to record the right commit
start=$(date +%s)
timeout -s INT "${SNAKE_TIMEOUT:-0}" python3 -m snakemake --workflow-profile workflow/profiles/paper --cores 16 --keep-going "$@" \
  > "$out/snakemake.log" 2>&1
rc=$?
echo "snakemake rc=$rc after $(( $(date +%s) - start )) s"
grep -E "steps \(|Error|Exiting" "$out/snakemake.log" | tail -5
tar czf "$out/paper_results.tgz" --exclude='*.npz' --exclude='*.npy' --exclude='*.pt' --exclude='*.mp4' --exclude=results/judge/sim \
  results/train/report results/maps results/calibration results/loop results/README.md results/bench results/data/summary.csv \
  results/data/summary.md results/logs results/judge results/loop_slides $(ls -d results/train/*/L*/seed*/metrics.json 2>/dev/null) \
  2>/dev/null
exit $rc
