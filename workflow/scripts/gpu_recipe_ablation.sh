#!/usr/bin/env bash
# The recipe ablation of issue 15 (workflow/rules/recipe.smk) on a CUDA machine, whole or in parts, resumable.
#   bash workflow/scripts/gpu_recipe_ablation.sh OUTDIR [snakemake args...]
# PART (default `all`): `all` makes results/recipe/report/ (every run, then the table, reliability and uncertainty
#   maps); otherwise row groups of the ablation, e.g. PART="reference_none robust_none" (the full recipes, the aims)
#   or PART="robust_jitter robust_scale" (target rules recipe_<recipe>_<switch_off>). docs/recipe.md gives the plan:
#   which parts fit a session, and their estimated device time.
# PROFILE (default paper) picks workflow/profiles/<PROFILE>. Snakemake runs in its own process session (setsid), so
#   it outlives the command: the device kills a command's processes at its 10-min limit, and one robust Sim job
#   alone can take longer. LIMIT_S (default: until done) is how long this command waits for it; the same command
#   again re-attaches to a run still going (OUTDIR/snakemake.pid), or starts the next one, which keeps the
#   finished jobs (a job cut by a fresh machine is redone whole). Exit 0: done; 75: still running; else
#   Snakemake's status. OUTDIR gets recipe_runs.tgz (every finished run's metrics.json, scores.npz, pr.npz,
#   no checkpoints), the report when made, and the logs.
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
out=$(cd "$out" && pwd)
pid=$(cat "$out/snakemake.pid" 2>/dev/null)
if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
  echo "re-attaching to the run still going (pid $pid)"
else
  # a killed Snakemake leaves its lock; nothing else runs here, so a new run may take it over
  [ -n "$(ls -A .snakemake/locks 2>/dev/null)" ] &&
    python3 -m snakemake --workflow-profile "workflow/profiles/$profile" --unlock > /dev/null 2>&1
  rm -f "$out/snakemake.rc"
  setsid bash -c 'python3 -m snakemake --workflow-profile "$0" --keep-going "${@:2}" >> "$1/snakemake.log" 2>&1
                  echo $? > "$1/snakemake.rc"' "workflow/profiles/$profile" "$out" "${targets[@]}" "$@" \
    < /dev/null > /dev/null 2>&1 &
  pid=$!
  echo "$pid" > "$out/snakemake.pid"
fi
start=$(date +%s)
while kill -0 "$pid" 2>/dev/null; do
  [ "${LIMIT_S:-0}" -gt 0 ] && [ $(( $(date +%s) - start )) -ge "$LIMIT_S" ] && break
  sleep 5
done
if kill -0 "$pid" 2>/dev/null; then rc=75; else rc=$(cat "$out/snakemake.rc" 2>/dev/null || echo 1); fi
echo "recipe ablation (${PART:-all}) rc=$rc after waiting $(( $(date +%s) - start )) s"
[ "$rc" = 75 ] && echo "still running (pid $pid): run the same command again on this warm machine to wait for it"
grep -E "steps \(|Error|Exiting" "$out/snakemake.log" | tail -5
runs=$(find results/recipe -path '*/seed*' \( -name metrics.json -o -name scores.npz -o -name pr.npz \) 2>/dev/null | sort)
[ -n "$runs" ] && tar czf "$out/recipe_runs.tgz" $runs
echo "$(echo "$runs" | grep -c metrics.json) finished runs in $out/recipe_runs.tgz"
[ -d results/recipe/report ] && cp -r results/recipe/report "$out/"
cp -r results/logs/recipe "$out/logs" 2>/dev/null
exit $rc
