"""The CPU step profile at toy size: the step is timed, its operators listed, the machine's rates measured."""

import json

import pytest

from palpation.graph.layout import rest_layout
from palpation.graph.synthetic import write_sim
from palpation.model.step_profile import main

TOY = ["graph.rest=ideal", "clip_len=2", "train.batch_size=2"]


def test_step_profile_record_at_toy_size(tmp_path):
    sim = write_sim(tmp_path / "sim", rest_layout("ideal"), n_traj=7, n_frames=72)
    out = tmp_path / "step.json"
    records = main(["--configs", "A-to-A:compact", "--sim", str(sim), "--out", str(out), "--steps", "2",
                    "--top", "5", "--override", *TOY])
    assert json.loads(out.read_text()) == records and len(records) == 1
    r = records[0]
    assert r["threads"] == 1 and r["step_ms"] > 0 and r["eval_forward_ms"] > 0
    assert r["batch"]["clips"] == 2 and r["batch"]["edges"] > r["batch"]["nodes"] > 0
    ops = r["by_operator"]
    assert len(ops) == 5 and all(a["self_ms_per_step"] >= b["self_ms_per_step"] for a, b in zip(ops, ops[1:]))
    assert 0 < sum(o["share"] for o in ops) <= 1
    gemm = r["rates"]["gemm"]
    assert gemm["shape"] == [r["batch"]["edges"], 56, 56] and gemm["gflops"] > 0
    drop = r["rates"]["dropout"]
    assert drop["shape"] == [r["batch"]["edges"], 64] and drop["dropout_ms"] > 0 and drop["rand_like_ms"] > 0
    assert "compiled" not in r


def test_step_profile_refuses_a_config_without_its_model(tmp_path):
    with pytest.raises(SystemExit, match="EXPERIMENT:MODEL"):
        main(["--configs", "A-to-A", "--out", str(tmp_path / "x.json")])
