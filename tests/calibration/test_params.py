"""The registry of searchable twin parameters: units, conversions and the checks before any simulation."""

import logging

import pytest

from palpation.calibration.config import CalibrationConfig, SearchParam
from palpation.calibration.params import REGISTRY, check_space, inert, to_env, twin_overrides, warn_inert
from palpation.calibration.search import ParamSpec
from palpation.twin.config import TwinConfig
from palpation.twin.parameters import ENV_KEYS, PARAMETERS


def test_every_name_maps_to_a_per_env_parameter_every_twin_takes():
    assert {p.field for p in REGISTRY.values()} == set(ENV_KEYS)
    assert set(REGISTRY) == set(ENV_KEYS) | {"k_n_ref", "k_t_ref"}  # not alpha / shell_ratio: layered only


def test_reference_units_are_converted_to_the_twin():
    env = to_env({"E": 881400.0, "k_n_ref": 94908.307, "k_t_ref": 10.0, "nu": 0.49})
    assert env == pytest.approx({"E": 881400.0, "k_n": 94908.307 / 5, "k_t": 2.0, "nu": 0.49})
    assert twin_overrides({"E": 2e5, "k_n_ref": 5e4, "k_s": 1e3}) == {"material": {"E": 2e5},
                                                                       "contact": {"k_n": 1e4, "k_s": 1e3}}


@pytest.mark.parametrize("space, fixed, match", [
    ([ParamSpec("young", 1.0, 2.0)], {}, "unknown parameter 'young'"),
    ([ParamSpec("E", 1e6, 1e5)], {}, "low < high"),
    ([ParamSpec("E", 1e5, 1e5)], {}, "low < high"),
    ([ParamSpec("E", -1.0, 1e6)], {}, "must be > 0"),
    ([ParamSpec("E", 1e5, 1e6)], {"kn": 3.0}, r"calibration.fixed: unknown twin parameter\(s\) \['kn'\]"),
    ([ParamSpec("k_n", 1e3, 1e4)], {"k_n_ref": 5e4}, r"\['k_n'\] are set twice"),
    ([ParamSpec("E", 1e5, 1e6)], {"E": 5e5}, "set twice"),
])
def test_bad_spaces_fail_with_the_name(space, fixed, match):
    with pytest.raises(ValueError, match=match):
        check_space(space, fixed)


def test_non_log_bounds_may_include_zero():
    check_space([ParamSpec("mu", 0.0, 1.0, log=False)], {})


def test_contact_terms_without_a_partner_are_flagged(caplog):
    assert inert(["E", "k_n_ref", "k_s", "mu"], vessel=False, phantom_contact=False) == ["k_n_ref", "k_s", "mu"]
    assert inert(["E", "k_n_ref", "k_s", "mu"], vessel=True, phantom_contact=False) == ["k_s"]
    assert inert(["k_s", "mu"], vessel=False, phantom_contact=True) == []
    with caplog.at_level(logging.WARNING):
        warn_inert([ParamSpec("k_n_ref", 1e4, 1e5)], vessel=False, cfg=TwinConfig(), where="test")
    assert "cannot act" in caplog.text


@pytest.mark.parametrize("spec, said", [
    (ParamSpec("E", 1e4, 1e6), "range [10000, 1e+06] of 'E' leaves its physical bounds [100000, 2e+06] Pa"),
    (ParamSpec("k_n_ref", 1e4, 1e6), "'k_n_ref' leaves its physical bounds [5000, 100000]"),
    (ParamSpec("mu", 0.0, 3.0, log=False), "'mu' leaves"),
    (ParamSpec("E", 1e5, 1e6), ""),
])
def test_search_ranges_outside_the_registry_bounds_are_logged(spec, said, caplog):
    with caplog.at_level(logging.WARNING):
        check_space([spec], {})
    assert (said in caplog.text) if said else "leaves" not in caplog.text


def test_bounds_left_out_come_from_the_registry():
    cfg = CalibrationConfig(params=[SearchParam("k_n_ref"), SearchParam("E", 2e5, None, False)])
    k_n, E = PARAMETERS["k_n"], PARAMETERS["E"]
    assert cfg.space() == [ParamSpec("k_n_ref", k_n.low * 5, k_n.high * 5, True), ParamSpec("E", 2e5, E.high, False)]
    check_space(cfg.space(), {})
    with pytest.raises(ValueError, match="calibration.params: unknown parameter 'young'"):
        CalibrationConfig(params=[SearchParam("young")]).space()
