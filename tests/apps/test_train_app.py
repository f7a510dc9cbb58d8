"""The train app: config composition, one tiny run through `run(cfg)`, and a --multirun smoke test."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from palpation.apps.train import job_from_config, run
from palpation.metrics.calibration import Calibrator
from palpation.paths import REPO_ROOT

CONF = str(REPO_ROOT / "conf")
TINY = ["graph.rest=ideal", "train.batch_size=4", "train.epochs=1", "train.train_batches=2",
        "train.val_batches=1"]


def compose_train(overrides):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose(config_name="train", overrides=overrides)


@pytest.mark.parametrize("exp, model, train_on, test_on, sizes", [
    ("A-to-A", "large", "sim", "sim", (16, 1, 152, 32)),
    ("A-to-B", "large", "sim", "silicone", (16, 1, 152, 32)),
    ("A-to-C", "large", "sim", "meat", (16, 1, 152, 32)),
    ("C-to-B", "compact", "meat", "silicone", (4, 30, None, None)),
])
def test_experiments_compose(exp, model, train_on, test_on, sizes):
    job = job_from_config(compose_train([f"experiment={exp}", "seed=3"]))
    assert (job.config_name, job.model.name, job.train_on, job.test_on) == (exp, model, train_on, test_on)
    t = job.train
    assert (t.batch_size, t.epochs, t.train_batches, t.val_batches) == sizes
    assert (t.lr, t.norm_stats, t.rotation, t.schedule) == (1e-4, "sample", "reference", "none")
    assert (job.seed, job.clip_len) == (3, 5)
    better = job_from_config(compose_train([f"experiment={exp}", "recipe=better"])).train
    assert better.norm_stats == "full"


def test_train_run_writes_outputs_and_mlflow(train_sets, tmp_path, results_tmp, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MLflow's SQLite store puts artefacts in ./mlruns of the cwd
    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    cfg = compose_train(["experiment=A-to-B", "model=compact", "seed=0", "clip_len=3", *TINY, *paths])
    metrics = run(cfg, tmp_path / "run")
    out = tmp_path / "run"
    for name in ("metrics.json", "scores.npz", "pr.npz", "checkpoint.pt"):
        assert (out / name).exists()
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["test"] == metrics["test"] and saved["config"] == "A-to-B" and saved["clip_len"] == 3
    with np.load(out / "scores.npz") as z:
        assert z["probs"].shape == z["labels"].shape == (2 * 6 * 127,)  # 2 videos x 6 windows x 127
        assert z["sequence"].tolist() == [0] * 6 + [1] * 6 and z["frame"].tolist() == [1, 2, 3, 4, 5, 6] * 2
    assert {"auroc", "ap", "fg_iou", "bg_iou", "mcc", "tp"} <= set(metrics["test"])

    import mlflow

    mlflow.set_tracking_uri(f"sqlite:///{results_tmp / 'mlflow.db'}")
    (r,) = mlflow.search_runs(experiment_names=["train"], output_format="list")
    assert r.data.tags["config"] == "A-to-B" and r.data.tags["seed"] == "0"
    assert r.data.params["model.name"] == "compact" and "test/ap" in r.data.metrics
    arts = {a.path for a in mlflow.MlflowClient().list_artifacts(r.info.run_id)}
    assert {"scores.npz", "pr.npz", "checkpoint.pt", "metrics.json"} <= arts


def test_seeds_together_write_one_folder_and_one_mlflow_run_per_seed(train_sets, tmp_path, results_tmp,
                                                                     monkeypatch):
    monkeypatch.chdir(tmp_path)
    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    cfg = compose_train(["experiment=A-to-B", "model=compact", "seeds=[0,1]", "clip_len=2", *TINY, *paths])
    metrics = run(cfg, tmp_path / "run")
    assert [m["seed"] for m in metrics] == [0, 1]
    for m in metrics:
        saved = json.loads((tmp_path / "run" / f"seed{m['seed']}" / "metrics.json").read_text())
        assert saved["test"] == m["test"] and saved["trained_together"]["seeds"] == [0, 1]
    assert metrics[0]["test"]["ap"] != metrics[1]["test"]["ap"]

    import mlflow

    mlflow.set_tracking_uri(f"sqlite:///{results_tmp / 'mlflow.db'}")
    runs = mlflow.search_runs(experiment_names=["train"], output_format="list")
    assert sorted(r.data.tags["seed"] for r in runs) == ["0", "1"]
    for r in runs:
        assert r.data.tags["trained_together"] == "0,1" and r.data.params["seed"] == r.data.tags["seed"]
        losses = mlflow.MlflowClient().get_metric_history(r.info.run_id, "train/loss")
        # each batch's loss and the epoch's mean (at its last step), as fit logs them, replayed afterwards
        assert sorted(m.step for m in losses) == [1, 2, 2]
        assert "test/ap" in r.data.metrics and "val/fg_iou" in r.data.metrics



@pytest.mark.parametrize("seeds", ["[]", "[1,1]"])
def test_seeds_together_refuse_an_empty_or_repeated_list(seeds, tmp_path):
    cfg = compose_train(["experiment=C-to-B", f"seeds={seeds}", "track=false"])
    with pytest.raises(ValueError, match=r"list distinct seeds, at least one \(or seeds=null"):
        run(cfg, tmp_path)

def test_multirun_seeds_and_clip_lens(train_sets, tmp_path):
    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    cmd = [sys.executable, "-m", "palpation.apps.train", "--multirun", "experiment=C-to-B", "seed=0,1",
           "clip_len=1,3", "track=false", *TINY, *paths, f"hydra.sweep.dir={tmp_path}"]
    env = {**os.environ, "PALPATION_RESULTS": str(tmp_path / "results")}
    proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    done = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.glob("C-to-B/L*/seed*/metrics.json"))
    assert done == [f"C-to-B/L{L}/seed{s}/metrics.json" for L in (1, 3) for s in (0, 1)]
    m = [json.loads((tmp_path / d).read_text()) for d in done]
    assert m[0]["test"]["ap"] != m[1]["test"]["ap"]  # seeds differ


def test_schema_types_the_config_and_refuses_unknown_keys():
    from dataclasses import fields

    from hydra.errors import ConfigCompositionException
    from omegaconf import OmegaConf

    from palpation.model.config import RecipeSchema, RunSizesSchema, TrainConfig

    with pytest.raises(ConfigCompositionException, match="Could not override 'train.epoch'"):
        compose_train(["train.epoch=1"])
    with pytest.raises(ConfigCompositionException, match="Error merging override seed=first"):
        compose_train(["seed=first"])
    # `+key=value` adds past a schema in Hydra; the node stays typed, so the apps' key check names it
    added = compose_train(["+train.epoch=1"])
    assert OmegaConf.get_type(added.train) is RunSizesSchema and "epoch" in added.train
    # TrainConfig = the recipe's fields + the chosen sizes + device: the schema cannot drift from it
    schema = {f.name for f in fields(RecipeSchema)} - {"name", "sizes"} | {f.name for f in fields(RunSizesSchema)}
    assert schema | {"device"} == {f.name for f in fields(TrainConfig)}


def test_choice_keys_are_typed_by_the_schema():
    """The recipe's choice keys are enums of the schema: a value outside them fails at composition, naming the
    key and the choices; the library receives plain strings (MLflow params and outputs as before); a
    TrainConfig built in code is checked against the same enums."""
    from hydra.errors import ConfigCompositionException

    from palpation.model.config import CHOICES, TrainConfig

    for key, kind in CHOICES.items():
        with pytest.raises(ConfigCompositionException) as err:
            compose_train([f"recipe.{key}=stepp"])
        assert f"full_key: recipe.{key}" in str(err.value.__cause__)
        assert f"expected one of [{', '.join(kind.__members__)}]" in str(err.value.__cause__)
        with pytest.raises(ValueError, match=rf"^{key}='stepp': use one of"):
            TrainConfig(**{key: "stepp"})
    train = job_from_config(compose_train(["recipe=robust"])).train
    assert [type(getattr(train, key)) for key in CHOICES] == [str] * len(CHOICES)
    assert (train.select_metric, train.calibration, train.rotation) == ("ap", "platt", "consistent")


ROBUST_TINY = ["recipe=robust", "model=compact", "clip_len=2", "graph.rest=ideal", "train.batch_size=4",
               "train.epochs=3", "train.train_batches=2", "train.val_batches=null", "recipe.patience=1",
               "track=false"]


def test_robust_seeds_together_and_shared_test_sets_match_separate_runs(train_sets, tmp_path):
    """The recipe ablation's stacked job (rule train_recipe_seeds_*): the robust recipe, every switch that changes
    the data on (jitter, dropout, scaling, consistent rotation, whole-split statistics), early stopping, AP
    checkpointing and Platt calibration; seeds 0, 1 trained together once and scored on Silicone (A-to-B) and
    Meat (A-to-C) match each (configuration, seed) trained alone up to the batched matmuls' rounding."""
    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    root = tmp_path / "together" / "A-to-B" / "L2"
    raw_root = tmp_path / "uncalibrated"
    together = run(compose_train(["experiment=A-to-B", "seeds=[0,1]", "also_test=[A-to-C:meat]", *ROBUST_TINY,
                                  f"also_uncalibrated={raw_root}", *paths]), root)
    together, raw = together[:4], together[4:]
    assert [(m["config"], m["seed"]) for m in together] == [("A-to-B", 0), ("A-to-B", 1), ("A-to-C", 0), ("A-to-C", 1)]
    for t, r in zip(together, raw):  # robust minus calibration: the same models, their raw scores
        sub = Path(t["config"], "L2", f"seed{t['seed']}")
        d, rd = root.parents[1] / sub, raw_root / sub
        assert (d / "checkpoint.pt").read_bytes() == (rd / "checkpoint.pt").read_bytes()
        assert "calibration" not in r and r["test"] == t["test_raw"] and r["history"] == t["history"]
        cal = Calibrator(**t["calibration"])
        probs, raw_probs = (np.load(f / "scores.npz")["probs"] for f in (d, rd))
        assert np.allclose(probs, cal.apply(raw_probs), atol=1e-6)
    assert together[0]["trained_together"]["configs"] == ["A-to-B", "A-to-C"]
    assert json.loads((tmp_path / "together/A-to-C/L2/seed1/metrics.json").read_text())["test_on"] == "meat"
    early, diffs = any(len(t["history"]) < 3 for t in together), []
    for t in (together[0], together[3]):  # (A-to-B, seed 0), (A-to-C, seed 1): each also trained alone
        alone = run(compose_train([f"experiment={t['config']}", f"seed={t['seed']}", *ROBUST_TINY, *paths]),
                    tmp_path / "alone" / t["config"] / str(t["seed"]))
        assert t["best_epoch"] == alone["best_epoch"] and len(t["history"]) == len(alone["history"])
        assert t["alpha"] == alone["alpha"]  # the same whole-split statistics
        pair = (root.parents[1] / t["config"] / "L2" / f"seed{t['seed']}",
                tmp_path / "alone" / t["config"] / str(t["seed"]))
        scores = [np.load(d / "scores.npz")["probs"] for d in pair]
        diffs.append(np.abs(scores[0] - scores[1]).max())
        for key in ("auroc", "ap", "fg_iou", "bg_iou"):  # calibrated test metrics: a tie may flip on a tiny set
            assert t["test"][key] == pytest.approx(alone["test"][key], abs=2e-3), (t["config"], t["seed"], key)
        for key in ("scale", "shift"):  # Platt fitted on each seed's own val scores
            assert t["calibration"][key] == pytest.approx(alone["calibration"][key], rel=1e-3, abs=1e-4)
        assert t["ece_raw"] == pytest.approx(alone["ece_raw"], abs=1e-5)
    assert early, "patience 1 should stop some seed before its third epoch"
    assert max(diffs) < 1e-4, diffs  # calibrated test scores; measured <= 2.3e-6 (batched float32 matmuls)
    # the augmentation draws stay each seed's own: the two seeds' models differ
    assert together[0]["test"]["ap"] != together[1]["test"]["ap"]


def test_one_seed_scored_on_several_test_sets_is_byte_for_byte_its_own_runs(train_sets, tmp_path, results_tmp,
                                                                           monkeypatch):
    """Rule train_shared_* without seeds_together (the quick profile): A-to-A's model of one seed trained once and
    scored on Sim, Silicone and Meat writes what A-to-A, A-to-B and A-to-C each trained alone write, byte for byte
    (training reads no test set), apart from metrics.json's timings and `trained_together`."""
    monkeypatch.chdir(tmp_path)
    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    tiny = ["model=compact", "seed=1", "clip_len=2", *TINY, "recipe=quick", *paths]
    shared = run(compose_train(["experiment=A-to-A", "also_test=[A-to-B:silicone,A-to-C:meat]", *tiny]),
                 tmp_path / "shared" / "A-to-A" / "L2" / "seed1")
    import mlflow  # one MLflow run per configuration, each with the training's loss history

    mlflow.set_tracking_uri(f"sqlite:///{results_tmp / 'mlflow.db'}")
    runs = mlflow.search_runs(experiment_names=["train"], output_format="list")
    assert sorted(r.data.tags["config"] for r in runs) == ["A-to-A", "A-to-B", "A-to-C"]
    losses = [[m.value for m in mlflow.MlflowClient().get_metric_history(r.info.run_id, "train/loss")] for r in runs]
    assert losses[0] and losses[0] == losses[1] == losses[2]
    tiny.append("track=false")
    assert [m["config"] for m in shared] == ["A-to-A", "A-to-B", "A-to-C"]
    assert shared[2]["trained_together"]["configs"] == ["A-to-A", "A-to-B", "A-to-C"]
    timing = ("train_seconds", "test_seconds", "trained_together")
    for m in shared:
        exp = m["config"]
        alone = run(compose_train([f"experiment={exp}", *tiny]), tmp_path / "alone" / exp)
        pair = (tmp_path / "shared" / exp / "L2" / "seed1", tmp_path / "alone" / exp)
        for name in ("scores.npz", "pr.npz", "checkpoint.pt"):
            assert (pair[0] / name).read_bytes() == (pair[1] / name).read_bytes(), (exp, name)
        assert {k: v for k, v in m.items() if k not in timing} == {k: v for k, v in alone.items() if k not in timing}
    with pytest.raises(ValueError, match="needs the run dir <root>/A-to-A/L2/seed1"):
        run(compose_train(["experiment=A-to-A", "also_test=[A-to-B:silicone]", *tiny]), tmp_path / "elsewhere")


def test_also_test_needs_the_run_layout(train_sets, tmp_path):
    with pytest.raises(ValueError, match="also_uncalibrated uses the models of `seeds`"):
        run(compose_train(["experiment=A-to-B", "also_uncalibrated=x", "track=false"]), tmp_path)
    with pytest.raises(ValueError, match="calibrates nothing"):
        run(compose_train(["experiment=A-to-B", "seeds=[0]", "also_uncalibrated=x", "track=false"]), tmp_path)
    with pytest.raises(ValueError, match="needs the run dir <root>/A-to-B/L5"):
        run(compose_train(["experiment=A-to-B", "seeds=[0]", "also_test=[A-to-C:meat]", "track=false"]), tmp_path)


def test_cross_real_calibration_is_fitted_on_the_other_real_sets_scores(train_sets, tmp_path):
    """calibration=cross_real (issue 15): each configuration's Platt scaling is the one fitted on the same seed's
    models' raw scores on the other real set (A-to-B on A-to-C's, and back), never on its own test set; the
    weights are those of the uncalibrated twins. Alone (no other real set) it is refused."""
    from palpation.metrics.calibration import fit_calibrator

    paths = [f"data.{k}={v}" for k, v in train_sets.items()]
    tiny = ["model=compact", "clip_len=2", *TINY, "recipe.calibration=cross_real", "track=false", *paths]
    root, raw_root = tmp_path / "x" / "A-to-B" / "L2", tmp_path / "raw"
    runs = run(compose_train(["experiment=A-to-B", "seeds=[0,1]", "also_test=[A-to-C:meat]",
                              f"also_uncalibrated={raw_root}", *tiny]), root)
    cal, raw = runs[:4], runs[4:]
    other = {"A-to-B": "A-to-C", "A-to-C": "A-to-B"}
    for m in cal:
        assert m["calibration_fitted_on"] == other[m["config"]]
        partner = np.load(raw_root / other[m["config"]] / "L2" / f"seed{m['seed']}" / "scores.npz")
        want = fit_calibrator(partner["probs"], partner["labels"], "platt")
        assert Calibrator(**m["calibration"]) == want
        own = np.load(raw_root / m["config"] / "L2" / f"seed{m['seed']}" / "scores.npz")
        written = np.load(root.parents[1] / m["config"] / "L2" / f"seed{m['seed']}" / "scores.npz")
        np.testing.assert_allclose(written["probs"], want.apply(own["probs"]), atol=1e-6)
    assert [r["test"] for r in raw] == [m["test_raw"] for m in cal]
    with pytest.raises(ValueError, match="cross_real fits on the same models' scores on another real set"):
        run(compose_train(["experiment=A-to-B", "seed=0", *tiny]), tmp_path / "alone")
    with pytest.raises(ValueError, match="exactly one other real test set"):
        run(compose_train(["experiment=A-to-B", "seeds=[0]", *tiny]), tmp_path / "y" / "A-to-B" / "L2")
