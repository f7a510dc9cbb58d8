#!/usr/bin/env bash
# Issue 12's downstream judge at the paper profile on a CUDA machine (docs/slides.md "Twin on the task",
# "Paper-profile run"): the slide loop, the candidate twins' replays, Sim sets and A-to-B / A-to-C runs, the
# table. Only the jobs these targets need run (no maps, no recipe/clip-length ablations); every seed of a
# candidate trains in one process (train.seeds_together). Needs no gmsh: carry results/twin/mesh_<res>.npz/.json
# (reference for paper) and results/data/photos; everything else the DAG rebuilds from the repo.
#   [PROFILE=paper] [LIMIT_S=0] [CORES=nproc] bash workflow/scripts/gpu_judge.sh OUTDIR [snakemake args...]
# Resumable and detached (workflow/scripts/device_run.sh): Snakemake runs in its own process session and outlives
# the command; LIMIT_S (default: until done; keep it below the device's 600 s per command) is how long a call
# waits. The same command again re-attaches to the run still going (OUTDIR/snakemake.pid) or, once it ended,
# continues the DAG on a warm machine (OUTDIR and results/ survive; a job cut short reruns). Exit 0: done; 75:
# still running; else Snakemake's status. Poll: LIMIT_S=550 bash workflow/scripts/gpu_judge.sh results/judge_gpu
# until it exits 0, then cp results/judge_gpu/* $OUT/
# OUTDIR then holds twin_selection.csv and loop_slides.csv (copy both to docs/results/), twin_selection.md,
# slide_motion.png/.pdf, slide_loop.json (results page section "Twin on the task"), choice.json (rule twin_choice:
# the main Sim set's twin, docs/slides.md "Which twin makes the Sim set") and judge_logs.tgz.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/device_run.sh"  # the detached, resumable run (pid guard, unlock, LIMIT_S)
out=${1:?usage: gpu_judge.sh OUTDIR [snakemake args...]}; shift
profile=${PROFILE:-paper}
res=$(sed -n 's/^twin_resolution: *\([a-z]*\).*/\1/p' "conf/workflow/$profile.yaml")
[ -n "$res" ] || { echo "gpu_judge: conf/workflow/$profile.yaml has no twin_resolution (PROFILE=$profile?)" >&2; exit 2; }
for f in "results/twin/mesh_$res.npz" "results/twin/mesh_$res.json" results/data/photos/measured_photos.npz \
  results/data/photos/measured_photos.json; do
  [ -f "$f" ] || { echo "gpu_judge: $f missing: build it where gmsh is (snakemake $f) and carry it" >&2; exit 2; }
done
mkdir -p "$out"
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
targets="results/judge/twin_selection.csv results/judge/twin_selection.md results/judge/slide_motion.png
  results/judge/slide_motion.pdf results/judge/drift_bounds.csv results/loop_slides/loop_slides.csv"
if ! device_attach "$out" snakemake; then  # one run at a time: a second call waits for the one going
  device=$(sed -n 's/^device: *\([a-z]*\).*/\1/p' "conf/workflow/$profile.yaml")
  device_check_warp "gpu_judge: the $profile profile runs on cuda" "$device" hydra optuna snakemake || exit 3
  device_touch_mesh "$profile"
  # another Snakemake run in this checkout (e.g. gpu_recipe_ablation.sh) holds the lock: unlocking would let both
  # build the shared upstream files (Sim set, data sets) at once; the judge then needs its own copy of the checkout
  device_unlock gpu_judge "$profile"
  # shellcheck disable=SC2086
  device_start "$out" snakemake python3 -m snakemake --workflow-profile "workflow/profiles/$profile" \
    --cores "${CORES:-$(nproc)}" --keep-going --rerun-incomplete $targets "$@"
fi
echo "gpu_judge ($profile):"
device_wait "$out" snakemake
rc=$DEVICE_RC
device_progress "$out" snakemake
for f in results/judge/twin_selection.csv results/judge/twin_selection.md results/judge/slide_motion.png \
  results/judge/slide_motion.pdf results/judge/drift_bounds.csv results/loop_slides/loop_slides.csv results/loop_slides/slide_loop.json \
  results/judge/choice/choice.json; do
  if [ -f "$f" ]; then cp "$f" "$out/"; else rm -f "$out/$(basename "$f")"; fi  # no stale copy
done
tar czf "$out/judge_logs.tgz" results/logs results/judge/slides/*.json \
  $(ls results/judge/train/*/*/L*/seed*/metrics.json results/train/A-to-[BC]/L*/seed*/metrics.json 2>/dev/null) \
  2>/dev/null
[ -f "$out/twin_selection.csv" ] && cat "$out/twin_selection.csv"
exit $rc
