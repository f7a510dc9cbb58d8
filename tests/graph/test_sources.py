import numpy as np
import pytest

from palpation.graph.clips import ClipSet
from palpation.graph.layout import rest_layout
from palpation.graph.sources import load_dataset
from palpation.graph.synthetic import write_all
from palpation.paths import REPO_ROOT


@pytest.fixture(scope="module")
def paths(tmp_path_factory):
    return write_all(tmp_path_factory.mktemp("data"), rest_layout("ideal"), n_traj=10, n_frames=72)


def test_loaders_read_the_described_formats(paths):
    sim = {s: load_dataset("sim", paths["sim"], s) for s in ("train", "val", "test")}
    assert [len(s.ids) for s in sim.values()] == [7, 1, 2]
    assert sim["train"].labels is None and sim["train"].centreline[0].shape == (72, 50, 2)
    sil = load_dataset("silicone", paths["silicone"], "test")
    assert len(sil.ids) == 10 and sil.markers[0].shape == (16, 127, 2) and sil.stride == 1
    meat = {s: load_dataset("meat", paths["meat"], s) for s in ("train", "val", "test")}
    assert [len(m.ids) for m in meat.values()] == [7, 3, 10]
    assert meat["train"].labels[0].dtype == np.int8 and meat["test"].window == "centred"


def test_real_sets_give_the_papers_node_counts(real_sets):
    SILICONE, MEAT = real_sets["silicone"], real_sets["meat"]
    rest = rest_layout("ideal")
    silicone = ClipSet(load_dataset("silicone", SILICONE, "test"), 5, rest)
    meat = {s: ClipSet(load_dataset("meat", MEAT, s), 5, rest) for s in ("train", "val", "test")}
    assert len(silicone) * 127 == 15_240 and len(meat["test"]) * 127 == 27_813  # SPEC §15.3
    assert [len(m.seqs.ids) for m in meat.values()] == [7, 3, 10]
    assert len(meat["train"]) == 153  # quirk 22: "L = 5 gives about 153"


def test_missing_files_name_the_rule(tmp_path):
    with pytest.raises(FileNotFoundError, match="simulate_dataset"):
        load_dataset("sim", tmp_path / "manifest.json", "train")
    with pytest.raises(ValueError, match="unknown dataset"):
        load_dataset("mri", tmp_path, "train")
