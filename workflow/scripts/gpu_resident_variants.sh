#!/usr/bin/env bash
# The frame-resident kernel's variants (issue 17, twin.integrator.resident_variant) on one CUDA card,
# in one call of at most 8 minutes (points start before 260 s, each <= 120 s; the fastest point's
# agreement <= 100 s; typically ~6 min), machine set up as for gpu_twin_checks.sh, meshes from results/twin:
# 1. the benchmark, 500 reference envs, a full 398-frame slide batch per variant and block size (aim:
#    <= 15 s), one process each, the first version ("tiles", 18.9 s on an H200) rerun as the baseline;
# 2. markers of the fastest variant vs the streamed kernels on cuda:0, the five agreement trajectories at
#    full length (aim: <= 0.01 px), then of the other variants while the time lasts;
# 3. with BASELINE=1, the streamed path's same point (38.1 s on an H200).
#   bash workflow/scripts/gpu_resident_variants.sh OUTDIR
# Prints one line per variant: full-batch seconds and core microseconds a substep. A CPU smoke run:
#   DEVICE=cpu RESOLUTION=coarse N_ENVS=1 AGREE_ARGS="--max-frames 5" bash ... /tmp/out
set -uo pipefail
out=${1:-results/bench}
mesh_dir=${MESH_DIR:-results/twin}
dev=${DEVICE:-cuda:0}
res=${RESOLUTION:-reference}
# VARIANT[:COLORING]@BLOCK_DIM, most telling first; "compact" fits two blocks an SM (<= 384 threads)
points=${POINTS:-packed@512 tiles@512 compact@320 atomic@512 compact@384 compact_atomic@384 compact@256 packed:largest_first@512 onesync@512}
bench_until=${BENCH_UNTIL_S:-260}  # start no benchmark point after this many seconds
budget_s=${BUDGET_S:-440}  # start no agreement run after this many seconds
mkdir -p "$out"
[ -f "$mesh_dir/mesh_$res.npz" ] || { echo "gpu_resident_variants: $mesh_dir/mesh_$res.npz missing:" \
  "carry results/twin or set MESH_DIR" >&2; exit 2; }
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
py=${PY:-python3}
nvidia-smi --query-gpu=name,clocks.max.sm --format=csv,noheader 2>/dev/null | head -1
for pt in $points; do
  [ "$SECONDS" -lt "$bench_until" ] || { echo "benchmark $pt: skipped at ${SECONDS} s"; continue; }
  # shellcheck disable=SC2086
  timeout 120 $py -m palpation.twin.benchmark --device "$dev" --mesh-dir "$mesh_dir" --kernel resident \
    --resolutions "$res" --n-envs ${N_ENVS:-500} --block-dim "${pt#*@}" --variants "${pt%@*}" \
    --out "$out/bench_${pt//[:@]/_}.json" >> "$out/benchmark_variants.log" 2>&1 || echo "benchmark $pt: exit $?"
done
echo "benchmarks done after ${SECONDS} s (log: benchmark_variants.log)"
$py -c "import glob, json, sys; json.dump([r for f in sorted(glob.glob(sys.argv[1] + '/bench_*.json'))
for r in json.load(open(f))], open(sys.argv[1] + '/twin_resident_variants.json', 'w'), indent=1)" "$out"
# one line per variant, fastest first; the ranking drives the agreement runs below
$py - "$out/twin_resident_variants.json" > "$out/ranking.txt" <<'EOF'
import json, sys
recs = sorted(json.load(open(sys.argv[1])), key=lambda r: r.get("wall_s_measured", float("inf")))
for r in recs:
    v = f"{r['resident_variant']}:{r['resident_coloring']}@{r['block_dim']}"
    print(v, f"block_dim {r['block_dim']} n_envs {r['n_envs']} wall_s {r.get('wall_s_measured', float('nan')):.2f}",
          f"core_substep_us {r['core_substep_us']:.1f} roofline {r['roofline_fraction_streamed']:.3f}", r["device"])
EOF
cat "$out/ranking.txt"
for pt in $(cut -d' ' -f1 "$out/ranking.txt"); do
  v=${pt%@*}
  [ "${v%%:*}" = tiles ] && continue  # measured before: 0.0005 px (docs/twin.md)
  left=$((budget_s - SECONDS))
  if [ -z "${agreed:-}" ] && [ "$left" -lt 100 ]; then left=100; fi  # the fastest one always runs
  [ "$left" -gt 45 ] || { echo "agreement $v: skipped, ${left} s left"; continue; }
  agreed=1
  # shellcheck disable=SC2086
  timeout "$left" $py -m palpation.twin.agreement --mesh "$mesh_dir/mesh_$res.npz" --devices "$dev" \
    --kernels streamed resident --variant "$v" --block-dim "${pt#*@}" --out "$out/agreement_${pt//[:@]/_}.json" \
    ${AGREE_ARGS:-} 2>&1 | tail -1
done
if [ "${BASELINE:-0}" = 1 ]; then  # the streamed path's same point on the same card (~45 s more)
  # shellcheck disable=SC2086
  $py -m palpation.twin.benchmark --device "$dev" --mesh-dir "$mesh_dir" --resolutions "$res" \
    --n-envs ${N_ENVS:-500} --out "$out/twin_streamed.json" 2>&1 | grep -o '"wall_s_measured": [0-9.]*'
fi
echo "done after ${SECONDS} s"
