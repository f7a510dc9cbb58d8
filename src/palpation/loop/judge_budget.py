"""Where a profile's downstream judge (issue 12, workflow/rules/judge.smk) spends its device time.

Counts the work (slide-loop rounds x envs x frames, replays, Sim sets, training jobs) from the profile's own
settings and the sequence set, and prices it with the H100 measurements the repo ships: the twin's batch
time (docs/results/bench_twin.json, fitted as frames x (a + b x envs)), the paper run's rule times
(docs/results/bench_reproduction.json) and seeds trained together vs apart (docs/results/bench_train.json).
`REPLAY_FACTOR` is the scene replay's cost per env-frame over a plain Sim slide (compliant phantom with the
vessels as inclusions; measured on the CPU, coarse mesh: 17.2 vs 13.3 ms, docs/loop.md "Paper-profile run").

    python -m palpation.loop.judge_budget                 # paper profile
    python -m palpation.loop.judge_budget --profile quick

A developer estimate, outside the results DAG: argparse, like the other benchmarks (twin/benchmark.py).
"""

from __future__ import annotations

import argparse
import json
import shlex

import numpy as np
import yaml

from palpation.paths import REPO_ROOT

REPLAY_FACTOR = 1.3
SIM_FRAMES = 398  # frames of a Sim-set slide (SPEC §7), the bench's schedule


def slide_loop_envs(candidates: dict[str, int], n_fit: int, n_held: int, max_rounds: int) -> list[int]:
    """Env counts of one fold's twin batches in the worst case (every round keeps an effect, the one with the
    fewest candidates, so the later rounds stay largest): round 0 fit and held-out, then per round the
    remaining candidates x the fitted trials and the held-out replay of the kept twin."""
    left = dict(candidates)
    envs = [n_fit, n_held]
    for _ in range(max_rounds):
        if not left:
            break
        envs.append(sum(left.values()) * n_fit)
        left.pop(min(left, key=left.get))
        envs.append(n_held)
    return envs


def twin_seconds(bench: list[dict], resolution: str) -> tuple[float, float]:
    """(a, b): seconds per frame = a + b x envs, least squares over the bench's CUDA rows of the mesh."""
    rows = [r for r in bench if r["resolution"] == resolution and str(r["device"]).startswith("cuda")]
    if len(rows) < 2:
        raise ValueError(f"docs/results/bench_twin.json: fewer than 2 CUDA rows for the {resolution} mesh; "
                         "rerun palpation.twin.benchmark on the GPU")
    n = np.array([r["n_envs"] for r in rows], float)
    t = np.array([(r["wall_s_measured"] - r["setup_s"]) / r["frames"] for r in rows])
    b, a = np.polyfit(n, t, 1)
    return float(a), float(b)


def slide_work(profile: dict, sequences: str, mesh: str | None) -> dict:
    """The slide loop of the profile's judge: trials, replay frames, candidates per effect, rounds."""
    from hydra import compose, initialize_config_dir

    from palpation.apps.slide_loop import select
    from palpation.loop.slides import make_scene, plan_replay
    from palpation.loop.folds import trial_folds
    from palpation.measured_sequences import load_sequence_set
    from palpation.twin.mesh import SensorMesh, cached_sensor_mesh
    from palpation.twin.runner import tip_node_B

    judge = profile["judge"]
    overrides = [f"twin/mesh={profile['twin_resolution']}", *shlex.split(judge.get("twin", "")),
                 *shlex.split(judge.get("slide_loop", ""))]
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose("slide_loop", overrides=overrides)
    sset = load_sequence_set(sequences)
    sub, numbers = select(sset, cfg.trials, cfg.frames)
    m = SensorMesh.load(mesh) if mesh else cached_sensor_mesh(profile["twin_resolution"])
    frames = max(len(plan_replay(p, make_scene(sset), tip_node_B(m))[0].T_BA) for p in sub.pose_mm)
    folds = trial_folds(numbers)
    cands = {e: len(next(iter(g.values()))) for e, g in cfg.effects.items()}
    return {"trials": numbers, "measured_frames": sub.n_frames, "replay_frames": frames, "candidates": cands,
            "max_rounds": int(cfg.max_rounds), "fold_sizes": [len(v) for v in folds.values()]}


def budget(profile: str, sequences: str, mesh: str | None = None) -> dict:
    profile_name = profile
    path = REPO_ROOT / "conf" / "workflow" / f"{profile_name}.yaml"
    profile = yaml.safe_load(path.read_text())
    if profile.get("device") != "cuda" or not profile.get("judge", {}).get("seeds"):
        raise ValueError(f"{path}: judge_budget prices a profile that runs the judge on cuda (device: cuda, "
                         "judge.seeds not empty), e.g. --profile paper")
    docs = REPO_ROOT / "docs" / "results"
    a, b = twin_seconds(json.loads((docs / "bench_twin.json").read_text()), profile["twin_resolution"])
    rules = {r["profile"]: r["per_rule"] for r in json.loads((docs / "bench_reproduction.json").read_text())}
    measured = rules.get("paper", {})
    train = json.loads((docs / "bench_train.json").read_text())["wall_s"]
    seeds = len(profile["judge"]["seeds"])
    together = bool(profile["train"].get("seeds_together"))
    work = slide_work(profile, sequences, mesh)
    f = work["replay_frames"]

    def replay(envs: int) -> float:
        return REPLAY_FACTOR * f * (a + b * envs)

    n_fit, n_held = work["fold_sizes"]
    loop_envs = [slide_loop_envs(work["candidates"], *sizes, work["max_rounds"])
                 for sizes in ((n_fit, n_held), (n_held, n_fit))]
    sim_set = SIM_FRAMES * (a + b * 2 * profile["dataset"]["n_pairs"])
    per_job = train["together"] * seeds / 5 if together else train["apart"] / 5  # bench: 5 seeds
    train_jobs = 4 * 2 * (1 if together else seeds)  # (photo_loop, calibrated, 2 fold twins) x A-to-B/A-to-C
    rows = [
        ("slide_loop (both folds, worst case)", 1, sum(replay(n) for envs in loop_envs for n in envs),
         f"{sum(map(len, loop_envs))} batches, envs {loop_envs}, {f} frames"),
        ("judge_slides replays", 4, np.mean([replay(len(work["trials"]))] * 2 + [replay(n_fit), replay(n_held)]),
         "1 twin x its held-out trials"),
        ("Sim sets (2 upstream + 2 fold twins)", 4, measured.get("simulate_dataset", sim_set),
         f"{2 * profile['dataset']['n_pairs']} slides; kernel time alone {sim_set:.0f} s"),
        ("training jobs", train_jobs, per_job, f"{seeds} seeds {'together' if together else 'apart'}"),
        ("calibrate + loop (upstream)", 1, measured.get("calibrate", 0) + measured.get("loop", 0), "paper run"),
    ]
    path = {"photo twins": measured.get("calibrate", 0) + measured.get("loop", 0) + rows[2][2] + rows[3][2],
            "slide twins": measured.get("silicone_set", 0) + rows[0][2] + rows[2][2] + rows[3][2]}
    return {"profile": profile_name, "work": work, "rows": rows, "job_s": sum(r[1] * r[2] for r in rows),
            "critical_path_s": path, "twin_s_per_frame": [a, b]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--profile", default="paper")
    p.add_argument("--sequences", default="results/data/silicone/silicone_sequences")
    p.add_argument("--mesh", default=None, help="mesh npz (default: the cached mesh of the profile's resolution)")
    r = budget(**vars(p.parse_args()))
    print(f"{r['profile']} profile: slide loop on trials {r['work']['trials']}, {r['work']['measured_frames']} "
          f"measured frames = {r['work']['replay_frames']} twin frames per replay, candidates "
          f"{r['work']['candidates']}, <= {r['work']['max_rounds']} rounds")
    for name, count, each, note in r["rows"]:
        print(f"  {name:40s} {count:3d} x {each:6.1f} s = {count * each:7.1f} s   ({note})")
    print(f"  job time {r['job_s']:.0f} s; dependency chains " +
          ", ".join(f"{k} {v:.0f} s" for k, v in r["critical_path_s"].items()) + " (on an otherwise idle H100)")


if __name__ == "__main__":
    main()
