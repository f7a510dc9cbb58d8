#!/usr/bin/env bash
# Twin checks on a CUDA machine: device-parametrised twin tests, CPU/CUDA marker agreement and the
# throughput benchmark. Needs the cached meshes (rule `mesh`) and an environment with warp-lang.
#   bash workflow/scripts/gpu_twin_checks.sh OUTDIR
set -uo pipefail
out=${1:-results/bench}
mkdir -p "$out"
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
python3 -c "import warp as wp; wp.init(); print(wp.get_cuda_devices())"
python3 -m pytest -q -p no:cacheprovider tests/twin 2>&1 | tail -15
for res in coarse reference; do
  python3 -m palpation.twin.agreement --mesh results/twin/mesh_$res.npz --devices cpu cuda:0 \
    --out "$out/agreement_$res.json" 2>&1 | tail -1
done
python3 -m palpation.twin.benchmark --device cuda:0 --out "$out/twin_cuda.json" 2>&1 | tail -20
