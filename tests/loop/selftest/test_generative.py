"""The generative self-test (loop.generative): the draws, the outside library's known answers, resume, and one
end-to-end run of the app on the coarse mesh at toy sizes."""

import csv
import io
import json
import os

import numpy as np
import pytest

from palpation.loop.config import LoopConfig, SelftestConfig
from palpation.loop.effects import EFFECTS
from palpation.loop.generative_config import GenerativeConfig
from palpation.loop.inputs import load_targets
from palpation.loop.problem import initial_params
from palpation.loop.selftest import generative as gen
from palpation.loop.selftest.fixed import make_sets, simulate_injections
from palpation.loop.selftest.generative_report import by_effect, summary
from palpation.loop.unlisted import ANISO_PX, DEFECT_MARKERS, DEFECT_PX, STIFFEN_PX, UNLISTED, twin_rest
from palpation.markers.template import rest_template
from palpation.measured import MeasuredState, load_measured_set, make_measured_set, save_measured_set

REST = rest_template().astype(np.float64)
BASE = initial_params({"E": 1.2225e6})
STATES = [MeasuredState("press_d4", "p.jpg", "press", 4.0), MeasuredState("twist_x_d2", "t.jpg", "twist_x", 2.0, 20.0)]
NOISE = 0.2


def _cfg(**gen_kw) -> LoopConfig:
    return LoopConfig(selftest=SelftestConfig(states=["press", "twist_x"], holdout=["twist_x"]),
                      generative=GenerativeConfig(**gen_kw)).validate()


def _press(scale: float = 40.0) -> np.ndarray:
    """Two contact-sized states (an outward bulge up to ~0.4 x scale px, a 3 deg twist) about REST, (2, 127, 2)."""
    q = REST - REST.mean(0)
    bump = np.exp(-(np.linalg.norm(q, axis=1, keepdims=True) / 180) ** 2)
    ang = np.deg2rad(3) * bump
    twist = REST.mean(0) + np.concatenate([np.cos(ang) * q[:, :1] - np.sin(ang) * q[:, 1:],
                                           np.sin(ang) * q[:, :1] + np.cos(ang) * q[:, 1:]], 1)
    return np.stack([REST + scale * bump * q / 180, twist])


def _similarity_rms(src: np.ndarray, dst: np.ndarray) -> float:
    """RMS (per marker) of dst after the least-squares image similarity of src (scale, rotation, shift)."""
    n = len(src)
    a = np.zeros((2 * n, 4))
    a[0::2] = np.c_[src[:, 0], -src[:, 1], np.ones(n), np.zeros(n)]
    a[1::2] = np.c_[src[:, 1], src[:, 0], np.zeros(n), np.ones(n)]
    x, *_ = np.linalg.lstsq(a, dst.reshape(-1), rcond=None)
    return float(np.sqrt(((a @ x - dst.reshape(-1)) ** 2).sum() / n))


# ---- the draw ----

def test_draws_respect_requires_the_cap_and_log_uniform_ranges():
    cfg = _cfg()
    g = cfg.generative
    draws = [gen.draw(cfg, BASE, 0, r) for r in range(400)]
    counts = np.bincount([len(d.effects) for d in draws], minlength=4)
    assert counts.sum() == 400 and len(counts) == 4 and counts.min() > 20  # 0..3 in-list effects, no more
    assert all("surface_contact" in d.effects for d in draws if "friction" in d.effects)  # requires, counted
    assert 0.18 < np.mean([bool(d.unlisted) for d in draws]) < 0.32 and all(len(d.unlisted) <= 1 for d in draws)
    assert {u for d in draws for u in d.unlisted} == set(UNLISTED)
    pos = []  # each strength's place in its range on a log scale: uniform in [0, 1]
    for d in draws:
        assert g.E[0] <= d.params["E"] <= g.E[1]
        contact = "surface_contact" in d.effects
        assert (g.k_s[0] <= d.params["k_s"] <= g.k_s[1]) if contact else d.params["k_s"] == 0.0
        for e in d.effects:
            lo, hi = g.k_s if e == "surface_contact" else g.strengths[e]
            v = d.params["k_s"] if e == "surface_contact" else d.strengths[e]
            assert lo <= v <= hi
            pos.append(np.log(v / lo) / np.log(hi / lo))
            betas = [b for k, b in d.betas.items() if k.startswith(e + ".")]
            assert np.linalg.norm(betas) == pytest.approx(d.strengths[e])  # a unit direction times the strength
        for u in d.unlisted:
            assert g.unlisted[u][0] <= d.strengths[u] <= g.unlisted[u][1]
        assert d.label == "+".join([*d.effects, *("unlisted:" + u for u in d.unlisted)])
    pos = np.array(pos)
    assert abs(pos.mean() - 0.5) < 0.05 and abs((pos < 0.25).mean() - 0.25) < 0.05  # log-, not linear-uniform


def test_pick_effects_counts_providers_and_never_overshoots():
    rng = np.random.default_rng(0)
    for _ in range(50):
        one = gen.pick_effects(["surface_contact", "friction", "camera"], 1, rng)
        assert len(one) == 1 and one != ["friction"]
        two = gen.pick_effects(["surface_contact", "friction"], 2, rng)
        assert two == ["surface_contact", "friction"]
    assert gen.pick_effects(["friction"], 1, rng, present=["surface_contact"]) == ["friction"]
    assert gen.pick_effects(["friction", "camera"], 3, rng) == ["camera"]  # no provider to draw: friction is passed


def test_dev_and_test_truths_are_disjoint_and_reproducible(tmp_path):
    cfg = _cfg()
    a, b = gen.draw(cfg, BASE, 0, 3), gen.draw(cfg, BASE, 0, 3)
    assert (a.label, a.params, a.strengths, a.betas, a.tag) == (b.label, b.params, b.strengths, b.betas, b.tag)
    assert a.tag == "dev_seed0_run3" and gen.draw(cfg, BASE, 1000, 3).tag == "test_seed1000_run3"
    assert a.params["E"] != gen.draw(cfg, BASE, 1000, 3).params["E"]
    with pytest.raises(ValueError, match="dev seeds in"):
        GenerativeConfig(dev_seeds=[1000]).validate(cfg)
    with pytest.raises(ValueError, match="test seeds >= 1000"):
        GenerativeConfig(test_seeds=[7]).validate(cfg)
    with pytest.raises(ValueError, match="leaves the search bounds"):
        GenerativeConfig(E=[5e5, 5e6]).validate(cfg)
    # a run remade alone equals the same run made in a batch: truth, redraw and set (outside draws, noise)
    template = load_targets(make_measured_set(np.stack([REST, REST]).astype(np.float32), np.ones((2, 127), bool),
                                              REST, STATES), "geometry", [], ["press", "twist_x"])
    geometry = {s.name: s for s in STATES}

    def simulate(jobs):  # markers that depend on every parameter; runs 2 and 5 diverge on their first draw
        first = {tuple(gen.draw(cfg, BASE, 0, r).params.items()) for r in (2, 5)}
        out = [REST + 1e-6 * sum(np.sin(i + 1.0) * v for i, v in enumerate(p.values())) + 0.3 * s.depth_mm
               for s, p in jobs]
        return np.stack(out), np.array([tuple(p.items()) in first for _, p in jobs])

    def made(runs, where):
        injs = [gen.draw(cfg, BASE, 0, r) for r in runs]
        markers = simulate_injections(injs, template, simulate, cfg, BASE,
                                      lambda i, k: gen.draw(cfg, BASE, 0, i.run, k))
        for inj in injs:
            inj.rest = REST
        paths = make_sets(injs, markers, template, NOISE, None, tmp_path / where, geometry, REST)
        return injs, [load_measured_set(p).markers for p in paths]

    batch, sets = made(range(6), "batch")
    assert [i.redrawn for i in batch] == [0, 0, 1, 0, 0, 1]
    for r in (2, 3):
        (alone,), (mset,) = made([r], f"alone{r}")
        assert alone.params == batch[r].params and alone.redrawn == batch[r].redrawn
        np.testing.assert_array_equal(mset, sets[r])


# ---- the outside library: known answers ----

def test_each_outside_kind_changes_markers_and_escapes_a_similarity():
    m = _press()
    for name, u in UNLISTED.items():
        out = u(m.copy(), u.strength[0], np.random.default_rng(1), REST)
        assert out.shape == m.shape and np.abs(out - m).max() > 1.0, name
        # one camera for every state: neither an image similarity nor the camera's own (on displacements) absorbs it
        assert _similarity_rms(m.reshape(-1, 2), out.reshape(-1, 2)) > 3 * NOISE, name
        assert _similarity_rms((m - REST).reshape(-1, 2), (out - REST).reshape(-1, 2)) > 3 * NOISE, name


def test_outside_kinds_do_what_they_claim():
    m, rng = _press(), np.random.default_rng(2)
    u, s = m - REST, 1.5
    # tangential distortion: quadratic about the centre (even: the same change at q and -q), linear in strength
    tang = UNLISTED["tangential_distortion"]
    from palpation.loop.residual import CENTRE_PX
    q = np.array([[[100.0, 60.0], [-100.0, -60.0]]]) + CENTRE_PX
    d1 = tang(q, s, np.random.default_rng(3)) - q
    d2 = tang(q, 2 * s, np.random.default_rng(3)) - q
    np.testing.assert_allclose(d1[0, 0], d1[0, 1], atol=1e-9)
    np.testing.assert_allclose(d2, 2 * d1, atol=1e-9)
    # barrel: radial about the centre
    d = UNLISTED["image_distortion"](m, s, rng) - m
    r = m - CENTRE_PX
    assert np.abs(d[..., 0] * r[..., 1] - d[..., 1] * r[..., 0]).max() < 1e-6
    # marker defect: 7 markers, one vector in every state, DEFECT_PX a step
    d = UNLISTED["marker_defect"](m, s, rng) - m
    moved = np.linalg.norm(d, axis=-1) > 0
    assert (moved.sum(axis=1) == DEFECT_MARKERS).all() and (moved[0] == moved[1]).all()
    np.testing.assert_allclose(np.linalg.norm(d[moved], axis=-1), DEFECT_PX * s)
    # strain stiffening: every displacement shrinks along itself, the largest by s x STIFFEN_PX, order kept
    out = UNLISTED["strain_stiffening"](m, 1.0, rng, REST) - REST  # 4 px of 17: below the cap
    mag, mag2 = np.linalg.norm(u, axis=-1), np.linalg.norm(out, axis=-1)
    assert (mag2 <= mag + 1e-12).all() and np.abs(u[..., 0] * out[..., 1] - u[..., 1] * out[..., 0]).max() < 1e-9
    assert mag.max() - mag2.flat[mag.argmax()] == pytest.approx(STIFFEN_PX)
    assert (np.diff(mag2.flat[np.argsort(mag, axis=None)]) > -1e-9).all()
    # anisotropic gel: displacements mapped by one symmetric matrix with scales 1 -+ c, the rest unmoved
    out = UNLISTED["anisotropic_gel"](m, s, rng, REST) - REST
    lin, *_ = np.linalg.lstsq(u.reshape(-1, 2), out.reshape(-1, 2), rcond=None)
    c = s * ANISO_PX / np.linalg.norm(u, axis=-1).max()
    np.testing.assert_allclose(np.sort(np.linalg.eigvalsh(lin)), [1 - c, 1 + c], atol=1e-9)
    np.testing.assert_allclose(UNLISTED["anisotropic_gel"](REST[None], s, rng, REST)[0], REST)
    with pytest.raises(ValueError, match="rest markers"):
        UNLISTED["strain_stiffening"](m, s, rng)
    # a twin's rest: the anchor moves the bound rest towards the template
    np.testing.assert_allclose(twin_rest(REST + 4.0, REST, {"marker_anchor": 0.5}), REST + 2.0)


# ---- resume, CSV, summary (the loop stubbed: it is the fixed self-test's, tested there) ----

def test_resume_skips_finished_runs_and_the_csv_has_exactly_the_columns(tmp_path, monkeypatch):
    calls = []

    def loop_on_sets(cfg, injections, paths, simulate, base, db_path, tkey, max_rounds, progress):
        calls.append([i.tag for i in injections])
        rows = [{"effects_named": "+".join(i.effects) or "none", "mae_before_px": 2.0, "mae_after_px": 0.5,
                 "excess_ratio": float("nan"), "injected_effects": i.effects, "unlisted": i.unlisted,
                 "named": i.effects, "unexplained": bool(i.unlisted), "strengths": i.strengths, "betas": i.betas,
                 "redrawn": i.redrawn, "tries": []} for i in injections]
        problems = [type("P", (), {"params": i.params})() for i in injections]
        return rows, problems

    monkeypatch.setattr(gen, "loop_on_sets", loop_on_sets)
    template = load_targets(make_measured_set(np.stack([REST, REST]).astype(np.float32), np.ones((2, 127), bool),
                                              REST, STATES), "geometry", [], ["press", "twist_x"])

    def simulate(jobs):
        return np.stack([REST + 0.3 * s.depth_mm for s, _ in jobs]), np.zeros(len(jobs), bool)

    def run(cfg):
        return gen.run_generative(cfg, simulate, BASE, template, {s.name: s for s in STATES}, REST, tmp_path,
                                  tmp_path / "study.journal", "toy", rest_of=lambda p: REST)

    cfg = _cfg(runs=5, batch=2)
    rows = run(cfg)
    assert calls == [["dev_seed0_run0", "dev_seed0_run1"], ["dev_seed0_run2", "dev_seed0_run3"], ["dev_seed0_run4"]]
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == [f"dev_seed0_run{r}.json" for r in range(5)]
    # every in-list run carries the oracle's truth (the toy twin moves no marker with an effect: none identifiable)
    assert all(r["identifiable"] == [] for r in rows if not r["unlisted"]) and all(
        "identifiable" not in r for r in rows if r["unlisted"])
    timing = json.loads((tmp_path / "timing.json").read_text())  # one entry per batch, apart from the run records
    assert [b["runs"] for b in timing] == calls and all(b["wall_s"] >= 0 for b in timing)
    calls.clear()
    # an in-list record saved before the oracle is completed on resume
    old = next(p for p in sorted((tmp_path / "runs").iterdir()) if not json.loads(p.read_text())["unlisted"])
    record = json.loads(old.read_text())
    old.write_text(json.dumps({k: v for k, v in record.items() if k not in ("identifiable", "oracle")}))
    assert run(cfg) == rows and calls == []  # ... without running its loop again
    (tmp_path / "runs" / "dev_seed0_run3.json").unlink()
    assert run(cfg) == rows and calls == [["dev_seed0_run3"]]  # only the missing run is made again, identically
    calls.clear()
    test = run(_cfg(runs=2, split="test"))  # the test split joins the same settings' rows
    assert calls == [["test_seed1000_run0", "test_seed1000_run1"]] and [r["split"] for r in test] == ["dev"] * 5 + [
        "test"] * 2
    calls.clear()
    assert len(run(_cfg(runs=5, noise_px=0.3))) == 5 and len(calls[0]) == 5  # other settings: made anew
    text = gen.rows_csv(test)
    table = list(csv.DictReader(io.StringIO(text)))
    assert tuple(next(csv.reader(io.StringIO(text)))) == gen.COLUMNS
    for r, rec in zip(table, test):
        true, fitted = json.loads(r["params_true"]), json.loads(r["params_fitted"])
        assert list(fitted)[:len(true)] == list(true) and list(true)[:2] == ["E", "k_s"]
        assert set(true) == {"E", "k_s", *(n for e in rec["injected_effects"] for n in EFFECTS[e].params)}
        assert set(fitted) == set(true) | {n for e in rec["named"] for n in EFFECTS[e].params}  # spurious ones too
        assert r["effects_injected"] == (rec["effects_injected"] or "none") and r["excess_ratio"] == "nan"
    s = summary(test, NOISE, 0.3)
    assert s["dev"]["runs"] == 5 and s["test"]["runs"] == 2 and s["dev"]["exact_named"] == 1.0
    assert s["dev"]["mae_cut_mean"] == pytest.approx(0.75) and s["dev"]["unexplained_on_exact"] == 0


def test_by_effect_counts_misses_and_spurious_names():
    rows = [{"injected_effects": ["mount", "layered"], "named": ["mount"]},
            {"injected_effects": ["viscous"], "named": ["viscous", "mount"]},
            {"injected_effects": [], "named": []}]
    assert by_effect(rows) == {"layered": {"injected": 1, "found": 0, "spurious": 0},
                               "mount": {"injected": 1, "found": 1, "spurious": 1},
                               "viscous": {"injected": 1, "found": 1, "spurious": 0}}


# ---- end to end: the app on the coarse mesh, toy sizes (numbers mean nothing: trajectories cut) ----

def test_app_generative_mode_writes_the_table(tmp_path):
    from hydra import compose, initialize_config_dir

    from palpation.apps import loop as app
    from palpation.paths import REPO_ROOT
    from palpation.twin.mesh import cached_sensor_mesh

    cached_sensor_mesh("coarse", os.environ.get("PALPATION_MESH_CACHE")).save(tmp_path / "mesh.npz")
    states = [MeasuredState("rest", "r.jpg", "rest", 0.0), *STATES]
    save_measured_set(tmp_path / "geometry", make_measured_set(np.stack([REST] * 3).astype(np.float32),
                                                               np.ones((3, 127), bool), REST, states))
    out = tmp_path / "out"
    sizes = [f"mesh={tmp_path / 'mesh.npz'}", f"measured={tmp_path / 'geometry'}", "loop.max_frames=30",
             "loop.search.n_trials=2", "loop.search.n_startup=1", "loop.method.tries_per_round=1",
             "loop.method.pair_tries=0", "loop.method.polish_iters=0", "loop.method.final_refit_iters=0",
             "loop.effects=[surface_contact,camera]", "loop.selftest.states=[press,twist_x]",
             "loop.selftest.holdout=[twist_x]", "loop.generative.runs=2", "loop.generative.max_rounds=1",
             "loop.generative.n_effects=[0,1]", "loop.generative.unlisted_share=0.5", "loop.generative.dev_seeds=[2]"]
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="loop", overrides=[*sizes, "track=false", "progress=false", f"out.dir={out}",
                                                     "mode=generative"])
    res = app.run(cfg)
    table = list(csv.DictReader((out / "loop_selftest_general.csv").open()))
    assert tuple(table[0]) == gen.COLUMNS and [r["run"] for r in table] == ["0", "1"]
    assert {r["split"] for r in table} == {"dev"} and all(r["effects_injected"] != "none" for r in table)
    assert table[0]["effects_injected"] == "surface_contact+unlisted:anisotropic_gel"  # on the twin's own rest
    assert (out / "selftest_general.md").read_text().startswith("# Residual loop: generative self-test")
    assert json.loads((out / "selftest_general.json").read_text())["summary"]["dev"]["runs"] == 2
    assert res["summary"]["dev"]["runs"] == 2 and len(list((out / "generative" / "runs").iterdir())) == 2

    # workflow/scripts/loop_verdict_rescore.py rebuilds each run's final twin from its record: on the device that made
    # the runs, the default rule's verdict is the recorded one
    import importlib.util

    spec = importlib.util.spec_from_file_location("rescore", REPO_ROOT / "workflow/scripts/loop_verdict_rescore.py")
    rescore = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rescore)
    rescore.main(out / "generative" / "runs", tmp_path / "rescore.csv", sizes)
    rows = list(csv.DictReader((tmp_path / "rescore.csv").open()))
    assert [r["run"] for r in rows] == ["0", "1"]
    assert [r["unexplained_twin"] for r in rows] == [r["unexplained_recorded"] for r in rows]
    assert all(0 <= float(r["explained_by_candidates"]) <= 1 for r in rows)
