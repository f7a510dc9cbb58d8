"""workflow/scripts/gpu_resident_loop.sh (issue 17, run on a GPU): its loop command composes, and the twin it runs
is the layered one that `kernel: auto` makes resident on CUDA (for batches of at least auto_min_envs envs)."""

import re

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import palpation.apps.loop  # noqa: F401  (registers the structured configs the loop config extends)
from palpation.loop.simulate import loop_twin_config
from palpation.paths import REPO_ROOT
from palpation.twin.config import TwinConfig
from palpation.twin.resident import runs_resident

SCRIPT = REPO_ROOT / "workflow" / "scripts" / "gpu_resident_loop.sh"


def test_the_loop_command_composes_to_a_layered_auto_twin(monkeypatch):
    text = SCRIPT.read_text()
    keys = re.findall(r" (twin\.[\w.]+|loop\.[\w.]+)=", text)
    assert {"twin.device", "twin.integrator.kernel", "loop.search.ask_workers"} <= set(keys)
    assert 'loop="$loop" twin/mesh="$twin_mesh"' in text and "loop=${LOOP:-paper}" in text
    values = {"twin.device": "cuda", "twin.integrator.kernel": "auto", "loop.search.ask_workers": "16"}
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="loop", overrides=["loop=paper", "twin/mesh=reference",
                                                     *(f"{k}={values[k]}" for k in keys)])
    twin: TwinConfig = OmegaConf.to_object(cfg.twin)
    loop = OmegaConf.to_object(cfg.loop).validate()
    tw = loop_twin_config(twin, loop.shell_thickness_mm * 1e-3)
    assert tw.layered and tw.integrator.kernel == "auto" and twin.mesh.resolution == "reference"
    gpu = type("Gpu", (), {"is_cuda": True, "max_shared_memory_per_block": 232_448})()  # an H100's
    monkeypatch.setattr("palpation.twin.resident.wp.get_device", lambda device=None: gpu)
    need = np.ones(3435, bool)  # the reference mesh's nodes (their force flags only size the tiles)
    # resident from auto_min_envs (100); the paper loop's calls (~15 envs) stay streamed
    assert runs_resident(tw, need, "cuda", 100) and not runs_resident(tw, need, "cuda", 16)
