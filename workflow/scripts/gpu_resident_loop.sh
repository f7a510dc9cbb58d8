#!/usr/bin/env bash
# Issue 17: the frame-resident kernel on the residual loop's twin calls (the layered elastic kernel: per-tet
# shell, per-env damping) on one CUDA card, in one call of <= 5 min (LIMIT_S, default 290 s in all). Machine set
# up as for gpu_loop_selftest.sh (wheels on PYTHONPATH; carry results/twin/mesh_reference.* and results/data/photos):
# 1. agreement: layered streamed vs layered resident on cuda:0, the five agreement trajectories at full length,
#    reference mesh (`palpation.twin.agreement --layered`; aim <= 0.01 px, the plain kernel's is 0.0005 px),
#    <= 120 s; skipped once OUTDIR/agreement_layered.json exists;
# 2. the paper real-photo loop (docs/loop.md: loop=paper twin/mesh=reference) with twin.integrator.kernel=KERNEL
#    (default auto: the resident kernel on CUDA), detached (workflow/scripts/device_run.sh): if it is not done
#    within the call, the same command again re-attaches (exit 75 while it runs). Its log's line "loop real done
#    in W s (N distinct envs simulated in C twin calls, T s in the twin)" is the figure; loop_real.csv is
#    compared with the committed paper run (float rounding of the twin may change the search's path).
#    Baseline: KERNEL=streamed on the same warm card (a second call; its own folder), else docs' records
#    (H200: ~220 s wall with ~166 s in the twin; 159 s in docs/loop.md's null_converge run).
#   bash workflow/scripts/gpu_resident_loop.sh OUTDIR; cp OUTDIR/*.json OUTDIR/*.log OUTDIR/loop_*/loop_real.csv $OUT/
# MODE=probe instead (a call of ~2-3 min): where the resident kernel starts to beat the streamed one at the loop's
# batch sizes (few envs leave most SMs idle: one block an env), the layered benchmark at N_ENVS (8 32 128 264),
# 40 frames, both kernels; sets twin.integrator.auto_min_envs from a measurement.
# A CPU smoke run (coarse mesh, the tiny loop; auto = streamed on the CPU):
#   DEVICE=cpu MESH=results/twin/mesh_coarse.npz TWIN_MESH=coarse LOOP=tiny AGREE_ARGS="--max-frames 5" bash ... /tmp/o
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/device_run.sh"
out=${1:?usage: gpu_resident_loop.sh OUTDIR}
dev=${DEVICE:-cuda:0}
mesh=${MESH:-results/twin/mesh_reference.npz}
measured=${MEASURED:-results/data/photos/measured_photos}
kernel=${KERNEL:-auto}
loop=${LOOP:-paper}  # conf/loop/*.yaml
twin_mesh=${TWIN_MESH:-reference}  # conf/twin/mesh/*.yaml, matching MESH
limit=${LIMIT_S:-290}
for f in "$mesh" $([ "${MODE:-loop}" = probe ] || echo "$measured.npz $measured.json"); do
  [ -f "$f" ] || { echo "gpu_resident_loop: $f missing: carry it (results/twin, results/data/photos)" >&2; exit 2; }
done
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
py=${PY:-python3}
mkdir -p "$out"
nvidia-smi --query-gpu=name,clocks.max.sm --format=csv,noheader 2>/dev/null | head -1
if [ "${MODE:-loop}" = probe ]; then
  for k in streamed resident; do
    # shellcheck disable=SC2086
    timeout 150 $py -m palpation.twin.benchmark --device "$dev" --mesh-dir "$(dirname "$mesh")" --kernel "$k" \
      --resolutions "$(basename "$mesh" .npz | sed 's/^mesh_//')" --layered --n-envs ${N_ENVS:-8 32 128 264} \
      --max-frames 40 --out "$out/probe_$k.json" > "$out/probe_$k.log" 2>&1 || echo "probe $k: exit $?"
  done
  $py -c "import json, sys
for k in ('streamed', 'resident'):
    for r in json.load(open(f'{sys.argv[1]}/probe_{k}.json')):
        print(k, 'n_envs', r['n_envs'], 'ms a frame', round(1e3 * r['substeps_per_frame'] / r['substeps_per_s'], 2),
              'core_substep_us', round(r['core_substep_us'], 1), r['device'])" "$out"
  echo "probe done after ${SECONDS} s"
  exit 0
fi
name=loop_$kernel
if device_attach "$out" "$name"; then
  :
elif [ -f "$out/$name.rc" ]; then  # finished in an earlier call: report it (a new OUTDIR runs it again)
  DEVICE_PID=
else
  device_check_warp gpu_resident_loop "${dev%%:*}" hydra optuna || exit 3
  if [ ! -f "$out/agreement_layered.json" ]; then
    # shellcheck disable=SC2086
    timeout 120 $py -m palpation.twin.agreement --mesh "$mesh" --devices "$dev" --kernels streamed resident \
      --layered --out "$out/agreement_layered.json" ${AGREE_ARGS:-} > "$out/agreement_layered.log" 2>&1
    echo "agreement (exit $?, after ${SECONDS} s): $(tail -1 "$out/agreement_layered.log")"
  fi
  rm -rf "$out/$name"  # a fresh study: a resumed one would time only what is left
  # shellcheck disable=SC2086
  device_start "$out" "$name" $py -m palpation.apps.loop loop="$loop" twin/mesh="$twin_mesh" mesh="$mesh" \
    measured="$measured" twin.device="${dev%%:*}" twin.integrator.kernel="$kernel" track=false progress=false \
    loop.search.ask_workers="${ASK_WORKERS:-$(nproc)}" out.dir="$out/$name" hydra.run.dir="$out/$name/hydra" \
    ${LOOP_ARGS:-}
fi
echo "loop, twin.integrator.kernel=$kernel:"
LIMIT_S=$(( limit - SECONDS > 30 ? limit - SECONDS : 30 )) device_wait "$out" "$name"
grep -E "done in|Error|error" "$out/$name.log" | tail -3
if [ -f "$out/$name/loop_real.csv" ]; then
  cat "$out/$name/loop_real.csv"
  ref=docs/results/paper/loop/loop_real.csv
  [ "$loop" = paper ] && [ -z "${LOOP_ARGS:-}" ] && { cmp -s "$ref" "$out/$name/loop_real.csv" && echo "loop_real.csv: identical to $ref" \
    || echo "loop_real.csv differs from $ref (above; $ref: $(tail -1 "$ref"))"; }
fi
exit "$DEVICE_RC"
