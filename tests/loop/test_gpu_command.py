"""The GPU self-test command (workflow/scripts/gpu_loop_selftest.sh) composes, and the app needs no gmsh."""

import re
import subprocess
import sys

from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import palpation.apps.loop  # noqa: F401  (registers the structured configs the loop config extends)
from palpation.paths import REPO_ROOT

SCRIPT = REPO_ROOT / "workflow" / "scripts" / "gpu_loop_selftest.sh"


def _loop(overrides):
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="loop", overrides=overrides)
    return OmegaConf.to_object(cfg.loop).validate()


def test_the_scripts_overrides_compose_and_validate():
    text = SCRIPT.read_text()
    keys = re.findall(r"\b((?:twin|loop)\.[\w.]+)=", text)
    assert {"twin.device", "loop.selftest.runs_per_case", "loop.split_by_kind", "loop.search.ask_workers"} <= set(keys)
    assert not [k for k in keys if k.startswith("loop.method")]  # the GPU self-test runs the users' loop
    values = {"twin.device": "cuda", "loop.selftest.runs_per_case": "5", "loop.split_by_kind": "false",
              "loop.search.ask_workers": "16", "loop.generative.split": "dev", "loop.generative.runs": "60"}
    loop = _loop(["mode=selftest", *(f"{k}={values[k]}" for k in keys)])
    assert len(loop.selftest.cases) * loop.selftest.runs_per_case >= 60 and not loop.split("cuda")
    assert loop.search.ask_workers == 16


def test_profiles_differ_only_in_size():
    """One loop: quick, paper and the base config share the method; profiles set sizes (search, self-test sets)."""
    base, quick, paper = (_loop([f"loop={name}"]) for name in ("base_loop", "quick", "paper"))
    assert quick.method == paper.method == base.method
    for key in ("effects", "holdout", "max_rounds", "noise_px", "states"):
        assert getattr(quick, key) == getattr(paper, key) == getattr(base, key), key
    assert paper.search.n_trials > quick.search.n_trials  # a size


def test_loop_app_imports_without_gmsh():
    code = ("import sys; sys.modules['gmsh'] = None; import palpation.apps.loop, palpation.loop.selftest.fixed; "
            "from palpation.twin.mesh import SensorMesh; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
