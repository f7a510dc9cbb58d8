#!/usr/bin/env bash
# Wheels the loop app needs on the CUDA device image (Python 3.12, torch/numpy/scipy/OpenCV/matplotlib/pandas
# already there) at environment.lock's versions, into DIR (default .whl; keep it git-ignored). warp-lang is
# too large for one carry: bring it with ../shared/tools/warp-wheel-parts.sh (.wparts) as before.
#   bash workflow/scripts/gpu_loop_wheels.sh [DIR]
# On the device:  python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site DIR/*.whl
set -euo pipefail
dir=${1:-.whl}
mkdir -p "$dir"
pins=$(grep -iE '^(hydra-core|omegaconf|optuna|colorlog|sqlalchemy|alembic|mako|greenlet)==' environment.lock)
# shellcheck disable=SC2086
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_24_x86_64 --platform manylinux_2_17_x86_64 \
  --platform manylinux2014_x86_64 -d "$dir" $pins
# antlr4-python3-runtime 4.9.3 (omegaconf's pin) ships no wheel: build the pure-Python one here
python3 -m pip wheel -q --no-deps -w "$dir" "$(grep -iE '^antlr4-python3-runtime==' environment.lock)"
ls "$dir"
