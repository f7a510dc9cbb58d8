"""The loop on measured slides (issue 12): folds by trial, the replay along measured poses, the rounds."""

import numpy as np
import pytest

from palpation.markers.template import rest_template
from palpation.measured_sequences import make_sequence_set
from palpation.slides.folds import other, trial_folds
from palpation.slides.loop import SearchSettings, SlideLoopSettings, at_bounds, candidates_of, run_slide_loop
from palpation.slides.replay import frame_mae, frame_mae_abs, make_scene, motion, plan_replay, replay, slide_modes, vessel_ratio
from palpation.twin.config import TwinConfig
from palpation.twin.markers import bind_markers
from palpation.twin.mesh import cached_sensor_mesh
from palpation.twin.runner import tip_node_B
from palpation.twin.trajectory import PHANTOM_TOP_M


def toy_set(n_trials=4, n_frames=3, step_mm=2.0, seed=0):
    rng = np.random.default_rng(seed)
    rest = rest_template()
    markers = rest + rng.normal(0, 1.0, (n_trials, n_frames, 127, 2))
    pose = np.zeros((n_trials, n_frames, 3))
    pose[..., 0] = np.arange(n_trials)[:, None] * 5.0
    pose[..., 1] = -np.arange(n_frames) * step_mm
    pose[..., 2] = 2.0
    labels = np.zeros((n_trials, n_frames, 127), np.int8)
    labels[..., :20] = 1
    return make_sequence_set(markers, np.ones((n_trials, n_frames, 127), bool), rest, pose,
                             [np.array([[-30.0, -2.0], [30.0, -2.0]])], [{"name": f"t{i + 1}"} for i in range(n_trials)],
                             [4.0], labels=labels)


def test_folds_split_by_trial_without_overlap():
    folds = trial_folds([1, 2, 3, 4, 5, 6, 7, 8, 9, 10])
    assert not set(folds["odd"]) & set(folds["even"])
    assert sorted(folds["odd"] + folds["even"]) == list(range(10))
    assert folds["odd"] == [0, 2, 4, 6, 8] and other("odd") == "even"
    with pytest.raises(ValueError, match="leave fold"):
        trial_folds([1, 3])
    with pytest.raises(ValueError, match="unique"):
        trial_folds([1, 1, 2])


def test_replay_reaches_every_measured_pose():
    s = toy_set(1, 3)
    scene = make_scene(s)
    traj, frames = plan_replay(s.pose_mm[0], scene, np.zeros(3))
    assert len(frames) == 3 and np.all(np.diff(frames) > 0)
    tips = traj.T_BA[frames][:, :3, 3]
    want = np.column_stack([scene.to_twin(s.pose_mm[0, :, :2]), PHANTOM_TOP_M - s.pose_mm[0, :, 2] * 1e-3])
    assert np.abs(tips - want).max() < 1e-3  # the controller's reach tolerance
    deeper, _ = plan_replay(s.pose_mm[0], scene, np.zeros(3), dz_mm=0.5)
    assert deeper.T_BA[-1][2, 3] == pytest.approx(traj.T_BA[-1][2, 3] - 5e-4, abs=1e-3)


def test_replay_markers_and_metrics():
    mesh = cached_sensor_mesh("coarse")
    s = toy_set(1, 2, step_mm=1.5)
    binding = bind_markers(mesh.nodes, mesh.dome_nodes, s.rest)
    markers, failed = replay(mesh, TwinConfig(), binding, s, make_scene(s),
                             [{"k_f": 1e7}, {"k_f": 1e8}, {"k_f": 1e7, "marker_anchor": 1.0}])
    assert markers.shape == (3, 1, 2, 127, 2) and not failed.any() and np.isfinite(markers).all()
    np.testing.assert_allclose(markers[2] - markers[0], np.broadcast_to(binding.template_px - binding.rest_px,
                                                                        markers[0].shape), atol=1e-6)
    markers = markers[:2]
    moved = np.linalg.norm(markers - binding.rest_px, axis=-1).mean(axis=-1)
    assert (moved[1] > moved[0]).all()  # a stiffer phantom deforms the dome more at the same depth
    mae = frame_mae(markers, s)
    assert mae.shape == (2, 1) and (mae > 0).all() and (frame_mae_abs(markers, s) > 0).all()
    # a static shift of every marker changes the absolute error, not the motion error
    np.testing.assert_allclose(frame_mae(markers + 3.0, s), mae, atol=1e-9)
    assert not np.allclose(frame_mae_abs(markers + 3.0, s), frame_mae_abs(markers, s))
    assert np.isfinite(vessel_ratio(markers[0], s.labels))


def test_replay_plans_each_trial_once_per_geometry(monkeypatch):
    """Candidates that differ only inside the kernels share a trial's pose schedule; a mount offset plans anew."""
    import palpation.slides.replay as slides

    planned = []
    monkeypatch.setattr(slides, "plan_replay", lambda *a, **k: planned.append(a[3]) or plan_replay(*a, **k))
    mesh = cached_sensor_mesh("coarse")
    s = toy_set(2, 2, step_mm=1.5)
    binding = bind_markers(mesh.nodes, mesh.dome_nodes, s.rest)
    markers, _ = replay(mesh, TwinConfig(), binding, s, make_scene(s),
                        [{"k_f": 1e7}, {"k_f": 1e8}, {"k_f": 1e7, "mount_dz_mm": 0.5}])
    assert planned == [0.0, 0.0, 0.5, 0.5]  # two trials, two geometries
    assert not np.allclose(markers[2], markers[0])  # the deeper mount pressed deeper


def fake_twin(truth, want=None):
    """A fake twin whose motion nears the real one as each parameter nears `want` (log distance for k_f, E)."""
    want = want or {"k_f": 3e7, "mu": 0.8}
    start = {"k_f": 1e7, "mu": 0.0, "E": 8.8e5}
    calls = []

    def evaluate(part, cands):
        calls.append(len(cands))
        out = []
        for c in cands:
            err = sum(abs(np.log10(c.get(k, start[k]) / v)) if k in ("k_f", "E") else abs(c.get(k, start[k]) - v)
                      for k, v in want.items())
            idx = [int(t["name"][1:]) - 1 for t in part.trials]
            out.append(truth[idx] + 5.0 + err * motion(truth[idx]))  # + a static offset the residual ignores
        return np.stack(out), np.zeros((len(cands), part.n_trials), bool)
    return evaluate, calls


def test_rounds_pick_the_effect_that_lowers_the_fitted_error():
    s = toy_set(4, 2)
    truth = s.markers.astype(np.float64)
    evaluate, _ = fake_twin(truth)

    settings = SlideLoopSettings(effects={"compliant_phantom": {"k_f": [3e6, 3e7]}, "friction": {"mu": [0.3, 0.8]},
                                          "vessel_inclusion": {"incl_ratio": [5.0, 20.0]}},
                                 base={"k_f": 1e7}, max_rounds=3, min_improvement_px=0.01,
                                 search=SearchSettings(sampler="grid")).validate()
    assert candidates_of({"mu": [0.3, 0.8], "k_t": [20, 60]}) == [{"mu": 0.3, "k_t": 20.0}, {"mu": 0.8, "k_t": 60.0}]
    result = run_slide_loop(evaluate, s, settings, [1, 2, 3, 4])
    rows = result["rows"]
    for fold in ("odd", "even"):
        fr = [r for r in rows if r["fold"] == fold]
        assert [r["effect_added"] for r in fr] == ["none", "friction", "compliant_phantom"]  # then nothing helps
        assert fr[-1]["mae_fit_px"] < fr[0]["mae_fit_px"] and fr[-1]["mae_heldout_px"] < fr[0]["mae_heldout_px"]
        assert fr[-1]["mae_abs_heldout_px"] > 4.0  # the offset stays in the absolute error
    assert result["folds"] == {"odd": [1, 3], "even": [2, 4]}
    assert rows[0]["modes_heldout"]["mae_over_vessel_px"] > 0
    modes = slide_modes(truth + 2.0, s)  # a uniform offset: all translation, no motion error
    assert modes["share_translation"] == pytest.approx(1.0) and modes["mae_over_vessel_px"] == pytest.approx(0.0)
    with pytest.raises(ValueError, match="leaves its physical bounds"):
        SlideLoopSettings(effects={"f": {"mu": [3.0]}}).validate()
    with pytest.raises(ValueError, match="unknown parameter 'young'"):
        SlideLoopSettings(effects={"f": {"young": [3.0]}}).validate()


def test_continuous_search_finds_values_between_the_grid_points_and_reports_a_bound():
    """search.sampler tpe: each effect's parameters searched within the registry's bounds in seeded batches;
    the optimum lies between any grid's values (mu 0.63); an optimum beyond E's upper bound ends at the bound
    and is reported as a symptom."""
    s = toy_set(4, 2)
    truth = s.markers.astype(np.float64)
    evaluate, calls = fake_twin(truth, {"mu": 0.63, "E": 5e6})
    settings = SlideLoopSettings(effects={"friction": {"mu": [0.3]}, "stiffness": {"E": [1e6]}}, base={},
                                 max_rounds=2, min_improvement_px=0.01,
                                 search=SearchSettings(sampler="tpe", batches=5, per_batch=6, seed=3)).validate()
    result = run_slide_loop(evaluate, s, settings, [1, 2, 3, 4])
    # per fold: the base twin on fit + held-out, then per round 5 batches of 6 asks per remaining effect + held-out
    assert calls[:2] == [1, 1] and calls[2:7] == [12] * 5 and calls[8:13] == [6] * 5
    for fold in ("odd", "even"):
        final = result["params"][fold][-1]
        assert abs(final["mu"] - 0.63) < 0.1 and final["E"] > 1.7e6
        last = [r for r in result["rows"] if r["fold"] == fold][-1]
        assert last["at_bounds"].startswith("E=") and "upper bound" in last["at_bounds"]
    again = run_slide_loop(fake_twin(truth, {"mu": 0.63, "E": 5e6})[0], s, settings, [1, 2, 3, 4])
    assert again["params"] == result["params"]  # seeded: deterministic
    assert at_bounds({"E": 2.0e6, "mu": 0.5}) == ["E=2e+06 at its upper bound [100000, 2e+06] Pa"]
    assert at_bounds({"E": 1.2e6, "mu": 0.0}) == ["mu=0 at its lower bound [0, 1.5] 1"]
    with pytest.raises(ValueError, match="search.sampler"):
        SlideLoopSettings(effects={}, search=SearchSettings(sampler="cma")).validate()


def test_lead_in_slides_to_the_first_pose_at_depth():
    s = toy_set(1, 3)
    scene = make_scene(s)
    plain, frames0 = plan_replay(s.pose_mm[0], scene, np.zeros(3))
    lead, frames = plan_replay(s.pose_mm[0], scene, np.zeros(3), lead_in_mm=6.0)
    np.testing.assert_allclose(lead.T_BA[frames][:, :3, 3], plain.T_BA[frames0][:, :3, 3], atol=1e-3)
    tip = lead.T_BA[:frames[0]][:, :3, 3]
    pressed = tip[:, 2] < PHANTOM_TOP_M - 1e-3  # > 1 mm into the phantom (the first pose: 2 mm) before frame 0
    y_first = scene.to_twin(s.pose_mm[0, :1, :2])[0, 1]
    assert tip[pressed, 1].max() > y_first + 4e-3  # pressed ~6 mm back along the slide (toy slides run -y)
    assert (plain.T_BA[:frames0[0]][:, :3, 3][:, 2] < PHANTOM_TOP_M - 1e-3).sum() < pressed.sum()
    with pytest.raises(ValueError, match="lead_in_mm"):
        plan_replay(s.pose_mm[0, :1], scene, np.zeros(3), lead_in_mm=6.0)


def test_phantom_tilt_deepens_the_press_along_the_slope_and_stays_out_of_the_sim_twin():
    from palpation.slides.twins import fold_params, scene_params, twin_overrides

    s = toy_set(1, 3, step_mm=4.0)
    scene = make_scene(s)
    flat, f0 = plan_replay(s.pose_mm[0], scene, np.zeros(3))
    tilted, f1 = plan_replay(s.pose_mm[0], scene, np.zeros(3), tilt=(0.0, 0.02))
    z0, z1 = flat.T_BA[f0][:, 2, 3], tilted.T_BA[f1][:, 2, 3]
    y_mm = s.pose_mm[0, :, 1] - scene.origin_mm[1]
    np.testing.assert_allclose(z0 - z1, 0.02 * y_mm * 1e-3, atol=1e-3)  # deeper (lower z) towards +y
    assert (z0 - z1)[0] > (z0 - z1)[-1]  # toy slides run -y: the press gets shallower along them
    with pytest.raises(ValueError, match="leaves its physical bounds"):
        SlideLoopSettings(effects={"t": {"tilt_y": [0.5]}}).validate()
    loop = {"params": {"odd": [{"k_f": 1e7}, {"k_f": 1e7, "mu": 0.8, "tilt_y": 0.01}], "even": [{"k_f": 1e7}]}}
    assert fold_params(loop, "odd") == {"k_f": 1e7, "mu": 0.8} and scene_params(loop, "odd") == {"tilt_y": 0.01}
    assert "tilt_y" not in str(twin_overrides(fold_params(loop, "odd"))) and scene_params(loop, "even") == {}


def test_motion_decomposition_separates_common_translation_and_affine_motion():
    from palpation.slides.diagnosis import decomposition, replay_errors

    s = toy_set(2, 5)
    rest = s.rest.astype(np.float64)
    x = rest - rest.mean(axis=0)
    shift = np.linspace(-2, 2, 5)[:, None] * np.array([0.0, 1.0])  # the whole field drifts along y
    scale = np.linspace(-0.01, 0.01, 5)[:, None, None]
    markers = np.broadcast_to(rest + shift[:, None] + scale * x, (2, 5, 127, 2)).copy()
    d = decomposition(markers, s.found, rest)
    assert d["motion_px"] > 1.0 and d["common_translation_px"] == pytest.approx(1.2, abs=1e-9)
    assert d["after_translation_px"] > 0.1 and d["after_affine_px"] < 1e-9 and d["lag1_autocorrelation"] > 0.4
    assert d["jitter_px"] < 1e-9  # linear in time: no second difference
    e = replay_errors(np.stack([markers, np.broadcast_to(rest, markers.shape)]), markers, s.found)
    assert e["common_error_px"][0] < 1e-9 and e["rest_error_px"][0] < 1e-9
    assert e["common_error_px"][1] == pytest.approx(1.2) and e["sim_common_px"][1] == 0.0


def test_folds_side_by_side_give_the_same_loop():
    """fold_workers 2 (two spawned processes, the app's picklable Replayer with the real twin) and batch_folds (the
    folds' twin calls as one batch) = one fold after the other, row for row and parameter for parameter, on the CPU."""
    import json

    from palpation.apps.slide_loop import Replayer

    s = toy_set(2, 2, step_mm=1.5)
    settings = SlideLoopSettings(effects={"compliant_phantom": {"k_f": [3e7]}}, base={"k_f": 1e7}, max_rounds=1,
                                 min_improvement_px=0.0, search=SearchSettings(sampler="grid"),
                                 ).validate()
    replayer = Replayer(TwinConfig(), None, s, 0.0)
    apart, together = (run_slide_loop(replayer, s, settings, [1, 2], workers=w) for w in (1, 2))
    assert json.dumps(apart, sort_keys=True, default=str) == json.dumps(together, sort_keys=True, default=str)
    batched = run_slide_loop(replayer, s, settings, [1, 2], batch_folds=True)
    assert json.dumps(apart, sort_keys=True, default=str) == json.dumps(batched, sort_keys=True, default=str)
    assert [(r["fold"], r["effect_added"]) for r in together["rows"]] == [
        ("odd", "none"), ("odd", "compliant_phantom"), ("even", "none"), ("even", "compliant_phantom")]


def test_fold_batches_run_each_call_once_and_fail_loudly():
    """slides.fold_batches: the folds' calls wait for each other and run as one `many` call (a fold that has finished no
    longer holds the other back); an error in the shared call reaches every fold instead of leaving one waiting."""
    from palpation.slides.fold_batches import run_folds_together

    seen = []

    def many(jobs):
        seen.append([len(c) for _, c in jobs])
        return [[c * 10 for c in cands] for _, cands in jobs]

    def fold(evaluate, n_calls, size):
        return [evaluate(None, list(range(size))) for _ in range(n_calls)]

    out = run_folds_together(fold, [(None, 3, 2), (None, 1, 5)], many)
    assert out == [[[0, 10]] * 3, [[0, 10, 20, 30, 40]]]
    assert sorted(seen[0]) == [2, 5] and seen[1:] == [[2], [2]]

    def broken(jobs):
        raise ValueError("twin diverged")

    with pytest.raises(RuntimeError, match="shared twin call") as err:
        run_folds_together(fold, [(None, 1, 2), (None, 1, 2)], broken)
    assert isinstance(err.value.__cause__, ValueError)
