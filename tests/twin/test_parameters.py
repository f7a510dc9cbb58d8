"""The twin's parameter registry: every entry names a real config field, its defaults come from the config
(and the config's from the paper), and every per-env entry reaches the arrays its kernel reads."""

import dataclasses

import numpy as np
import pytest

from palpation import paper
from palpation.twin.config import TwinConfig
from palpation.twin.elasticity import lame_parameters
from palpation.twin.mesh import box_mesh
from palpation.twin.parameters import (ALIASES, CONTACT_KEYS, LAYERED_KEYS, PARAMETERS, by_env_key, outside_bounds,
                                       per_env_keys)
from palpation.twin.runner import EnvRequest, simulate_states
from palpation.twin.simulator import BatchedTwin


def layered_config() -> TwinConfig:
    cfg = TwinConfig()
    return dataclasses.replace(cfg, damping=dataclasses.replace(cfg.damping, per_env=True))


def test_entries_name_config_fields_and_their_defaults_lie_inside_the_bounds():
    cfg = TwinConfig()
    for p in PARAMETERS.values():
        assert p.scope in ("env", "layered", "camera", "mount", "markers") and p.needs in (
            "", "vessel", "phantom", "contact", "shell")
        assert p.low < p.high and (not p.log or p.low > 0), p.name
        assert p.low <= p.default(cfg) <= p.high, p.name  # the shipped twin is a point of its own search space
    assert PARAMETERS["mount_dz_mm"].default(dataclasses.replace(cfg, mount=dataclasses.replace(cfg.mount, dz=2e-4))
                                             ) == pytest.approx(0.2)  # mm, the field in metres
    assert set(per_env_keys()) == {p.field for p in PARAMETERS.values() if p.per_env}


def test_defaults_are_read_from_the_config_and_the_config_from_the_paper():
    cfg = TwinConfig()
    assert (cfg.material.E, cfg.material.nu, cfg.material.rho) == (paper.E, paper.NU, paper.RHO)
    assert (cfg.contact.k_n, cfg.contact.c_n) == (paper.K_N_REF / paper.LENGTH_SCALE, paper.C_N_REF)
    assert (cfg.damping.alpha, cfg.damping.beta) == (paper.ALPHA_REF / paper.LENGTH_SCALE, paper.BETA)
    soft = dataclasses.replace(cfg, material=dataclasses.replace(cfg.material, E=3e5))
    assert PARAMETERS["E"].default(soft) == 3e5 and EnvRequest("press").resolved(soft).E == 3e5
    assert PARAMETERS["k_s"].off_value(cfg) == 0.0 and PARAMETERS["alpha"].off_value(cfg) == cfg.damping.alpha


def test_reference_unit_aliases_scale_by_the_length_scale():
    k_n, alias = PARAMETERS["k_n"], ALIASES["k_n_ref"]
    assert alias.field == "k_n" and alias.scale == 1.0 / paper.LENGTH_SCALE
    assert (alias.low, alias.high) == (k_n.low * 5, k_n.high * 5)
    assert outside_bounds("k_n_ref", 1e4, 1e5) == ""  # SPEC §6.3's search range
    assert outside_bounds("k_n_ref", 1e4, 1e6).startswith("range [10000, 1e+06] of 'k_n_ref' leaves")
    with pytest.raises(ValueError, match="unknown twin parameter 'young'"):
        outside_bounds("young", 1.0, 2.0)


def test_every_per_env_entry_reaches_the_array_its_kernel_reads():
    mesh = box_mesh()
    cfg = layered_config()
    values = {key: np.array([0.9, 1.1]) * by_env_key(key).default(cfg) + np.array([0.01, 0.02])
              for key in per_env_keys()}
    values["nu"] = np.array([0.45, 0.46])
    sim = BatchedTwin(mesh, 2, cfg, values, device="cpu")
    for key in CONTACT_KEYS:
        assert np.array_equal(getattr(sim.contact, key).numpy(), values[key].astype(np.float32)), key
    for key in LAYERED_KEYS:
        assert np.array_equal(getattr(sim, f"env_{key}").numpy(), values[key].astype(np.float32)), key
    mu, lam = lame_parameters(values["E"], values["nu"], cfg.material.lame)
    assert np.array_equal(sim.env_mu.numpy(), mu.astype(np.float32))
    assert np.array_equal(sim.env_lam.numpy(), lam.astype(np.float32))
    assert set(per_env_keys()) == set(CONTACT_KEYS) | set(LAYERED_KEYS) | {"E", "nu"}  # nothing left unread
    with pytest.raises(ValueError, match=r"unknown env parameter\(s\) \['young'\]"):
        sim.set_env_params({"young": 1.0})


def test_a_request_takes_exactly_the_registry_names():
    req = EnvRequest("press", 5.0, E=6e5, vessel=True)
    assert req.E == 6e5 and req.k_n is None and req.heading_offset_deg == 5.0
    full = req.resolved(TwinConfig())
    assert full.twin == {**{k: by_env_key(k).default(TwinConfig()) for k in per_env_keys(False)}, "E": 6e5}
    assert "alpha" in EnvRequest("press").resolved(layered_config()).twin  # the layered kernel takes it per env
    with pytest.raises(ValueError, match=r"EnvRequest: unknown twin parameter\(s\) \['young'\]"):
        EnvRequest("press", young=1.0)
    with pytest.raises(ValueError, match=r"request 0 \(press\): unknown parameters \['young'\]"):
        simulate_states(box_mesh(), TwinConfig(), [("press", {"young": 1.0})])
