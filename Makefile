# Two entry points for a fresh machine (see README):
#   make reproduce   set up the venv from environment.lock and run the quick reproduction
#   make test        set up the venv and run the test suite
VENV ?= .venv
PY := $(VENV)/bin/python
export PATH := $(abspath $(VENV))/bin:$(PATH)
CORES ?= 2

.PHONY: setup setup-gpu reproduce test lock bench paper

$(VENV)/.installed: environment.lock pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r environment.lock
	$(PY) -m pip install -q --no-deps -e .
	touch $@

setup: $(VENV)/.installed

# A CUDA machine whose python already holds a CUDA torch: install the project and every other pinned
# package of environment.lock into that python WITHOUT touching torch (the lock's torch line is dropped
# from the constraints; pyproject's unpinned `torch` is then already satisfied). Offline:
#   make setup-gpu PIP_ARGS="--no-index --find-links /path/to/wheels"
GPU_PY ?= python3
setup-gpu:
	grep -v -E '^torch==' environment.lock > .gpu-constraints.txt
	$(GPU_PY) -m pip install $(PIP_ARGS) -c .gpu-constraints.txt -e ".[test]"
	$(GPU_PY) -c "import torch, warp as wp, hydra, omegaconf; wp.init(); print('torch', torch.__version__, 'cuda', torch.cuda.is_available(), 'warp', wp.__version__, wp.get_cuda_devices())"

reproduce: setup
	snakemake --cores $(CORES)

test: setup
	$(PY) -m pytest -q

bench: setup
	snakemake --cores $(CORES) bench

# Rebuild environment.lock from pyproject's direct dependencies (torch pinned to the CPU build).
lock:
	rm -rf .venv-lock && python3 -m venv .venv-lock
	.venv-lock/bin/pip install -q torch==2.13.0 "mlflow==3.17.2" -e ".[test]" snakemake-executor-plugin-slurm
	{ echo "# Every package of the project's environment, pinned (pip freeze of a working venv, Python 3.11)."; \
	  echo "# Regenerate: make lock   (fresh venv from pyproject's direct deps, then pip freeze; torch pinned to 2.13.0)"; \
	  .venv-lock/bin/pip freeze --exclude-editable | sed 's/^torch==\(.*\)+cpu/torch==\1/'; } > environment.lock
	rm -rf .venv-lock
