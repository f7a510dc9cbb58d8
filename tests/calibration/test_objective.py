"""The project objective with a stand-in simulator: targets, geometry, batching, divergence, hold-out."""

import numpy as np
import pytest

from palpation.calibration.objective import (INTERACTIONS, PhotoObjective, marker_mae_px, photo_targets,
                                             target_geometry, undeformed_mae)
from palpation.measured import MeasuredState, make_measured_set

RNG = np.random.default_rng(0)
REST = RNG.uniform(700, 1400, (127, 2))
STATES = [("press", 4.0, None), ("twist_z", 4.0, 90.0), ("twist_x", 2.0, 20.0), ("slide", 3.0, None)]


def measured(kinds=STATES):
    markers = np.stack([REST + 3.0 * (i + 1) for i in range(len(kinds))])
    states = [MeasuredState(f"{k}_photo", f"{k}.png", k, d, a) for k, d, a in kinds]
    return make_measured_set(markers, np.ones(markers.shape[:2], bool), REST, states)


class FakeTwin:
    """Markers = photo + E-dependent offset, so the MAE is |E - 5e5| / 1e5 px; E > 9e5 diverges."""

    def __init__(self, targets):
        self.photo = {t.kind: t.markers for t in targets}
        self.calls = []

    def __call__(self, requests):
        self.calls.append(requests)
        out = np.stack([self.photo[k] + [abs(p["E"] - 5e5) / 1e5, 0.0] for k, p in requests])
        failed = np.array([p["E"] > 9e5 for _, p in requests])
        out[failed] = np.nan
        return out.astype(np.float32), failed


def test_missing_interaction_names_the_set():
    with pytest.raises(ValueError, match=r"my_photos: no measured state for interaction\(s\) \['twist_x'\]"):
        photo_targets(measured([s for s in STATES if s[0] != "twist_x"]), source="my_photos")
    with pytest.raises(ValueError, match="non-empty subset"):
        photo_targets(measured(), ["poke"])


def test_geometry_from_file_names_and_the_twist_z_quirk():
    targets = {t.kind: t for t in photo_targets(measured())}
    assert target_geometry(targets["press"]) == {"depth_mm": 4.0}
    assert target_geometry(targets["twist_x"]) == {"depth_mm": 2.0, "angle_deg": 20.0}
    assert target_geometry(targets["twist_z"]) == {"depth_mm": 4.0}  # reference: canonical 30 deg
    assert target_geometry(targets["twist_z"], twist_z_angle="filename") == {"depth_mm": 4.0, "angle_deg": 90.0}
    assert target_geometry(targets["twist_x"], geometry="canonical") == {}
    with pytest.raises(ValueError, match="twist_z_angle"):
        target_geometry(targets["twist_z"], twist_z_angle="photo")


def test_batch_layout_divergence_and_holdout():
    targets = photo_targets(measured())
    twin = FakeTwin(targets)
    obj = PhotoObjective(targets, twin, fit=["press", "twist_x", "slide"], fixed={"k_n_ref": 5e4})
    res = obj.evaluate([{"E": 6e5}, {"E": 9.5e5}, {"E": 5e5}])
    assert len(twin.calls) == 1 and len(twin.calls[0]) == 12  # one twin call: 3 proposals x 4 photos
    kinds, params = zip(*twin.calls[0])
    assert list(kinds[:4]) == list(INTERACTIONS)
    assert params[0] == {"E": 6e5, "k_n": 1e4, "vessel": False, "depth_mm": 4.0}
    assert params[2]["angle_deg"] == 20.0 and "angle_deg" not in params[1]
    assert res[0].value == pytest.approx(1.0, abs=1e-3) and not res[0].diverged
    assert res[0].metrics["mae_px/heldout"] == pytest.approx(1.0, abs=1e-3)
    assert res[1].diverged and res[1].value == 165.0
    assert res[2].value == pytest.approx(0.0, abs=1e-3)
    with pytest.raises(ValueError, match="fitted interactions"):
        PhotoObjective(targets, twin, fit=["poke"])


def test_undeformed_baseline():
    targets = photo_targets(measured())
    assert undeformed_mae(REST, targets)["press"] == pytest.approx(3.0 * np.sqrt(2))
    assert marker_mae_px(REST, REST) == 0.0
