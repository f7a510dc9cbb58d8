"""Shared twin fixtures: the coarse sensor mesh (cached by rule `mesh` or PALPATION_MESH_CACHE) and its
marker binding, built once per test module as before."""

import os

import pytest

from palpation.markers.template import rest_template
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import cached_sensor_mesh


@pytest.fixture(scope="module")
def mesh():
    return cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE"))


@pytest.fixture(scope="module")
def binding(mesh):
    return bind_markers(mesh.nodes, mesh.dome_nodes, rest_template())
