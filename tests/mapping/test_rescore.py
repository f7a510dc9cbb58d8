"""The dense Sim slide: every start rescored with a checkpoint, then mapped (sim.source=slide)."""

import numpy as np
import torch
from hydra import compose, initialize_config_dir

from palpation.apps.vessel_maps import run
from palpation.graph.layout import rest_layout
from palpation.graph.normalise import N_SCALED, NormStats
from palpation.mapping.pipeline import config_maps
from palpation.mapping.rescore import score_dense
from palpation.mapping.sources import sim_source
from palpation.model import STGNN, ModelConfig
from palpation.model.checkpoint import save_checkpoint
from palpation.paths import REPO_ROOT

COMPACT = ModelConfig("compact", 56, 64, 32)


def untrained_checkpoint(path, clip_len=5):
    torch.manual_seed(0)
    unit = {f"{g}_{k}": (0.0,) * N_SCALED if k == "mean" else (1.0,) * N_SCALED
            for g in ("node", "spatial", "temporal") for k in ("mean", "std")}
    save_checkpoint(path, STGNN(clip_len, COMPACT), COMPACT, NormStats(**unit, alpha=0.9, n_clips=1, mode="full"),
                    rest_layout("ideal"))
    return path


def test_dense_slide_scores_every_start_and_maps(tmp_path, make_sim_set):
    slide = make_sim_set(tmp_path / "slide", n_files=1)
    ckpt = untrained_checkpoint(tmp_path / "run" / "checkpoint.pt")
    dense = score_dense(ckpt, slide, batch_size=32)
    assert len(dense["sequence"]) == 144 - 24 * 5 + 1
    assert dense["frame"][0] == 48 and np.all(np.diff(dense["frame"]) == 1)
    with np.load(slide.parent / "trajectory_0000.npz") as z:  # labels recomputed by the clip set = the file's
        assert np.array_equal(dense["labels"].reshape(-1, 127), z["labels"][dense["frame"]])
    res = config_maps("A-to-A", sim_source(slide, "all"), dense["probs"], dense["labels"], dense["sequence"],
                      dense["frame"])
    assert len(res.stack) == 1 and res.stack.truth.any()

    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="vessel_maps", overrides=[
            "configs=[A-to-A]", f"scores.A-to-A={ckpt.parent / 'scores.npz'}", "sim.source=slide",
            f"sim.slide_manifest={slide}", "sim.batch_size=32", f"out_dir={tmp_path / 'maps'}", "track=false"])
    out = run(cfg)
    assert out["configs"]["A-to-A"]["n_samples"] == len(dense["sequence"])
