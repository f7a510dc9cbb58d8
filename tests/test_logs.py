"""Logs a user reads: progress as plain lines in a file, no CPU-only CUDA warning from Warp."""

import io
import subprocess
import sys

from palpation.progress import LineProgress, bar


def test_bar_into_a_file_writes_plain_lines(monkeypatch):
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    progress = bar(range(4), desc="frames", mininterval=0, leave=False, file=log)
    assert isinstance(progress, LineProgress)
    assert list(progress) == [0, 1, 2, 3]
    text = log.getvalue()
    assert "\r" not in text and "\x1b" not in text
    lines = text.splitlines()
    assert lines[0].startswith("frames:   0%") and lines[-1].startswith("frames: 100%")
    assert text.endswith("\n") and "" not in lines


def test_disabled_bar_writes_nothing(monkeypatch):
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    for _ in bar(range(3), enabled=False, file=log):
        pass
    assert log.getvalue() == ""


def test_warp_starts_without_the_cpu_only_driver_warning():
    start = "from palpation.twin.warp_runtime import init_warp; init_warp(); init_warp()"
    done = subprocess.run([sys.executable, "-c", start], capture_output=True, check=True)
    assert b"Could not find or load the NVIDIA CUDA driver" not in done.stderr
    assert b"Warp 1.19" in done.stdout  # Warp's own banner is kept


def test_app_help_is_the_apps_own_text():
    shown = subprocess.run([sys.executable, "-m", "palpation.apps.train", "--help"],
                           capture_output=True, text=True, check=True).stdout
    assert shown.startswith("palpation.apps.train: Hydra entry point: train one ST-GNN")
    groups = shown.split("== Config groups it composes")[1].split("== Options")[0]
    assert "model=large" in groups and "recipe=reference" in groups
    assert "hydra/" not in groups and "base_vessel_maps" not in shown  # no other app's or Hydra's groups
    assert "seed: 42" in shown
