import numpy as np
import pytest
from sklearn.metrics import average_precision_score, matthews_corrcoef, roc_auc_score

from palpation.metrics.classification import iou, marker_metrics


def test_hand_made_counts():
    probs = np.array([0.9, 0.6, 0.5, 0.4, 0.2, 0.1])
    labels = np.array([1, 0, 1, 1, 0, 0])
    m = marker_metrics(probs, labels)
    assert (m["tp"], m["fp"], m["fn"], m["tn"]) == (2, 1, 1, 2)  # 0.5 counts as positive (>=)
    assert m["precision"] == pytest.approx(2 / 3) and m["recall"] == pytest.approx(2 / 3)
    assert m["f1"] == pytest.approx(2 / 3)
    assert m["fg_iou"] == pytest.approx(2 / 4) and m["bg_iou"] == pytest.approx(2 / 4)
    assert m["mcc"] == pytest.approx(matthews_corrcoef(labels, probs >= 0.5))
    assert m["ap"] == pytest.approx(average_precision_score(labels, probs))
    assert m["auroc"] == pytest.approx(roc_auc_score(labels, probs))
    assert m["chance"] == 0.5 and m["lift"] == pytest.approx(m["ap"] / 0.5)


def test_degenerate_cases():
    assert iou(np.zeros(3, bool), np.zeros(3, bool)) == 1.0  # empty union
    m = marker_metrics(np.zeros(4), np.zeros(4))
    assert m["mcc"] == 0.0 and m["fg_iou"] == 1.0 and m["bg_iou"] == 1.0 and np.isnan(m["ap"])
    m = marker_metrics(np.ones(4), np.array([1, 0, 0, 0]))
    assert m["mcc"] == 0.0 and m["recall"] == 1.0 and m["fg_iou"] == 0.25 and m["bg_iou"] == 0.0
    with pytest.raises(ValueError, match="differ"):
        marker_metrics(np.ones(3), np.ones(4))
