"""The calibration history: Optuna's optimisation-history plot plus the startup, diverged and baseline marks."""

import matplotlib
import optuna

from palpation.figures import calibration


def toy_study() -> optuna.Study:
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0))
    for n in range(8):
        trial = study.ask()
        x = trial.suggest_float("x", -1, 1)
        trial.set_user_attr("diverged", n == 5)
        study.tell(trial, 1e3 if n == 5 else x * x)
    return study


def test_history_marks_startup_diverged_and_baseline_and_leaves_the_style(tmp_path, monkeypatch):
    saved = {}

    def keep(fig, stem, dpi):
        saved["labels"] = fig.axes[0].get_legend_handles_labels()[1]
        saved["size"] = tuple(fig.get_size_inches())
        return [tmp_path / "history.png"]

    monkeypatch.setattr(calibration, "save_figure", keep)
    before = dict(matplotlib.rcParams)
    calibration.plot_history(toy_study(), 3, tmp_path / "history", baseline=0.5, ylabel="MAE (px)")
    assert {"diverged", "random (startup)", "undeformed sensor (0.50)", "Best Value"} <= set(saved["labels"])
    assert saved["size"] == (5.0, 3.4)
    assert dict(matplotlib.rcParams) == before, "optuna's ggplot style must not leak into later figures (Fig. 4)"


def test_history_writes_png_and_pdf(tmp_path):
    paths = calibration.plot_history(toy_study(), 3, tmp_path / "history")
    assert sorted(p.suffix for p in paths) == [".pdf", ".png"] and all(p.stat().st_size > 0 for p in paths)
