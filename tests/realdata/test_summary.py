"""Real-data summary table: both npz layouts, central-frame positive rate, missing or bad inputs."""

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.paths import REPO_ROOT
from palpation.realdata.summary import (
    COLUMNS,
    DatasetSpec,
    load_sequences,
    specs_from_mapping,
    summary_table,
    to_markdown,
)


def dense_set(path, n_trials=3, n_frames=16):
    """Silicone layout: (trials, T, 127, 2); label 1 only on the two first and last frames + one central."""
    labels = np.zeros((n_trials, n_frames, 127), np.int32)
    labels[:, :2] = 1
    labels[:, -2:] = 1
    if n_frames > 6:
        labels[:, 5, :10] = 1
        labels[0, 6, 0] = -1  # unknown: not counted
    np.savez(path, markers=np.zeros((n_trials, n_frames, 127, 2), np.float32), labels=labels)
    return path


def flat_set(path):
    """Meat layout: flat frames cut by trial_offsets (trials of 3 and 2 frames)."""
    labels = np.zeros((5, 127), np.int32)
    labels[0, :127] = 1
    np.savez(path, markers=np.zeros((5, 127, 2), np.float32), labels=labels,
             trial_offsets=np.array([0, 3, 5]))
    return path


def test_summary_rows(tmp_path):
    specs = [DatasetSpec("silicone", str(dense_set(tmp_path / "s.npz")), central_trim=2,
                         reference_positive_rate=0.1133),
             DatasetSpec("meat", str(flat_set(tmp_path / "m.npz")), reference_positive_rate=0.0651)]
    table = summary_table(specs)
    assert tuple(table.columns) == COLUMNS
    sil, meat = table.to_dict(orient="records")
    assert (sil["trials"], sil["frames"], sil["markers_per_frame"]) == (3, 48, 127)
    assert sil["positive_rate"] == pytest.approx(30 / (3 * 12 * 127 - 1))  # central frames 2..13 only
    assert (meat["trials"], meat["frames"], meat["positive_rate"]) == (2, 5, pytest.approx(1 / 5))
    md = to_markdown(table)
    assert md.splitlines()[0] == "| " + " | ".join(COLUMNS) + " |"
    assert "| meat | 2 | 5 | 127 | 0.2000 | 0.0651 |" in md


def test_reference_rate_defaults_by_name():
    (spec,) = specs_from_mapping({"meat": {"path": "x.npz"}})
    assert spec.reference_positive_rate == 0.0651 and spec.central_trim == 0


def test_missing_input_names_the_file(tmp_path):
    specs = [DatasetSpec("meat", str(flat_set(tmp_path / "m.npz"))),
             DatasetSpec("silicone", str(tmp_path / "silicone.npz"))]
    with pytest.raises(FileNotFoundError, match="silicone.npz"):
        summary_table(specs)


def test_bad_layouts(tmp_path):
    np.savez(tmp_path / "nolabels.npz", markers=np.zeros((2, 127, 2)))
    with pytest.raises(ValueError, match="labels"):
        load_sequences(tmp_path / "nolabels.npz", "x")
    np.savez(tmp_path / "flat.npz", markers=np.zeros((4, 127, 2)), labels=np.zeros((4, 127)))
    with pytest.raises(ValueError, match="trial_offsets"):
        load_sequences(tmp_path / "flat.npz", "x")
    np.savez(tmp_path / "off.npz", markers=np.zeros((4, 127, 2)), labels=np.zeros((4, 127)),
             trial_offsets=np.array([0, 3]))
    with pytest.raises(ValueError, match="do not cut 4 frames"):
        load_sequences(tmp_path / "off.npz", "x")
    with pytest.raises(ValueError, match="central_trim"):
        summary_table([DatasetSpec("x", str(dense_set(tmp_path / "short.npz", n_frames=4)), central_trim=2)])


def test_data_summary_app(tmp_path):
    from palpation.apps.data_summary import run

    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose("data_summary", overrides=[
            f"datasets.silicone.path={dense_set(tmp_path / 's.npz')}",
            f"datasets.meat.path={flat_set(tmp_path / 'm.npz')}", f"out.dir={tmp_path}"])
    rows = run(cfg)
    assert set(rows) == {"silicone", "meat"}
    assert (tmp_path / "summary.csv").read_text().splitlines()[0] == ",".join(COLUMNS)
    assert (tmp_path / "summary.md").is_file()
