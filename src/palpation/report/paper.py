"""The paper's published numbers (SPEC §6.4, §7, §12, §13, §15), for side-by-side tables.

The one home of every published number the code compares against; other modules import from here."""

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

# §15.8: calibration MAE in px per interaction: the reference twin, its undeformed rest markers vs the
# photo, and the press d=0 photo vs the photo; 27.5 px/mm (mm = px × 2/55)
CALIBRATION_MAE = {
    "press": {"twin": 11.87, "undeformed": 13.95, "press_d0": 13.81},
    "twist_z": {"twin": 15.82, "undeformed": 15.40, "press_d0": 15.29},
    "twist_x": {"twin": 14.53, "undeformed": 16.27, "press_d0": 16.74},
    "slide": {"twin": 12.42, "undeformed": 14.15, "press_d0": 14.70},
}
CALIBRATION_MEAN = {"twin": 13.66, "undeformed": 14.94, "press_d0": 15.14}  # §15.8 bold row
CALIBRATION_OPTIMUM_PX = 12.43  # §6.4: MAE_absent of the best trial

# §15.6: Table 4 lower half, map per pixel (exact pixels) at the operating point of §12
TABLE4_MAPS = {
    "A-to-A": dict(tp=157, fp=178, fn=41, tn=2726, mcc=0.58, f1=0.59, precision=0.47, recall=0.79, fg_iou=0.42,
                   bg_iou=0.93, ap=0.71, d_bar_mm=1.05, threshold=0.6283, threshold_rule="precision>=0.9@3mm"),
    "A-to-B": dict(tp=592, fp=750, fn=752, tn=15906, mcc=0.40, f1=0.44, precision=0.44, recall=0.44, fg_iou=0.28,
                   bg_iou=0.91, ap=0.42, d_bar_mm=1.21, threshold=0.5739, threshold_rule="precision>=0.9@3mm"),
    "A-to-C": dict(tp=1359, fp=4843, fn=220, tn=68938, mcc=0.41, f1=0.35, precision=0.22, recall=0.86, fg_iou=0.21,
                   bg_iou=0.93, ap=0.30, d_bar_mm=5.49, threshold=0.5530, threshold_rule="f1_fallback"),
    "C-to-B": dict(tp=626, fp=700, fn=718, tn=15956, mcc=0.43, f1=0.47, precision=0.47, recall=0.47, fg_iou=0.31,
                   bg_iou=0.92, ap=0.45, d_bar_mm=1.31, threshold=0.6129, threshold_rule="precision>=0.9@3mm"),
}
MAPS_PHOTO_THRESHOLD = {"A-to-B": 0.5990, "C-to-B": 0.6183}  # §15.6, Silicone against the photo truth
MAPS_VIDEO_PHOTO_IOU = 0.2934  # §12: video-truth vs photo-truth IoU of the Silicone map

# Real sets as the reference counts them: trials, clip-centre frames (viewer states) and the central-frame
# positive rate (§13.4: 160 Silicone states; §13.5: 219 Meat states, 1,727/15,240 and 1,810/27,813 nodes;
# §7: Sim 4.2 % on the A-to-A test split)
DATASETS = {
    "silicone": {"trials": 10, "frames": 160, "positive_rate": 0.1133},
    "meat": {"trials": 10, "frames": 219, "positive_rate": 0.0651},
    "sim": {"trials": 500, "positive_rate": 0.042},
}
# §15.3: central-frame nodes and positives of each configuration's test set
TEST_SETS = {"A-to-A": (85725, 3607), "A-to-B": (15240, 1727), "A-to-C": (27813, 1810), "C-to-B": (15240, 1727)}
