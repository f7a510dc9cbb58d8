"""The loop starts from the twin it is given: overrides and fitted.yaml files are honoured or refused."""

from dataclasses import replace

import pytest
from omegaconf import OmegaConf

from palpation.loop.config import LoopConfig
from palpation.loop.real import make_problem
from palpation.loop.start import nominal_projection, read_start, start_twin
from palpation.twin.config import TwinConfig

SHELL = 1.5e-3


def _with(**sections) -> TwinConfig:
    cfg = TwinConfig()
    return replace(cfg, **{k: replace(getattr(cfg, k), **v) for k, v in sections.items()})


def test_reference_twin_starts_with_no_effect():
    on, params = start_twin(TwinConfig(), SHELL)
    assert on == [] and params["k_s"] == 0.0 and params["E"] == TwinConfig().material.E


def test_contact_override_is_honoured_not_dropped():
    on, params = start_twin(_with(contact={"phantom_contact": True, "k_s": 2000.0}), SHELL)
    assert on == ["surface_contact"] and params["k_s"] == 2000.0
    on, params = start_twin(_with(contact={"phantom_contact": True, "k_s": 2000.0, "mu": 0.9},
                                  camera={"dx_px": 25.0}), SHELL)
    assert set(on) == {"surface_contact", "friction", "camera"} and params["mu"] == 0.9
    assert params["cam_dx_px"] == 25.0 and nominal_projection(_with(camera={"dx_px": 25.0})).camera.is_identity


def test_problem_starts_at_the_override_and_drops_it_from_the_candidates():
    from palpation.measured import MeasuredState, make_measured_set
    from palpation.markers.template import rest_template
    import numpy as np
    rest = rest_template().astype(np.float32)
    mset = make_measured_set(np.stack([rest, rest]), np.ones((2, 127), bool), rest,
                             [MeasuredState("press_d4", "p.jpg", "press", 4.0),
                              MeasuredState("slide_d2", "s.jpg", "slide", 2.0)])
    on, params = start_twin(_with(contact={"phantom_contact": True, "k_s": 2000.0}), SHELL)
    p = make_problem(mset, "x", LoopConfig(), params, effects_on=on)
    assert p.params["k_s"] == 2000.0 and "surface_contact" not in p.candidates
    assert p.effects == ["surface_contact"] and "k_s" in p.searched


def test_values_the_loop_cannot_honour_are_refused_in_one_line():
    with pytest.raises(ValueError, match=r"twin.contact.mu=0.9 acts only with contact.*phantom_contact=true"):
        start_twin(_with(contact={"mu": 0.9}), SHELL)
    with pytest.raises(ValueError, match="loop.shell_thickness_mm=2"):
        start_twin(_with(material={"shell_thickness": 2e-3}), SHELL)


def test_fitted_yaml_is_read(tmp_path):
    f = tmp_path / "fitted.yaml"
    f.write_text("# @package twin\ncontact: {phantom_contact: true, k_s: 3000.0}\nmaterial: {E: 1.5e6}\n")
    merged = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(TwinConfig), read_start(f)))
    on, params = start_twin(merged, SHELL)
    assert on == ["surface_contact"] and params["k_s"] == 3000.0 and params["E"] == 1.5e6
    with pytest.raises(ValueError, match="no such file"):
        read_start(tmp_path / "missing.yaml")
    (tmp_path / "bad.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(ValueError, match="expected a mapping"):
        read_start(tmp_path / "bad.yaml")
