"""One name for the MLflow switch: `track`. The old `tracking` is refused in one line that names the new key."""

import subprocess
import sys

import pytest
from omegaconf import OmegaConf

from palpation.config_check import ConfigKeyError, check_argv, check_config
from palpation.paths import REPO_ROOT

APPS = tuple(sorted(p.stem for p in (REPO_ROOT / "conf").glob("*.yaml")))
TRACKED = {app for app in APPS if "track" in OmegaConf.load(REPO_ROOT / "conf" / f"{app}.yaml")}


def test_no_config_file_says_tracking():
    files = [p for p in (REPO_ROOT / "conf").rglob("*.yaml")
             if any(line.lstrip().startswith("tracking:") for line in p.read_text().splitlines())]
    assert files == []
    assert {"train", "vessel_maps", "recipe_report", "simulate", "calibrate"} <= TRACKED


@pytest.mark.parametrize("app", APPS)
def test_added_tracking_key_names_track(app, hydra_job):
    cfg = hydra_job(app, ["+tracking=false"])
    assert ("track" in cfg) == (app in TRACKED)
    with pytest.raises(ConfigKeyError) as info:
        check_config(cfg, app)
    msg = str(info.value)
    assert "\n" not in msg and "'tracking'" in msg and "'+tracking=false'" in msg
    assert ("use track=false" if app in TRACKED else "(the switch is called 'track'") in msg, msg


@pytest.mark.parametrize("arg", ["tracking=false", "+tracking=true", "++tracking=0", "~tracking"])
@pytest.mark.parametrize("app", ["train", "vessel_maps", "recipe_report", "render_twin"])
def test_command_line_is_checked_before_hydra(app, arg):
    with pytest.raises(ConfigKeyError, match="'tracking'.*'track'"):
        check_argv(app, ["seed=1", arg])


def test_other_arguments_pass():
    check_argv("train", ["track=false", "hydra.run.dir=tracking", "--multirun", "seed=0,1"])


@pytest.mark.parametrize("app, tracked", [("results_page", True), ("render_twin", False)])
def test_old_switch_on_the_command_line(app, tracked, tmp_path, fault):
    """`tracking=false` (the old name) on an app's command line: was Hydra's five lines hinting +tracking"""
    proc = subprocess.run([sys.executable, "-m", f"palpation.apps.{app}", "tracking=false"], capture_output=True,
                          text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 1 and list(tmp_path.iterdir()) == []
    fix = "use track=false" if tracked else "drop it"
    with fault(SystemExit, f"{app}: error: config key 'tracking'", fix):
        raise SystemExit(proc.stderr.strip())
