"""Hydra entry point: close the loop with measured data.

    python -m palpation.apps.loop                      the real photos: rounds, report, final twin
    python -m palpation.apps.loop mode=selftest        hidden effects in twin-made sets, confusion table
    python -m palpation.apps.loop mode=generative loop.generative.split=dev    drawn truths (loop.generative)
    python -m palpation.apps.loop measured=<stem>      any measured set in the generic format

Real mode writes under out.dir: report.md, loop_real.csv, rounds.json, twin_fit/fitted.yaml (the final
twin, loaded downstream with hydra.searchpath=[file://<out.dir>] +twin_fit=fitted), fitted_params.yaml,
modes.png/.pdf, rounds.png/.pdf, residuals/ (quivers per photo)
and study.journal (the Optuna studies, resumable). Self-test mode: loop_selftest.csv, selftest.md,
selftest.json and selftest/ (the generated sets and their study.journal). Generative mode:
loop_selftest_general.csv, selftest_general.md, selftest_general.json and generative/ (runs/ one file per finished
run, resumed from; sets/, study.journal).
"""

from __future__ import annotations

import contextlib
import logging
import time
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from palpation.calibration.objective import marker_mae_px
from palpation.config_check import app_main
from palpation.config_ranges import Choice
from palpation.figures import loop as figures
from palpation.io import save_json, save_text
from palpation.loop import report
from palpation.loop.config import LoopConfig
from palpation.loop.inputs import load_targets
from palpation.loop.real import make_problem, run_loop, twin_key
from palpation.loop.recalibrate import LOOP_STUDY
from palpation.loop.residual import decompose, image_direction_deg
from palpation.loop.selftest.fixed import confusion, rows_csv, run_selftest, summary
from palpation.loop.selftest.generative import run_generative
from palpation.loop.selftest.generative_report import write_outputs
from palpation.loop.simulate import LoopSimulator, loop_twin_config
from palpation.loop.start import nominal_projection, read_start, start_twin
from palpation.loop.unlisted import twin_rest
from palpation.markers.template import rest_template
from palpation.measured import load_measured_set
from palpation.twin.config import TwinConfig
from palpation.twin.mesh import SensorMesh

log = logging.getLogger(__name__)
MODES = ("real", "selftest", "generative")
RANGES = {"mode": Choice(*MODES)}  # the loop's and twin's settings: on LoopConfig, TwinConfig


def _tracked(cfg: DictConfig, run_name: str):
    if not cfg.track:
        return contextlib.nullcontext()
    from palpation.tracking import start_run
    return start_run("loop", params=OmegaConf.to_container(cfg, resolve=True), config=run_name)


def _log(metrics: dict, step: int | None = None, track: bool = True) -> None:
    if track:
        from palpation.tracking import log_metrics
        log_metrics({k: v for k, v in metrics.items() if np.isfinite(v)}, step=step)


def loop_simulator(twin: TwinConfig, loop: LoopConfig, mesh: SensorMesh) -> tuple[TwinConfig, LoopSimulator]:
    """The loop's twin (the nominal projection with the loop's shell) and the simulator every mode runs it in."""
    tw = loop_twin_config(nominal_projection(twin), loop.shell_thickness_mm * 1e-3)
    return tw, LoopSimulator(mesh, tw, rest_template(), device=twin.device, split_by_kind=loop.split(twin.device),
                             max_frames=loop.max_frames)


def run(cfg: DictConfig) -> dict:
    if cfg.mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got '{cfg.mode}'")
    twin_node = cfg.twin
    if cfg.get("start"):  # a starting twin file (e.g. an earlier loop's twin_fit/fitted.yaml) over cfg.twin
        start_file = read_start(cfg.start)  # raises its own one-line errors
        try:
            twin_node = OmegaConf.merge(cfg.twin, start_file)
        except Exception as exc:  # omegaconf: unknown key or wrong type in the file
            raise ValueError(f"loop start={cfg.start}: {str(exc).splitlines()[0]}; the file must hold twin "
                             "sections and fields only (python -m palpation.apps.loop --cfg job lists them)") from None
    twin: TwinConfig = OmegaConf.to_object(twin_node)
    loop: LoopConfig = OmegaConf.to_object(cfg.loop).validate()
    # the starting twin: effects it already has and their values, honoured or refused (never dropped)
    effects_on, start_params = start_twin(twin, loop.shell_thickness_mm * 1e-3)
    out = Path(cfg.out.dir)
    mset = load_measured_set(cfg.measured)
    source = str(cfg.measured)
    # every input check before the mesh is loaded or anything is simulated
    if cfg.mode == "real":
        make_problem(mset, source, loop, start_params, effects_on=effects_on)
    else:
        load_targets(mset, source, loop.selftest.holdout, loop.selftest.states, loop.twist_z_angle)
        if cfg.mode == "generative":
            loop.generative.validate(loop)
    mesh = SensorMesh.load(cfg.mesh)
    tw, sim = loop_simulator(twin, loop, mesh)
    tkey = twin_key(tw, mesh.resolution)
    start = time.perf_counter()
    if cfg.mode == "real":
        result = run_real(cfg, loop, tw, mset, source, sim, tkey, out, mesh.resolution, start_params, effects_on)
    elif cfg.mode == "selftest":
        result = run_self(cfg, loop, tw, mset, source, sim, tkey, out, start_params)
    else:
        result = run_general(cfg, loop, mset, source, sim, tkey, out, start_params)
    result.update({"wall_s": time.perf_counter() - start, "envs_simulated": sim.envs_simulated,
                   "envs_cached": sim.cache_hits, "twin_calls": sim.calls, "twin_s": sim.sim_s,
                   "env_frames": sim.env_frames, "span_frames": sim.span_frames, "cached_frames": sim.cached_frames})
    log.info("loop %s done in %.0f s (%d distinct envs simulated, %d read back from the cache, in %d twin calls "
             "with %d worker(s), %.0f s in the twin; %d env-frames, %d on the busiest worker, %d saved by the cache)",
             cfg.mode, result["wall_s"], sim.envs_simulated, sim.cache_hits, sim.calls, sim.workers, sim.sim_s,
             sim.env_frames, sim.span_frames, sim.cached_frames)
    return result


def run_real(cfg, loop: LoopConfig, tw, mset, source, sim, tkey, out: Path, resolution: str, start: dict,
             effects_on: list[str]) -> dict:
    with _tracked(cfg, "real"):
        def on_round(k, problems):
            p = problems[0]  # the twin kept after round k (a rejected try is restored)
            kept = [r for r in p.rounds if r["round"] == k and r["accepted"]]
            a = p.summary()
            _log({"mae_px/fit": a["fit"], "mae_px/heldout": a["heldout"], "mae_px/all": a["all"],
                  "share_explained": kept[0]["share_explained"] if kept else 0.0,
                  "tries": float(sum(r["round"] == k for r in p.rounds))}, k, cfg.track)

        p = run_loop(mset, source, loop, sim.simulate, start, out / LOOP_STUDY, tkey, on_round,
                     progress=bool(cfg.progress), effects_on=effects_on)
        final = p.markers
        template = rest_template()
        baseline = {t.name: marker_mae_px(template, t.markers) for t in p.targets}
        decs, fig_paths = {}, []
        for i, t in enumerate(p.targets):
            slide = image_direction_deg(-90.0 + t.state.heading_offset_deg) if t.state.kind == "slide" else None
            d0 = decompose(p.rounds[0]["markers_after"][i], t.markers, t.name, slide)
            d1 = decompose(final[i], t.markers, t.name, slide)
            decs[t.name] = [("round 0", d0), (f"final ({'+'.join(p.effects) or 'no effect'})", d1)]
            sims = (p.rounds[0]["markers_after"][i], final[i])
            panels = [(lab, m, d) for (lab, d), m in zip(decs[t.name], sims)]
            fig_paths += figures.plot_state(t.markers, panels, out / "residuals" / f"residual_{t.name}")
        flat = [(f"{n}\n{lab.split(' (')[0]}", d) for n, rows in decs.items() for lab, d in rows]
        fig_paths += figures.plot_shares([d for _, d in flat], [lab for lab, _ in flat], out / "modes")
        rows = report.real_rows(p)
        fig_paths += figures.plot_rounds(rows, float(np.mean(list(baseline.values()))), out / "rounds")
        save_text(out / "loop_real.csv", report.csv_text(rows, report.REAL_COLUMNS))
        meta = {"source": source, "mesh": resolution, "n_trials": loop.search.n_trials,
                "candidates": loop.effects, "final_markers": final, "bounds": loop.search.bounds,
                "target_applies": Path(source).name == loop.target_set, "target_set": loop.target_set,
                "target_mm": loop.target_mm,
                "mean_px": float(np.mean([marker_mae_px(m, t.markers) for t, m in zip(p.targets, final)]))}
        save_text(out / "report.md", report.real_markdown(p, decs, baseline, meta))
        for name, (rows_, columns) in report.real_tables(p, decs, baseline).items():  # the tables, as CSV
            save_text(out / "tables" / f"{name}.csv", report.csv_text(rows_, columns))
        record = {"source": source, "mesh": resolution, "rounds": len(p.rounds) - 1,
                  "mae_px": {t.name: marker_mae_px(m, t.markers) for t, m in zip(p.targets, final)}}
        integ = {"dt": float(tw.integrator.dt), "substeps": int(tw.integrator.substeps)}
        option, readable = report.write_twin_fit(out, p, loop.shell_thickness_mm * 1e-3, record, integ)
        modes = {n: [(lab, d.row()) for lab, d in rows] for n, rows in decs.items()}
        save_json(out / "rounds.json", {"rounds": [_plain(r) for r in p.rounds], "effects": p.effects,
                                        "params": p.params, "decompositions": modes, "final_check": p.final})
        if cfg.track:
            from palpation.tracking import log_artifact
            for path in (out / "report.md", out / "loop_real.csv", option, readable, *fig_paths):
                log_artifact(path)
    return {"effects": p.effects, "rows": rows, "params": p.params, "fitted_option": str(option)}


def run_self(cfg, loop: LoopConfig, tw, mset, source, sim, tkey, out: Path, start: dict) -> dict:
    st = loop.selftest
    template = load_targets(mset, source, [], st.states, loop.twist_z_angle)
    geometry = {s.name: s for s in mset.states}
    binding_rest = sim.binding({}).anchor_px  # the nominal twin's rest markers (outside effects on displacements)
    with _tracked(cfg, "selftest"):
        rows, _, _ = run_selftest(loop, sim.simulate, start, template, geometry, mset.rest,
                                  out / "selftest", out / "selftest" / LOOP_STUDY, tkey,
                                  progress=bool(cfg.progress),
                                  rest_of=lambda p: twin_rest(binding_rest, sim.template, p))
        table = confusion(rows, loop.effects)
        summ = summary(rows)
        save_text(out / "loop_selftest.csv", rows_csv(rows))
        meta = {"low": st.strength_low, "high": st.strength_high, "noise_px": st.noise_px, "states": st.states,
                "holdout": st.holdout, "base_effects": st.base_effects, "runs_per_case": st.runs_per_case,
                "max_rounds": st.max_rounds, "ratio": loop.method.verdict_ratio, "alpha": loop.method.unexplained_alpha}
        save_text(out / "selftest.md", report.selftest_markdown(rows, table, summ, meta))
        save_json(out / "selftest.json", {"rows": rows, "confusion": table, "summary": summ})
        for r in rows:
            _log({"mae_before_px": r["mae_before_px"], "mae_after_px": r["mae_after_px"],
                  "unexplained": float(r["unexplained"])}, r["run"], cfg.track)
        _log({f"summary/{k}": float(v) for k, v in summ.items() if isinstance(v, (int, float))}, None, cfg.track)
        if cfg.track:
            from palpation.tracking import log_artifact
            for path in (out / "loop_selftest.csv", out / "selftest.md"):
                log_artifact(path)
    return {"summary": summ, "confusion": table, "rows": rows}


def run_general(cfg, loop: LoopConfig, mset, source, sim, tkey, out: Path, start: dict) -> dict:
    st = loop.selftest
    template = load_targets(mset, source, [], st.states, loop.twist_z_angle)
    geometry = {s.name: s for s in mset.states}
    binding_rest = sim.binding({}).anchor_px  # the nominal twin's rest markers (outside effects on displacements)
    with _tracked(cfg, "generative"):
        rows = run_generative(loop, sim.simulate, start, template, geometry, mset.rest, out / "generative",
                              out / "generative" / LOOP_STUDY, tkey, lambda p: twin_rest(binding_rest, sim.template, p),
                              progress=bool(cfg.progress))
        summ = write_outputs(out, rows, loop)
        for split, s in summ.items():
            if isinstance(s, dict):
                _log({f"{split}/{k}": float(v) for k, v in s.items() if isinstance(v, (int, float))}, None, cfg.track)
        if cfg.track:
            from palpation.tracking import log_artifact
            for path in (out / "loop_selftest_general.csv", out / "selftest_general.md"):
                log_artifact(path)
    return {"summary": summ, "rows": rows}


def _plain(r: dict) -> dict:
    """A round record without its marker arrays (they are large and rebuilt from the params)."""
    return {k: v for k, v in r.items() if not k.startswith("markers")}


@hydra.main(version_base="1.3", config_path="../../../conf", config_name="loop")
@app_main("loop", RANGES)
def main(cfg: DictConfig) -> None:
    run(cfg)


if __name__ == "__main__":
    main()
