#!/usr/bin/env bash
# The recipe ablation of issue 15 (workflow/rules/recipe.smk) on a CUDA machine, whole or in parts, resumable.
#   bash workflow/scripts/gpu_recipe_ablation.sh OUTDIR [snakemake args...]
# PART (default `all`): `all` makes results/recipe/report/ (every run, then the table, reliability and uncertainty
#   maps); otherwise row groups of the ablation, e.g. PART="reference_none robust_none" (the full recipes, the aims)
#   or PART="robust_jitter robust_scale" (target rules recipe_<recipe>_<switch_off>). docs/recipe.md gives the plan:
#   which parts fit a session, and their estimated device time.
# PROFILE (default paper) picks workflow/profiles/<PROFILE>; LIMIT_S stops Snakemake cleanly (SIGINT) before the
#   device's per-command limit. OUTDIR gets recipe_runs.tgz (every finished run's metrics.json, scores.npz,
#   pr.npz, no checkpoints), the report when made, and the logs. A stopped run resumes: the same command again
#   on the warm machine keeps the finished jobs and redoes the cut ones (the profile's rerun-incomplete).
# Needs what workflow/scripts/device_paper.sh needs: the lock's packages importable (PYTHONPATH to a --target
# install, workflow/scripts/gpu_loop_wheels.sh) and the CPU-made inputs carried in (the meshes under results/twin,
# the photo set results/data/photos: the device has no gmsh).
# On the lent device (10 min per command; $OUT is emptied before each):
#   LIMIT_S=560 PART="reference_none robust_none" bash workflow/scripts/gpu_recipe_ablation.sh results/recipe_gpu
#   cp -r results/recipe_gpu/. $OUT/
set -uo pipefail
out=${1:?usage: gpu_recipe_ablation.sh OUTDIR [snakemake args...]}; shift
profile=${PROFILE:-paper}
[ -d "workflow/profiles/$profile" ] || { echo "gpu_recipe_ablation: no workflow/profiles/$profile" >&2; exit 2; }
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
switches=$(python3 -c "from palpation.model.recipe import SWITCHES; print(' '.join(SWITCHES))") || exit 3
targets=()
for part in ${PART:-all}; do
  if [ "$part" = all ]; then targets+=(results/recipe/report/recipe_ablation.csv)
  elif [[ " reference_none robust_none ${switches// / robust_} " == *" $part "* ]]; then targets+=("recipe_$part")
  else echo "gpu_recipe_ablation: PART '$part' is not all, reference_none, robust_none or robust_<switch> ($switches)" >&2
    exit 2
  fi
done
mkdir -p "$out"
start=$(date +%s)
# a killed Snakemake leaves its lock; nothing else runs here, so a rerun may take it over
python3 -m snakemake --workflow-profile "workflow/profiles/$profile" --unlock > /dev/null 2>&1
timeout -s INT "${LIMIT_S:-0}" python3 -m snakemake --workflow-profile "workflow/profiles/$profile" --keep-going \
  "${targets[@]}" "$@" >> "$out/snakemake.log" 2>&1
rc=$?
echo "recipe ablation (${PART:-all}) rc=$rc after $(( $(date +%s) - start )) s"
[ "$rc" = 124 ] && echo "stopped at LIMIT_S=$LIMIT_S s: run the same command again on this warm machine to resume"
grep -E "steps \(|Error|Exiting" "$out/snakemake.log" | tail -5
runs=$(find results/recipe -path '*/seed*' \( -name metrics.json -o -name scores.npz -o -name pr.npz \) 2>/dev/null | sort)
[ -n "$runs" ] && tar czf "$out/recipe_runs.tgz" $runs
echo "$(echo "$runs" | grep -c metrics.json) finished runs in $out/recipe_runs.tgz"
[ -d results/recipe/report ] && cp -r results/recipe/report "$out/"
cp -r results/logs/recipe "$out/logs" 2>/dev/null
exit $rc
