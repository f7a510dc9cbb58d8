"""Photo-set measurement: state names, photo order, and a replication of the reference's numbers."""

import pytest

from palpation.markers.manifest import state_name
from palpation.markers.photoset import list_photos, reference_pipeline_baselines
from palpation.paths import FLAT_TIP_PHOTOS

REST = "press_press_depth=0_angle=10_slide_length=50_timestamp=2025-08-30-21-23-00.jpg"


def test_photo_order_and_names():
    names = [state_name(p) for p in list_photos(FLAT_TIP_PHOTOS)]
    assert names == ["press_d0", "sensor_default_state", "press_d4", "twist_z_d4_a90", "twist_x_d2_a20",
                     "slide_d3"]


def test_reference_pipeline_reproduces_spec_baselines():
    """With the reference's blob detectors and hand-placed markers, our base-graph order and Hungarian
    give SPEC §15.8's undeformed baselines: this pins the ordering, not the detector."""
    spec = {"press_d4": (13.95, 13.81), "twist_z_d4_a90": (15.40, 15.29),
            "twist_x_d2_a20": (16.27, 16.74), "slide_d3": (14.15, 14.70)}
    got = reference_pipeline_baselines(list_photos(FLAT_TIP_PHOTOS), REST)
    for name, (template_mae, rest_mae) in spec.items():
        assert got[name]["baseline_mae_template_px"] == pytest.approx(template_mae, abs=0.03)
        assert got[name]["baseline_mae_rest_photo_px"] == pytest.approx(rest_mae, abs=0.03)
