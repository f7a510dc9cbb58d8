#!/usr/bin/env bash
# Issue 15, lead side (CPU, no GPU): the recipe ablation's table from the runs of several device sessions.
#   bash workflow/scripts/recipe_merge.sh RUNS.tgz [RUNS.tgz ...]
# Each RUNS.tgz is a recipe_runs.tgz of workflow/scripts/gpu_recipe_ablation.sh (metrics.json, scores.npz, pr.npz
# of finished runs under results/recipe/, no checkpoints). They are unpacked into results/ in the order given; a run
# in a later archive replaces an earlier one's (counted). Then the real test sets are made where missing (Snakemake,
# CPU, ~1 min), and palpation.apps.recipe_report makes the table from the profile's train.recipe_ablation
# (PROFILE, default paper): every row complete (a missing run is an error) unless PARTIAL="why" is given.
# Without PARTIAL, palpation.apps.recipe_crossfit (rule recipe_crossfit) follows; its CSV, JSON, PNG are copied too.
# With DOCS=1 (default) the report is copied to docs/results/{recipe_ablation,uncertainty}.csv and
# docs/results/<profile>/recipe/report/ (PNGs colour-quantised), and for the paper profile docs/results.md is rebuilt by the results_page
# app (its line 3, the run's provenance, kept from HEAD). Prints the table and the trajectory check (runs of
# switches that train as the full robust recipe, against it: near 0 = same Sim set and code across sessions).
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: recipe_merge.sh RUNS.tgz [RUNS.tgz ...]" >&2; exit 2; }
profile=${PROFILE:-paper}
conf="conf/workflow/$profile.yaml"
[ -f "$conf" ] || { echo "recipe_merge: no $conf (PROFILE=$profile?)" >&2; exit 2; }
py=${PYTHON:-python3}
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}"
for tgz in "$@"; do
  [ -f "$tgz" ] || { echo "recipe_merge: $tgz not found" >&2; exit 2; }
  bad=$(tar tzf "$tgz" | grep -vE '^results/recipe/(reference|robust)/[a-z_]+/[A-Za-z-]+/L[0-9]+/seed[0-9]+/(metrics\.json|scores\.npz|pr\.npz)$' || true)
  [ -z "$bad" ] || { echo "recipe_merge: $tgz holds files other than recipe runs, e.g. $(echo "$bad" | head -1)" >&2; exit 2; }
  replaced=$(tar tzf "$tgz" | grep 'metrics\.json$' | while read -r f; do if [ -f "$f" ]; then echo "$f"; fi; done | wc -l)
  tar xzf "$tgz"
  echo "$tgz: $(tar tzf "$tgz" | grep -c 'metrics\.json$') runs ($replaced replaced runs already here)"
done
# the profile's ablation as Hydra list overrides, one a line (one owner: conf/workflow/<profile>.yaml)
mapfile -t args < <("$py" - "$conf" <<'EOF2'
import sys, yaml
t = yaml.safe_load(open(sys.argv[1]))["train"]
a = t["recipe_ablation"]
lst = lambda v: "[" + ",".join(map(str, v)) + "]"
for k in ("experiments", "seeds", "switches"):
    print(f"{k}={lst(a[k])}")
print(f"switch_experiments={lst(a.get('switch_experiments', a['experiments']))}")
print(f"clip_len={t['clip_len']}")
EOF2
)
[ "${#args[@]}" = 5 ] || { echo "recipe_merge: $conf has no train.recipe_ablation" >&2; exit 2; }
"$py" -m snakemake --workflow-profile "workflow/profiles/$profile" --cores 2 \
  results/data/silicone/silicone.npz results/data/meat/meat.npz > results/recipe_merge_data.log 2>&1 ||
  { tail -20 results/recipe_merge_data.log; echo "recipe_merge: the real test sets failed" >&2; exit 1; }
[ -n "${PARTIAL:-}" ] && args+=(partial=true "partial_reason='${PARTIAL}'")
"$py" -m palpation.apps.recipe_report "profile=$profile" runs_root=results/recipe out_dir=results/recipe/report \
  track=false "${args[@]}" > results/recipe_merge_report.log 2>&1 || { tail -5 results/recipe_merge_report.log; exit 1; }
rep=results/recipe/report
cat "$rep/recipe_ablation.csv"
"$py" -c "import json; r = json.load(open('$rep/recipe_report.json')); print('rows', len(r['rows']), 'partial', r['partial'],
'left out', len(r['left_out'])); [print('trajectory', k, v) for k, v in r.get('trajectory_checks', {}).items()]"
# the calibration cross-fitted between the real sets (rule recipe_crossfit; the results page reads it): complete
# tables only, as its rows need every seed of a row and of its partner
crossfit=0
if [ -z "${PARTIAL:-}" ]; then
  "$py" -m palpation.apps.recipe_crossfit "profile=$profile" runs_root=results/recipe out_dir=$rep "${args[@]}" \
    > results/recipe_merge_crossfit.log 2>&1 && crossfit=1 ||
    { tail -3 results/recipe_merge_crossfit.log; echo "recipe_merge: recipe_crossfit failed, docs keep theirs" >&2; }
else
  echo "recipe_merge: partial table, recipe_crossfit not run (docs/results/$profile keeps its copy, if any)"
fi
[ "${DOCS:-1}" = 1 ] || exit 0
mkdir -p "docs/results/$profile/recipe/report"
if [ "$crossfit" = 1 ]; then
  for f in recipe_calibration_crossfit.csv recipe_calibration_crossfit.json reliability_crossfit.png; do
    cp "$rep/$f" "docs/results/$profile/recipe/report/$f"
  done
  "$py" -c "import sys; from PIL import Image; p = sys.argv[1]
Image.open(p).convert('RGB').quantize(colors=256).save(p, optimize=True)" \
    "docs/results/$profile/recipe/report/reliability_crossfit.png"
  [ "$profile" != paper ] || cp "$rep/recipe_calibration_crossfit.csv" docs/results/
fi
for f in recipe_ablation.csv recipe_ablation.md recipe_report.json reliability.png uncertainty.csv uncertainty_maps.png; do
  cp "$rep/$f" "docs/results/$profile/recipe/report/$f"
done
# the committed PNGs are colour-quantised to keep the repository small (as the other docs/results figures)
"$py" -c "import sys; from PIL import Image
for p in sys.argv[1:]: Image.open(p).convert('RGB').quantize(colors=256).save(p, optimize=True)" \
  "docs/results/$profile/recipe/report/reliability.png" "docs/results/$profile/recipe/report/uncertainty_maps.png"
if [ "$profile" = paper ]; then  # docs/results/*.csv and the page are the paper profile's
  cp "$rep/recipe_ablation.csv" "$rep/uncertainty.csv" docs/results/
  "$py" -m palpation.apps.results_page root=docs/results/paper out=docs/results.md links=results/paper profile=paper \
    track=false > results/recipe_merge_page.log 2>&1 || { tail -5 results/recipe_merge_page.log; exit 1; }
  line3=$(git show HEAD:docs/results.md | sed -n 3p)
  LINE3="$line3" "$py" -c "import os; p = 'docs/results.md'; lines = open(p).read().split('\n')
lines[2] = os.environ['LINE3']; open(p, 'w').write('\n'.join(lines))"
  echo "docs/results.md rebuilt (line 3 kept from HEAD); git diff --stat:"; git diff --stat -- docs/results.md docs/results
fi
