"""The render_twin app: figure and one MP4 per trajectory listed in the manifests; bad input named."""

import numpy as np
import pytest
from omegaconf import OmegaConf

from palpation.apps import render_twin
from palpation.graph.layout import rest_layout
from palpation.twin.output import TrajectoryRecord, write_outputs


def record(name: str, frames: int = 4) -> TrajectoryRecord:
    rest = rest_layout("ideal").astype(np.float32)
    shift = np.linspace(0, 6, frames, dtype=np.float32)[:, None, None]  # markers slide by up to 6 px
    return TrajectoryRecord(
        name=name, kind="press", seed=0, params={"E": 1.0}, markers=rest[None] + shift,
        labels=np.zeros((frames, 127), np.int8), centreline_px=np.zeros((frames, 50, 2), np.float32),
        contact=np.ones(frames, bool), T_BA=np.tile(np.eye(4), (frames, 1, 1)),
        frame_index=np.arange(frames, dtype=np.int32), centreline_A=np.zeros((50, 3)), rest_markers_px=rest)


def test_render_writes_figure_and_videos(tmp_path):
    write_outputs(tmp_path / "canonical", [record("press"), record("slide")], [])
    cfg = OmegaConf.create({"manifests": [str(tmp_path / "canonical" / "manifest.json")],
                            "out": {"dir": str(tmp_path / "render")}})
    written = render_twin.run(cfg)
    names = sorted(p.name for p in written)
    assert names == ["canonical_press.mp4", "canonical_slide.mp4", "markers.pdf", "markers.png"]
    assert all(p.stat().st_size > 1000 for p in written)


def test_missing_manifest_is_named(tmp_path):
    cfg = OmegaConf.create({"manifests": [str(tmp_path / "none" / "manifest.json")], "out": {"dir": str(tmp_path)}})
    with pytest.raises(FileNotFoundError, match="none/manifest.json not found; run the simulate stage"):
        render_twin.run(cfg)


def test_empty_manifest_list_is_refused(tmp_path):
    with pytest.raises(ValueError, match="manifests"):
        render_twin.run(OmegaConf.create({"manifests": [], "out": {"dir": str(tmp_path)}}))
