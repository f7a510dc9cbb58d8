#!/usr/bin/env bash
# The frame-resident twin kernel (issue 17) on a CUDA machine set up as for gpu_twin_checks.sh:
# 1. markers of the resident kernel vs the streamed kernels on cuda:0, the five agreement
#    trajectories at full length on the reference mesh (aim: <= 0.01 px);
# 2. the benchmark: 500 reference envs, a full 398-frame slide batch per block size (aim: <= 15 s);
# 3. with BASELINE=1, the streamed path's same point on the same card (46.1 s on an H100 at 60418b8).
#   bash workflow/scripts/gpu_resident_checks.sh OUTDIR
set -uo pipefail
out=${1:-results/bench}
mesh_dir=${MESH_DIR:-results/twin}
mkdir -p "$out"
[ -f "$mesh_dir/mesh_reference.npz" ] || { echo "gpu_resident_checks: $mesh_dir/mesh_reference.npz missing:" \
  "carry results/twin or set MESH_DIR" >&2; exit 2; }
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
py=${PY:-python3}
$py -m palpation.twin.agreement --mesh "$mesh_dir/mesh_reference.npz" --devices cuda:0 \
  --kernels streamed resident --out "$out/agreement_resident.json" 2>&1 | tail -1
# shellcheck disable=SC2086
$py -m palpation.twin.benchmark --device cuda:0 --mesh-dir "$mesh_dir" --kernel resident \
  --resolutions reference --n-envs ${N_ENVS:-500} --block-dim ${BLOCK_DIMS:-512 256} \
  --out "$out/twin_resident.json" > "$out/benchmark_resident.log" 2>&1
echo "benchmark exit $?"
$py -c "import json,sys; [print(r['kernel'], r.get('block_dim'), r['n_envs'], 'wall_s', r.get('wall_s_measured'),
'core_substep_us', round(r['core_substep_us'], 1), 'roofline', round(r['roofline_fraction_streamed'], 3))
for r in json.load(open(sys.argv[1]))]" "$out/twin_resident.json"
if [ "${BASELINE:-0}" = 1 ]; then
  # shellcheck disable=SC2086
  $py -m palpation.twin.benchmark --device cuda:0 --mesh-dir "$mesh_dir" --resolutions reference \
    --n-envs ${N_ENVS:-500} --out "$out/twin_streamed.json" 2>&1 | grep -o '"wall_s_measured": [0-9.]*'
fi
