"""palpation.model.diagnose on a toy Sim set: the rotation offset of the template layout and the jitter's shift of the
temporal features are what it measures, and both show."""

from palpation.graph.layout import rest_layout
from palpation.graph.synthetic import write_sim
from palpation.model.diagnose import diagnose


def test_diagnose_measures_rotation_offset_and_jitter_shift(tmp_path):
    manifest = write_sim(tmp_path / "sim", rest_layout("template"), n_traj=10, n_frames=144)
    r = diagnose(str(manifest), n_clips=16, seed=0)
    assert r["clips"]["sampled"] == min(16, r["clips"]["train"]) and r["clips"]["val"] > 0
    off = r["rotation_offset_px"]
    assert 0.5 < off["median"] <= off["p90"] <= off["max"] < 20  # the template is not 6-fold symmetric
    cols = r["columns"]
    assert set(cols) == {"val", "train robust", "train lattice", "train no jitter"}
    # robust jitter (0.2 px) is the only difference between these two batches: it widens the motion features
    assert cols["train robust"]["temporal dist"][0] > cols["train no jitter"]["temporal dist"][0]
    assert cols["train robust"]["node rest dist"] == cols["train no jitter"]["node rest dist"]
