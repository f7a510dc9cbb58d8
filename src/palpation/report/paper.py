"""The paper's published numbers (SPEC §15.1, §15.4, §15.5), for side-by-side tables."""

from __future__ import annotations

CONFIG_TITLES = {"A-to-A": "Sim→Sim", "A-to-B": "Sim→Silicone", "A-to-C": "Sim→Meat", "C-to-B": "Meat→Silicone"}

# §15.1: five-seed sweep, (mean, std) per metric; the A-to-A row is published at 3 d.p.
PAPER_DIGITS = {"A-to-A": 3}
SEED_SWEEP = {
    "A-to-A": {"auroc": (0.958, 0.001), "ap": (0.491, 0.006), "fg_iou": (0.193, 0.019),
               "bg_iou": (0.818, 0.024), "chance": (0.042, 0.0)},
    "A-to-B": {"auroc": (0.7789, 0.0043), "ap": (0.3213, 0.0043), "fg_iou": (0.2342, 0.0073),
               "bg_iou": (0.8113, 0.0265), "chance": (0.1133, 0.0)},
    "A-to-C": {"auroc": (0.8371, 0.0024), "ap": (0.2243, 0.0036), "fg_iou": (0.1707, 0.0058),
               "bg_iou": (0.7304, 0.0191), "chance": (0.0651, 0.0)},
    "C-to-B": {"auroc": (0.7165, 0.0543), "ap": (0.3035, 0.0377), "fg_iou": (0.1550, 0.0121),
               "bg_iou": (0.5367, 0.1236), "chance": (0.1133, 0.0)},
}

# §15.5: Table 4 upper half, best-of-five per marker at threshold 0.5
TABLE4 = {
    "A-to-A": {"seed": 1, "tp": 3569, "fp": 15169, "fn": 38, "tn": 66949, "mcc": 0.39, "f1": 0.32,
               "precision": 0.19, "recall": 0.99, "fg_iou": 0.19, "bg_iou": 0.81, "ap": 0.50},
    "A-to-B": {"seed": 2, "tp": 909, "fp": 2070, "fn": 818, "tn": 11443, "mcc": 0.30, "f1": 0.39,
               "precision": 0.31, "recall": 0.53, "fg_iou": 0.24, "bg_iou": 0.80, "ap": 0.33},
    "A-to-C": {"seed": 2, "tp": 1493, "fp": 7134, "fn": 317, "tn": 18869, "mcc": 0.29, "f1": 0.29,
               "precision": 0.17, "recall": 0.82, "fg_iou": 0.17, "bg_iou": 0.72, "ap": 0.23},
    "C-to-B": {"seed": 4, "tp": 1600, "fp": 8448, "fn": 127, "tn": 5065, "mcc": 0.20, "f1": 0.27,
               "precision": 0.16, "recall": 0.93, "fg_iou": 0.16, "bg_iou": 0.37, "ap": 0.35},
}

# §15.4: Table 3, A-to-B, seeds 0-2: (mean, std) and the FG IoU range
TABLE3 = {
    1: {"fg_iou": (0.1142, 0.0018), "fg_range": (0.1123, 0.1157), "auroc": (0.5815, 0.0030), "ap": (0.2094, 0.0054)},
    3: {"fg_iou": (0.1967, 0.0059), "fg_range": (0.1900, 0.2011), "auroc": (0.7403, 0.0024), "ap": (0.2008, 0.0012)},
    5: {"fg_iou": (0.2384, 0.0012), "fg_range": (0.2371, 0.2394), "auroc": (0.7818, 0.0018), "ap": (0.3243, 0.0011)},
    7: {"fg_iou": (0.2139, 0.0294), "fg_range": (0.1799, 0.2310), "auroc": (0.7676, 0.0078), "ap": (0.3105, 0.0061)},
}
