"""The seeds-together benchmark at toy size on the CPU: both sides run, the record compares them."""

import json

from palpation.model.benchmark import main

TOY = ["model=compact", "graph.rest=ideal", "clip_len=2", "train.batch_size=8", "train.epochs=2",
       "train.train_batches=1", "train.val_batches=1"]


def test_benchmark_record_at_toy_size(tmp_path):
    out = tmp_path / "bench_train.json"
    record = main(["--device", "cpu", "--out", str(out), "--seeds", "0", "1", "--synthetic", "7", "--frames", "72",
                   "--keep", str(tmp_path / "runs"), "--override", *TOY])
    assert record["job"]["data"]["sim"].startswith("synthetic: 7 slides x 72 frames")
    assert json.loads(out.read_text())["wall_s"] == record["wall_s"]
    assert record["job"]["config"] == "A-to-A" and record["seeds"] == [0, 1]
    assert record["wall_s"]["apart"] > 0 and record["wall_s"]["together"] > 0
    for s, row in zip((0, 1), record["per_seed"]):
        assert row["seed"] == s and row["best_epoch"]["apart"] == row["best_epoch"]["together"]
        assert (tmp_path / "runs" / "together" / f"seed{s}" / "checkpoint.pt").exists()
        assert abs(row["test"]["ap"]["apart"] - row["test"]["ap"]["together"]) < 1e-4
    assert record["max_abs_score_diff"] < 1e-5  # CPU: the same draws, only batched rounding
    assert record["per_seed"][0]["test"]["ap"]["apart"] != record["per_seed"][1]["test"]["ap"]["apart"]
