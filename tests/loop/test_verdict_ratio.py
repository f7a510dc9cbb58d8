"""workflow/scripts/loop_verdict_ratio.py, and the verdict's ratio apart from the search's above-the-noise one."""

import importlib.util

import pandas as pd
import pytest

from palpation.loop.method import Method
from palpation.loop.unexplained import residual_test
from palpation.paths import REPO_ROOT

SPEC = importlib.util.spec_from_file_location("loop_verdict_ratio",
                                              REPO_ROOT / "workflow" / "scripts" / "loop_verdict_ratio.py")
vr = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(vr)


def record(path, rows):
    """A generative record: (injected, named, excess); `unexplained` joins the named set above 2.0 (as recorded)."""
    pd.DataFrame([{"run": i, "seed": 1, "split": "dev", "effects_injected": inj, "mae_before_px": 1.0,
                   "effects_named": named + ("+unexplained" if ex > 2.0 else ""), "mae_after_px": 0.3,
                   "excess_ratio": ex, "params_true": "{}", "params_fitted": "{}"}
                  for i, (inj, named, ex) in enumerate(rows)]).to_csv(path, index=False)
    return path


def test_the_rule_sits_above_the_exact_runs_and_counts_what_each_ratio_flags(tmp_path):
    a = record(tmp_path / "a.csv", [("camera", "camera", 1.1), ("mount", "mount", 1.25),
                                    ("camera+unlisted:marker_defect", "camera", 1.8),
                                    ("unlisted:image_distortion", "mount", 3.0), ("viscous", "none", 1.6)])
    t = vr.table(vr.runs_of([a])).set_index("ratio")
    assert t["chosen"].idxmax() == 1.5  # 1.15 x 1.25 = 1.44: the smallest grid value at or above it
    assert t.loc[1.25, "exact_flagged"] == 0 and t.loc[1.5, "outside_flagged"] == 2
    assert t.loc[2.0, "outside_flagged"] == 1 and t.loc[1.5, "inexact_flagged"] == 1


def test_a_record_whose_flags_are_not_its_excess_is_refused(tmp_path):
    bad = tmp_path / "bad.csv"
    record(bad, [("camera", "camera", 1.1)])
    table = pd.read_csv(bad)
    table.loc[0, "effects_named"] = "camera+unexplained"  # flagged at 1.1: not a ratio-2 record
    table.to_csv(bad, index=False)
    with pytest.raises(ValueError, match="not a record of ratio"):
        vr.runs_of([bad])


def test_the_verdict_flags_below_the_search_s_above_the_noise_ratio():
    m = Method()
    assert m.verdict_ratio < m.unexplained_ratio
    rng = pytest.importorskip("numpy").random.default_rng(0)
    sigma, excess = 0.2, 0.5 * (m.verdict_ratio + m.unexplained_ratio)  # between the two
    r = rng.normal(0.0, sigma * excess, 2000)
    assert residual_test(r, [], sigma, m.unexplained_alpha, m.verdict_ratio)["unexplained"]
    assert not residual_test(r, [], sigma, m.unexplained_alpha, m.unexplained_ratio)["unexplained"]
