#!/usr/bin/env bash
# The residual loop's full self-test (issue 13: 12 cases x RUNS runs, default 5 = 60) on a CUDA machine, in one
# process: all runs advance as one twin batch per call (loop.split_by_kind=false), the Optuna proposals of
# all runs' studies come from ASK_WORKERS processes. Needs no gmsh: the mesh is read from MESH (default
# results/twin/mesh_coarse.npz) and the states' geometry from the photo set MEASURED (default
# results/data/photos/measured_photos, .npz + .json; rule measured_photos run elsewhere).
#   bash workflow/scripts/gpu_loop_selftest.sh OUTDIR [extra Hydra overrides...]
# Copy OUTDIR/loop_selftest.csv and selftest.md to docs/results/ afterwards. The run is detached
# (workflow/scripts/device_run.sh): it outlives the command, LIMIT_S (default: until done) is how long a call
# waits (exit 75: still running), and the same command again re-attaches (OUTDIR/selftest.pid). A killed run
# resumes (the sets are re-made from the seed, the studies continue in OUTDIR/selftest/study.journal).
# On the lent device (10 min per command; $OUT is emptied before each), until it exits 0:
#   LIMIT_S=560 bash workflow/scripts/gpu_loop_selftest.sh results/loop_gpu; cp results/loop_gpu/*.{csv,md,json,log} $OUT/
# MODE=generative: the generative self-test (loop.selftest.generative) at loop=PRESET sizes (default paper) instead, split
# SPLIT (dev, or test once at the end) with RUNS drawn runs per seed (default 60); finished runs are kept in
# OUTDIR/generative/runs and skipped by the same command again. Writes OUTDIR/loop_selftest_general.csv and
# selftest_general.{md,json}:
#   MODE=generative SPLIT=dev LIMIT_S=560 bash workflow/scripts/gpu_loop_selftest.sh results/loop_gen
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/device_run.sh"
out=${1:?usage: gpu_loop_selftest.sh OUTDIR [overrides...]}; shift
mesh=${MESH:-results/twin/mesh_coarse.npz}
measured=${MEASURED:-results/data/photos/measured_photos}
for f in "$mesh" "$measured.npz" "$measured.json"; do
  [ -f "$f" ] || { echo "gpu_loop_selftest: $f missing: make it where gmsh/the photos are (snakemake $f) and" \
    "carry it" >&2; exit 2; }
done
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
mkdir -p "$out"
case "${MODE:-selftest}" in
  selftest) name=selftest md=selftest.md head=9 sizes=(mode=selftest loop.selftest.runs_per_case="${RUNS:-5}") ;;
  generative) name=generative md=selftest_general.md head=16
    sizes=(mode=generative loop="${PRESET:-paper}" loop.generative.split="${SPLIT:-dev}"
           loop.generative.runs="${RUNS:-60}") ;;
  *) echo "gpu_loop_selftest: MODE must be selftest or generative, got '$MODE'" >&2; exit 2 ;;
esac
if ! device_attach "$out" "$name"; then
  device_check_warp gpu_loop_selftest cpu hydra optuna || exit 3
  device_start "$out" "$name" python3 -m palpation.apps.loop "${sizes[@]}" track=false progress=false twin.device=cuda \
    mesh="$mesh" measured="$measured" loop.split_by_kind=false \
    loop.search.ask_workers="${ASK_WORKERS:-$(nproc)}" out.dir="$out" \
    hydra.run.dir="$out/hydra" "$@"
fi
echo "loop self-test ($name):"
device_wait "$out" "$name"
grep -E "done in|Error|error" "$out/$name.log" | tail -3
[ -f "$out/$md" ] && sed -n "3,${head}p" "$out/$md"
exit $DEVICE_RC
