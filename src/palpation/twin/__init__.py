"""Warp digital twin of the ViTacTip: mesh, batched Neo-Hookean FEM, vessel contact.

Public API (the FEM core; trajectories, markers and the runner build on it):
    build_sensor_mesh, SensorMesh, box_mesh      twin.mesh
    TwinConfig (+ sub-configs), from_reference_units  twin.config
    BatchedTwin                                  twin.simulator
    time_substeps                                twin.bench
Units: SI (metres, newtons, seconds) in the world frame A; see docs/twin.md.
"""

from palpation.twin.config import (ContactConfig, DampingConfig, HealthConfig, IntegratorConfig,
                                   MaterialConfig, MeshConfig, SceneConfig, TwinConfig,
                                   from_reference_units)
from palpation.twin.mesh import RESOLUTIONS, SensorMesh, box_mesh, build_sensor_mesh

__all__ = ["BatchedTwin", "ContactConfig", "DampingConfig", "HealthConfig", "IntegratorConfig",
           "MaterialConfig", "MeshConfig", "RESOLUTIONS", "SceneConfig", "SensorMesh", "TwinConfig",
           "box_mesh", "build_sensor_mesh", "from_reference_units", "time_substeps"]


def __getattr__(name):
    # keep `import palpation.twin` light (no Warp init) until the simulator is needed
    if name == "BatchedTwin":
        from palpation.twin.simulator import BatchedTwin
        return BatchedTwin
    if name == "time_substeps":
        from palpation.twin.bench import time_substeps
        return time_substeps
    raise AttributeError(f"module 'palpation.twin' has no attribute {name!r}")
