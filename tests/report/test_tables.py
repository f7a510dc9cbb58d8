"""The paper's tables as Markdown: Table 4 lower half beside the paper's row."""

import pandas as pd

from palpation.mapping.threshold import OperatingPoint
from palpation.report.tables import MAPS_COLUMNS, table4_maps_markdown


def test_markdown_puts_the_paper_beside_ours():
    op = OperatingPoint(0.61, "precision>=0.9@3mm", 0.9, 0.3, 0.45, 100, 3.0, 0.9, 20)
    row = {"config": "A-to-B", "threshold": op.threshold, "threshold_rule": op.rule, "tp": 10, "fp": 2, "fn": 5,
           "tn": 100, "mcc": 0.5, "f1": 0.6, "precision": 0.8, "recall": 0.6, "fg_iou": 0.5, "bg_iou": 0.9,
           "ap": 0.7, "d_bar_mm": 1.234}
    text = table4_maps_markdown(pd.DataFrame([row], columns=list(MAPS_COLUMNS)), "quick", ["a note"])
    assert "| A-to-B | ours |" in text and "| A-to-B | paper |" in text
    assert "**1.23**" in text and "**1.21**" in text and "0.5739" in text and "* a note" in text
    assert ("| A-to-B | ours | 10 | 2 | 5 | 100 | 0.50 | 0.60 | 0.80 | 0.60 | 0.50 | 0.90 | 0.70 | **1.23** | 0.6100 "
            "| precision>=0.9@3mm |") in text
    assert ("| A-to-B | paper | 592 | 750 | 752 | 15,906 | 0.40 | 0.44 | 0.44 | 0.44 | 0.28 | 0.91 | 0.42 | **1.21** "
            "| 0.5739 | precision>=0.9@3mm |") in text


def test_seed_verdicts_need_three_seeds_and_a_spread():
    from palpation.report.compare import compare

    assert compare(0.70, 0.0, 0.80, 0.001, n_ours=2).verdict() == "too few seeds to judge (2; 3 needed)"
    assert compare(0.70, 0.0, 0.80, 0.001, n_ours=5).verdict() == "no spread over our 5 seeds to judge by"
    assert compare(0.70, 0.0, 0.80, 0.001, n_ours=2).within is None
    assert compare(0.70, 0.02, 0.80, 0.02, n_ours=5).verdict() == "**3.5σ lower**"
    assert compare(0.79, 0.02, 0.80, 0.02, n_ours=3).within is True
