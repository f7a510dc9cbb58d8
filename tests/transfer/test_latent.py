"""The latent press depth of a slide recovered by the twin-made lookup (palpation.transfer.latent), and the Sim set's
depth options of palpation.apps.simulate (set=depth_bank, dataset.depths_from)."""

import numpy as np
import pytest
from omegaconf import OmegaConf

from palpation.apps.simulate import set_depths, trajectory_set
from palpation.graph.layout import rest_layout
from palpation.io import csv_text, save_text
from palpation.transfer.latent import DepthLookup, draw_depths, read_estimates, slide_signature

REST = rest_layout("ideal").astype(np.float64)


def toy_slide(depth_mm, rng, n_frames=20, drift_px=30.0):
    """A stand-in for a twin slide: the press spreads the markers radially (more with depth, most near the centre
    of the dome) and squeezes the field anisotropically as the tip slides; the whole field drifts along the slide
    (what every real trial does differently) and the detector adds noise."""
    c = REST.mean(0)
    r = REST - c
    rad = np.linalg.norm(r, axis=1, keepdims=True) / np.linalg.norm(r, axis=1).max()
    spread = 0.9 * depth_mm * r / max(np.linalg.norm(r, axis=1).max(), 1) * 8 * np.exp(-rad ** 2)
    t = np.linspace(0, 1, n_frames)[:, None, None]
    shear = 0.02 * depth_mm * np.sin(2 * np.pi * t) * r[None, :, ::-1]
    drift = drift_px * np.concatenate([t, -0.5 * t], -1)
    return REST + spread + shear + drift + rng.normal(0, 0.3, (n_frames, *REST.shape))


def test_signature_ignores_the_whole_field_drift():
    rng = np.random.default_rng(0)
    a = slide_signature(toy_slide(3.0, np.random.default_rng(1), drift_px=0.0), REST)
    b = slide_signature(toy_slide(3.0, np.random.default_rng(1), drift_px=80.0), REST)
    np.testing.assert_allclose(a, b, atol=1e-9)
    assert slide_signature(toy_slide(5.0, rng), REST)[0] > a[0] > slide_signature(toy_slide(1.0, rng), REST)[0] > 0


def test_depth_of_a_slide_recovered_from_a_bank_at_known_depths():
    rng = np.random.default_rng(4)
    bank = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    lookup = DepthLookup.fit(np.array([slide_signature(toy_slide(d, rng), REST) for d in bank]), np.array(bank))
    assert lookup.loo_rmse_mm < 0.15 and lookup.n_bank == 6
    for depth, drift in ((2.7, 55.0), (4.4, -20.0)):  # unseen depths, another drift and noise
        est = lookup.estimate(slide_signature(toy_slide(depth, rng, n_frames=16, drift_px=drift), REST))[0]
        assert abs(est - depth) < 0.15, (depth, est)
    with pytest.raises(ValueError, match="at 2 or more depths"):
        DepthLookup.fit(np.ones((5, 2)), np.full(5, 3.0))
    # a slide that does not move (a tissue far softer than the bank's surface) lies below the bank: extrapolated
    still = REST[None].repeat(8, 0)
    flags = lookup.in_bank(np.array([slide_signature(toy_slide(3.5, rng), REST), slide_signature(still, REST)]))
    assert flags.tolist() == [True, False] and lookup.bank_mm == (1.0, 6.0)
    assert lookup.raw(slide_signature(still, REST))[0] < 1.0 - 2 * lookup.loo_rmse_mm


def test_sim_depths_drawn_over_the_estimates_leave_the_other_draws_alone(tmp_path):
    path = tmp_path / "latent_depth.csv"
    rows = [{"set": "meat", "trial": f"t{i}", "depth_mm": d, "in_bank": "true"} for i, d in enumerate([1.5, 2.5, 4.0])]
    save_text(path, csv_text([*rows, {"set": "silicone", "trial": "s0", "depth_mm": 0.0, "in_bank": "false"}],
                             ("set", "trial", "depth_mm", "in_bank"), 4))
    est = read_estimates(path)  # the extrapolated estimate is left out
    assert est.tolist() == [1.5, 2.5, 4.0]
    depths = draw_depths(est, 40, seed=42)
    assert set(depths) <= set(est) and len(set(depths)) == 3 and np.array_equal(depths, draw_depths(est, 40, 42))
    cfg = OmegaConf.create({"set": "randomised", "n_pairs": 4, "seed": 42, "dataset": {"depths_from": str(path)}})
    plain = trajectory_set("randomised", 42, 4)
    spread = trajectory_set("randomised", 42, 4, depths_mm=set_depths(cfg))
    assert [r.depth_mm for r in plain] == [None] * 8
    assert [r.depth_mm for r in spread][::2] == [r.depth_mm for r in spread][1::2] == list(draw_depths(est, 4, 42))
    strip = lambda r: (r.heading_offset_deg, r.twin, r.vessel, r.name)  # noqa: E731
    assert [strip(r) for r in plain] == [strip(r) for r in spread]  # heading, k_n, c_n: the same draws
    assert set_depths(OmegaConf.create({"set": "randomised", "dataset": {"depths_from": None}})) is None
    bank = trajectory_set("depth_bank", 0, depths_mm=[1.0, 3.0])
    assert [(r.depth_mm, r.vessel, r.kind) for r in bank] == [(1.0, False, "slide"), (3.0, False, "slide")]
    save_text(path, "set,trial,depth_mm,in_bank\nmeat,t0,12.0,true\n")
    with pytest.raises(ValueError, match="depth_mm in"):
        read_estimates(path)
    save_text(path, "set,trial,depth_mm,in_bank\nmeat,t0,0.0,false\nmeat,t1,0.0,false\n")
    with pytest.raises(ValueError, match="every estimate lies outside its bank's depths"):
        read_estimates(path)
    save_text(path, "set,trial,depth_mm\nmeat,t0,2.0\n")  # written before the flag: refused, rerun the script
    with pytest.raises(ValueError, match="in_bank"):
        read_estimates(path)


def test_depth_of_a_twin_made_slide_recovered_from_a_twin_made_bank(tmp_path):
    """The lookup on the twin itself (coarse mesh, CPU, slides cut short, the phantom surface on): a bank at 1-5 mm
    made by set=depth_bank, and four twin slides at depths the bank never saw, recovered within a quarter millimetre.
    Without the surface the twin's vessel-free slides move no marker at any depth: the bank is refused."""
    import os

    from hydra import compose, initialize_config_dir

    from palpation.apps.simulate import run
    from palpation.paths import REPO_ROOT
    from palpation.transfer.latent import SIGNATURE, bank_lookup
    from palpation.twin.mesh import cached_sensor_mesh

    mesh = tmp_path / "mesh.npz"
    cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE")).save(mesh)

    def bank(name, depths, contact=("twin.contact.phantom_contact=true", "twin.contact.k_s=2000")):
        with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
            cfg = compose(config_name="simulate", overrides=[
                "set=depth_bank", f"bank_depths_mm=[{','.join(map(str, depths))}]", "max_frames=120",
                "progress=false", "track=false", f"mesh={mesh}", f"out.dir={tmp_path / name}", *contact])
        return run(cfg)["manifest"]

    lookup, rows = bank_lookup(bank("bank", [1.0, 2.0, 3.0, 4.0, 5.0]))
    assert lookup.n_bank == 5 and lookup.loo_rmse_mm < 0.25
    _, held = bank_lookup(bank("held", [1.5, 2.5, 3.5, 4.5]))  # only their signatures are used, not their fit
    estimates = lookup.estimate(np.array([[r[k] for k in SIGNATURE] for r in held]))
    assert np.all(np.abs(estimates - [r["depth_mm"] for r in held]) < 0.25), (estimates, held)
    with pytest.raises(ValueError, match="set=depth_bank: the twin has no phantom surface"):
        bank("flat", [1.0, 2.0], contact=())
