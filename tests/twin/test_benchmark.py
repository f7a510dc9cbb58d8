"""twin.benchmark: a full batch is timed unless told otherwise, and estimates say so in their names."""

import json

from palpation.twin import benchmark
from palpation.twin.config import TwinConfig

CORE = {"core_substeps_per_s", "core_substep_us", "roofline_fraction_streamed",
        "roofline_fraction_compulsory", "bandwidth_bytes_per_s"}


def test_default_times_the_full_slide(mesh):
    rec = benchmark.bench_point(mesh, TwinConfig(), 1, "cpu")
    assert rec["frames_timed"] == rec["frames"] == 398
    assert rec["wall_s_measured"] > 0 and not any("extrapolat" in k for k in rec)
    assert CORE <= rec.keys()
    assert abs(rec["core_substep_us"] * rec["core_substeps_per_s"] - 1e6) < 1e-3


def test_fewer_frames_are_named_extrapolated(mesh, tmp_path, monkeypatch):
    monkeypatch.setattr(benchmark.SensorMesh, "load", classmethod(lambda cls, path: mesh))
    out = tmp_path / "twin.json"
    benchmark.main(["--device", "cpu", "--resolutions", "coarse", "--n-envs", "2", "--max-frames", "3",
                    "--out", str(out)])
    (rec,) = json.loads(out.read_text())
    assert rec["frames_timed"] == rec["extrapolated_from_frames"] == 3
    assert {"wall_s_extrapolated", "trajectories_per_hour_extrapolated"} <= rec.keys()
    assert "wall_s_measured" not in rec and "trajectories_per_hour" not in rec and "wall_s" not in rec
    assert CORE <= rec.keys()


def test_resident_kernel_entry(mesh, tmp_path, monkeypatch):
    monkeypatch.setattr(benchmark.SensorMesh, "load", classmethod(lambda cls, path: mesh))
    out = tmp_path / "twin.json"
    benchmark.main(["--device", "cpu", "--resolutions", "coarse", "--n-envs", "2", "--max-frames", "3",
                    "--kernel", "resident", "--block-dim", "256", "--variants", "tiles", "packed:largest_first",
                    "--out", str(out)])
    rec, packed = json.loads(out.read_text())
    assert rec["kernel"] == "resident" and rec["block_dim"] == 256 and rec["force_sum"] == "colored"
    assert (rec["resident_variant"], rec["resident_coloring"]) == ("tiles", "mesh_order")
    assert (packed["resident_variant"], packed["resident_coloring"]) == ("packed", "largest_first")
    assert CORE <= rec.keys() and rec["core_substep_us"] > 0
