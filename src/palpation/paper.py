"""The paper's twin: the physical constants its simulator was built and calibrated with (SPEC §1.2-§6.4).

These are inputs of the model, in the reference's own units; the twin's defaults (twin.config), the
calibration's paper point and the loop's nominal values are derived from them here, never restated.
The paper's published *results* (tables and metrics the code compares against) live in report.paper.
"""

from __future__ import annotations

LENGTH_SCALE = 5.0  # reference sim length / physical length (SPEC §1.2)

E = 881400.0  # Pa, Young's modulus: the calibrated 881,359 Pa adopted rounded (SPEC §2.3, §6.4)
NU = 0.497  # Poisson ratio (SPEC §2.3)
RHO = 1100.0  # kg/m^3 (SPEC §2.3)
ALPHA_REF = 0.1  # damping alpha, reference units (SPEC §2.3)
BETA = 0.01  # fraction removed from the elastic force (SPEC §2.3)

K_N_REF = 94908.307  # calibrated sensor-vessel normal stiffness, reference units (SPEC §3.3, §6.4)
C_N_REF = 100.0  # contact damping (SPEC §3.3); not length-scaled
