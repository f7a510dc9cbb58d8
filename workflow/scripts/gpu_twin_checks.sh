#!/usr/bin/env bash
# Twin checks on a CUDA machine (set it up with `make setup-gpu`): the throughput benchmark (every
# point a full 398-frame slide batch), CPU/CUDA marker agreement and the device-parametrised twin tests.
# Needs no gmsh: the meshes come from MESH_DIR (default results/twin, rule `mesh` run elsewhere);
# only the tests that build a mesh are skipped.
#   bash workflow/scripts/gpu_twin_checks.sh OUTDIR
# BENCH_ARGS (e.g. "--resolutions reference --n-envs 500", or "skip") and AGREE_ARGS ("--max-frames 100")
# narrow the run when device time is short.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/device_run.sh"  # device_check_warp
out=${1:-results/bench}
mesh_dir=${MESH_DIR:-results/twin}
mkdir -p "$out"
for res in coarse reference; do
  [ -f "$mesh_dir/mesh_$res.npz" ] || { echo "gpu_twin_checks: $mesh_dir/mesh_$res.npz missing:" \
    "run \`snakemake results/twin/mesh_$res.npz\` where gmsh is, copy it here or set MESH_DIR" >&2; exit 2; }
done
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1 PALPATION_MESH_CACHE="$mesh_dir"
device_check_warp gpu_twin_checks cpu  # no exit: the checks below report their own failures
if [ "${BENCH_ARGS:-}" != skip ]; then
  # shellcheck disable=SC2086
  python3 -m palpation.twin.benchmark --device cuda:0 --mesh-dir "$mesh_dir" ${BENCH_ARGS:-} \
    --out "$out/twin_cuda.json" > "$out/benchmark.log" 2>&1; echo "benchmark exit $?"; tail -3 "$out/benchmark.log"
fi
for res in coarse reference; do
  python3 -m palpation.twin.agreement --mesh "$mesh_dir/mesh_$res.npz" --devices cpu cuda:0 ${AGREE_ARGS:-} \
    --out "$out/agreement_$res.json" 2>&1 | tail -1
done
python3 -m pytest -q -p no:cacheprovider tests/twin 2>&1 | tee "$out/pytest_twin.log" | tail -15
