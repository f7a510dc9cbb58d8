"""Per-marker metrics (SPEC §11) and their aggregation over seeds."""

from palpation.metrics.classification import confusion, iou, marker_metrics
from palpation.metrics.aggregate import best_of_five, mean_curve, pr_curve, summarise_seeds

__all__ = ["confusion", "iou", "marker_metrics", "best_of_five", "mean_curve", "pr_curve", "summarise_seeds"]
