#!/usr/bin/env bash
# Issue 12's downstream judge at the paper profile on a CUDA machine (docs/loop.md "Twin on the task",
# "Paper-profile run"): the slide loop, the candidate twins' replays, Sim sets and A-to-B / A-to-C runs, the
# table. Only the jobs these targets need run (no maps, no recipe/clip-length ablations); every seed of a
# candidate trains in one process (train.seeds_together). Needs no gmsh: carry results/twin/mesh_<res>.npz/.json
# (reference for paper) and results/data/photos; everything else the DAG rebuilds from the repo.
#   [PROFILE=paper] [LIMIT_S=0] [CORES=nproc] bash workflow/scripts/gpu_judge.sh OUTDIR [snakemake args...]
# Resumable: OUTDIR and results/ survive on a warm machine and the same command continues the DAG (a job
# cut short by LIMIT_S reruns). In the foreground keep LIMIT_S below the device's 600 s per command;
# in the background give none and poll:
#   setsid nohup bash workflow/scripts/gpu_judge.sh results/judge_gpu > /tmp/judge.out 2>&1 &
#   cat /tmp/judge.out; tail -3 results/judge_gpu/snakemake.log      # poll; when done: cp results/judge_gpu/* $OUT/
# OUTDIR then holds twin_selection.csv and loop_slides.csv (copy both to docs/results/), twin_selection.md,
# slide_motion.png/.pdf, slide_loop.json (results page section "Twin on the task") and judge_logs.tgz.
set -uo pipefail
out=${1:?usage: gpu_judge.sh OUTDIR [snakemake args...]}; shift
profile=${PROFILE:-paper}
res=$(sed -n 's/^twin_resolution: *\([a-z]*\).*/\1/p' "conf/workflow/$profile.yaml")
[ -n "$res" ] || { echo "gpu_judge: conf/workflow/$profile.yaml has no twin_resolution (PROFILE=$profile?)" >&2; exit 2; }
for f in "results/twin/mesh_$res.npz" "results/twin/mesh_$res.json" results/data/photos/measured_photos.npz \
  results/data/photos/measured_photos.json; do
  [ -f "$f" ] || { echo "gpu_judge: $f missing: build it where gmsh is (snakemake $f) and carry it" >&2; exit 2; }
done
mkdir -p "$out"
pidf="$out/gpu_judge.pid"  # one run at a time: a second call while one runs only reports
if [ -f "$pidf" ] && kill -0 "$(cat "$pidf")" 2>/dev/null; then
  echo "gpu_judge: already running (pid $(cat "$pidf")); progress:"; grep -E "steps \(" "$out/snakemake.log" | tail -1
  exit 0
fi
echo $$ > "$pidf"
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
device=$(sed -n 's/^device: *\([a-z]*\).*/\1/p' "conf/workflow/$profile.yaml")
python3 -c "import sys, warp as wp, hydra, optuna, snakemake; wp.init(); print('warp', wp.__version__, wp.get_cuda_devices())
sys.exit('gpu_judge: the $profile profile runs on cuda, and Warp sees no CUDA device' if '$device' == 'cuda' \
and not wp.get_cuda_devices() else 0)" || { rm -f "$pidf"; exit 3; }
# the carried mesh must look newer than its conf so that rule mesh (gmsh) never reruns here; touched once only,
# so a resumed run does not see it change under the jobs already done
for c in conf/mesh.yaml "conf/twin/mesh/$res.yaml"; do
  [ "$c" -nt "results/twin/mesh_$res.npz" ] && touch "results/twin/mesh_$res.npz" "results/twin/mesh_$res.json"
done
targets="results/judge/twin_selection.csv results/judge/twin_selection.md results/judge/slide_motion.png
  results/judge/slide_motion.pdf results/loop_slides/loop_slides.csv"
snake=(python3 -m snakemake --workflow-profile "workflow/profiles/$profile" --cores "${CORES:-$(nproc)}")
# another Snakemake run in this checkout (e.g. gpu_recipe_ablation.sh) holds the lock: unlocking would let both
# build the shared upstream files (Sim set, data sets) at once; the judge then needs its own copy of the checkout
if [ -n "$(ls -A .snakemake/locks 2>/dev/null)" ] && pgrep -f "snakemake --workflow-profile" > /dev/null; then
  echo "gpu_judge: another Snakemake run holds this checkout's lock; run the judge in its own copy of the checkout" \
    "(docs/loop.md, \"Paper-profile run\")" >&2
  rm -f "$pidf"; exit 4
fi
"${snake[@]}" --unlock > /dev/null 2>&1  # a run cut short keeps the lock; no other run is going (checked above)
start=$(date +%s)
touch "$out/snakemake.log"; seen=$(wc -l < "$out/snakemake.log")  # the log grows over resumed calls
# shellcheck disable=SC2086
timeout -s INT "${LIMIT_S:-0}" "${snake[@]}" --keep-going --rerun-incomplete $targets "$@" \
  >> "$out/snakemake.log" 2>&1
rc=$?
echo "gpu_judge ($profile) snakemake rc=$rc after $(( $(date +%s) - start )) s"
[ "$rc" = 124 ] && echo "stopped at LIMIT_S=$LIMIT_S s: run the same command again on this warm machine to resume"
tail -n +"$((seen + 1))" "$out/snakemake.log" | grep -E "steps \(|Nothing to be done|Error in rule|Exiting" | tail -4
for f in results/judge/twin_selection.csv results/judge/twin_selection.md results/judge/slide_motion.png \
  results/judge/slide_motion.pdf results/loop_slides/loop_slides.csv results/loop_slides/slide_loop.json; do
  if [ -f "$f" ]; then cp "$f" "$out/"; else rm -f "$out/$(basename "$f")"; fi  # no stale copy
done
tar czf "$out/judge_logs.tgz" results/logs results/judge/slides/*.json \
  $(ls results/judge/train/*/*/L*/seed*/metrics.json results/train/A-to-[BC]/L*/seed*/metrics.json 2>/dev/null) \
  2>/dev/null
[ -f "$out/twin_selection.csv" ] && cat "$out/twin_selection.csv"
rm -f "$pidf"
exit $rc
