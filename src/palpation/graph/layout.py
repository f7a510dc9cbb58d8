"""The rest layout graphs are built on: the measured rest template, or an ideal hexagon for tests."""

from __future__ import annotations

import numpy as np

from palpation.graph.augment import ROTATION_CENTRE_PX
from palpation.markers.lattice import ideal_hex_lattice

PITCH_PX = 55.0  # real marker pitch (SPEC §1.2)
RESTS = ("template", "ideal")


def rest_layout(source: str = "template") -> np.ndarray:
    """(127, 2) px in base-graph order. `template`: markers of the shipped rest photo (SPEC §5.2);
    `ideal`: a regular hexagon of 55 px pitch centred on the rotation centre (no photo needed)."""
    if source == "template":
        from palpation.markers.template import rest_template

        return rest_template()
    if source == "ideal":
        return ideal_hex_lattice(PITCH_PX, 0.0, ROTATION_CENTRE_PX)
    raise ValueError(f"unknown rest layout '{source}': use one of {RESTS}")
