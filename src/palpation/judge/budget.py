"""Where a profile's downstream judge (issue 12, workflow/rules/judge.smk) spends its device time.

Counts the work (slide-loop rounds x envs x frames, replays, Sim sets, training jobs) from the profile's own
settings and the sequence set, and prices it with the H100 measurements the repo ships: the twin's batch
time (docs/results/bench_twin.json, fitted as frames x (a + b x envs)), the paper run's rule times
(docs/results/bench_reproduction.json) and seeds trained together vs apart (docs/results/bench_train.json).
`REPLAY_FACTOR` is the scene replay's cost per env-frame over a plain Sim slide (compliant phantom with the
vessels as inclusions; measured on the CPU, coarse mesh: 17.2 vs 13.3 ms, docs/slides.md "Paper-profile run").

    python -m palpation.judge.budget                      # paper profile
    python -m palpation.judge.budget --profile quick

A developer estimate, outside the results DAG: argparse, like the other benchmarks (twin/benchmark.py).
"""

from __future__ import annotations

import argparse
import shlex

import numpy as np

from palpation.paths import REPO_ROOT
from palpation.readers import read_json, read_yaml

REPLAY_FACTOR = 1.3
SIM_FRAMES = 398  # frames of a Sim-set slide (SPEC §7), the bench's schedule
# The slide loop's measured rate on the H100 (paper run of 25 Nov, docs/results/paper/loop_slides/slide_loop.json:
# 172 s for 390 env replays of 495 frames in 8 batches, beside the loop self-test): s per env-frame, batch overhead
# of 2 ms a frame taken off. The bench model above prices the same work at ~1/3 of it; both are printed.
MEASURED_S_PER_ENV_FRAME = (172.0 - 8 * 495 * 2.0e-3) / (390 * 495)
# A robust-recipe Sim job (5 seeds together, A-to-B + A-to-C scored) on the H100: 187 s beside three other Sim
# jobs (docs/recipe.md, "Device time"); ~20 s an epoch alone, ~41 s when four Sim jobs share the card.
ROBUST_SIM_JOB_S = 187.0


def slide_loop_envs(candidates: dict[str, int], n_fit: int, n_held: int, max_rounds: int,
                    batches: int = 1, gate_envs: int = 0) -> list[int]:
    """Env counts of one fold's twin batches in the worst case (every round keeps an effect, the one with the
    fewest candidates, so the later rounds stay largest): round 0 fit and held-out, then per round `batches`
    sequential batches of the remaining candidates x the fitted trials (grid: 1 batch of every value; tpe:
    `search.batches` of `search.per_batch` asks per effect), the inner gate's `batches` batches of `gate_envs`
    (tpe: tries x inner folds x per_batch x n_fit; 0 when off or grid, whose gate replays nothing) and the
    held-out replay of the kept twin."""
    left = dict(candidates)
    envs = [n_fit, n_held]
    for _ in range(max_rounds):
        if not left:
            break
        envs += [sum(left.values()) * n_fit] * batches
        envs += [gate_envs] * (batches if gate_envs else 0)
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
    # imported here: Hydra and the twin load only when a slide loop is priced, not for --help
    from hydra import compose, initialize_config_dir

    from palpation.measured_sequences import load_sequence_set
    from palpation.slides.folds import trial_folds
    from palpation.slides.replay import make_scene, plan_replay
    from palpation.slides.selection import select
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
    lead = float(cfg.get("lead_in_mm", 0.0))
    frames = max(len(plan_replay(p, make_scene(sset), tip_node_B(m), lead_in_mm=lead)[0].T_BA) for p in sub.pose_mm)
    folds = trial_folds(numbers)
    search = cfg.get("search") or {"sampler": "grid"}
    if search["sampler"] == "grid":
        cands, batches = {e: len(next(iter(g.values()))) for e, g in cfg.effects.items()}, 1
    else:  # tpe: per round `batches` sequential batches of `per_batch` asks per remaining effect
        cands, batches = {e: int(search["per_batch"]) for e in cfg.effects}, int(search["batches"])
    gate = cfg.get("gate") or {}
    sizes = [len(v) for v in folds.values()]
    gate_envs = [int(gate["tries"]) * min(int(gate.get("inner_folds") or n), n) * int(search["per_batch"]) * n
                 if gate.get("inner") and search["sampler"] != "grid" and n >= 2 else 0 for n in sizes]
    return {"trials": numbers, "measured_frames": sub.n_frames, "replay_frames": frames, "candidates": cands,
            "batches": batches, "gate_envs": gate_envs, "sampler": search["sampler"], "lead_in_mm": lead,
            "max_rounds": int(cfg.max_rounds), "fold_sizes": [len(v) for v in folds.values()]}


def budget(profile: str, sequences: str, mesh: str | None = None) -> dict:
    profile_name = profile
    path = REPO_ROOT / "conf" / "workflow" / f"{profile_name}.yaml"
    profile = read_yaml(path, "name a profile of conf/workflow/ (e.g. --profile paper)", "workflow profile")
    if profile.get("device") != "cuda" or not profile.get("judge", {}).get("seeds"):
        raise ValueError(f"{path}: judge_budget prices a profile that runs the judge on cuda (device: cuda, "
                         "judge.seeds not empty), e.g. --profile paper")
    docs = REPO_ROOT / "docs" / "results"
    fix = "restore it from git (docs/results/ holds the committed benchmark records)"
    a, b = twin_seconds(read_json(docs / "bench_twin.json", fix, kind=list), profile["twin_resolution"])
    records = read_json(docs / "bench_reproduction.json", fix, kind=list)
    rules = {r["profile"]: r["per_rule"] for r in records
             if isinstance(r, dict) and {"profile", "per_rule"} <= r.keys()}
    measured = rules.get("paper", {})
    train = read_json(docs / "bench_train.json", fix, keys=("wall_s",))["wall_s"]
    seeds = len(profile["judge"]["seeds"])
    together = bool(profile["train"].get("seeds_together"))
    recipe = profile["judge"].get("recipe") or profile["train"]["recipe"]
    work = slide_work(profile, sequences, mesh)
    f = work["replay_frames"]

    def replay(envs: int) -> float:
        return REPLAY_FACTOR * f * (a + b * envs)

    n_fit, n_held = work["fold_sizes"]
    loop_envs = [slide_loop_envs(work["candidates"], *sizes, work["max_rounds"], work["batches"], g)
                 for sizes, g in zip(((n_fit, n_held), (n_held, n_fit)), work["gate_envs"])]
    env_frames = f * sum(map(sum, loop_envs))
    measured_loop = f * a * sum(map(len, loop_envs)) + env_frames * MEASURED_S_PER_ENV_FRAME
    sim_set = SIM_FRAMES * (a + b * 2 * profile["dataset"]["n_pairs"])
    if recipe == "robust":  # measured per job (5 seeds together); apart: x 2.2 as the reference bench
        per_job = ROBUST_SIM_JOB_S * seeds / 5 * (1 if together else train["apart"] / train["together"] / seeds)
    else:
        per_job = train["together"] * seeds / 5 if together else train["apart"] / 5  # bench: 5 seeds
    # (photo_loop, calibrated, 2 fold twins); seeds together: A-to-B trained once, A-to-C scored by its models
    train_jobs = 4 * (1 if together else 2 * seeds)
    rows = [
        ("slide_loop (both folds, worst case)", 1, sum(replay(n) for envs in loop_envs for n in envs),
         f"{sum(map(len, loop_envs))} batches, envs {loop_envs}, {f} frames; at the last paper run's measured "
         f"rate {measured_loop:.0f} s"),
        ("judge_slides replays", 4, np.mean([replay(len(work["trials"]))] * 2 + [replay(n_fit), replay(n_held)]),
         "1 twin x its held-out trials"),
        # the calibrated candidate's set: always simulated (since 9665dd9 the main set is often its copy, ~10 s)
        ("Sim sets (2 upstream + 2 fold twins)", 4, measured.get("simulate_dataset_calibrated", sim_set),
         f"{2 * profile['dataset']['n_pairs']} slides; kernel time alone {sim_set:.0f} s"),
        ("training jobs", train_jobs, per_job, f"recipe {recipe}, {seeds} seeds {'together' if together else 'apart'}"),
        ("calibrate + loop (upstream)", 1, measured.get("calibrate", 0) + measured.get("loop", 0), "paper run"),
    ]
    path = {"photo twins": measured.get("calibrate", 0) + measured.get("loop", 0) + rows[2][2] + rows[3][2],
            "slide twins": measured.get("silicone_set", 0) + rows[0][2] + rows[2][2] + rows[3][2]}
    path["slide twins, measured loop rate"] = path["slide twins"] - rows[0][2] + measured_loop
    return {"profile": profile_name, "work": work, "rows": rows, "job_s": sum(r[1] * r[2] for r in rows),
            "critical_path_s": path, "twin_s_per_frame": [a, b], "slide_loop_measured_rate_s": measured_loop}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--profile", default="paper")
    p.add_argument("--sequences", default="results/data/silicone/silicone_sequences")
    p.add_argument("--mesh", default=None, help="mesh npz (default: the cached mesh of the profile's resolution)")
    r = budget(**vars(p.parse_args()))
    w = r["work"]
    print(f"{r['profile']} profile: slide loop on trials {w['trials']}, {w['measured_frames']} measured frames = "
          f"{w['replay_frames']} twin frames per replay (lead-in {w['lead_in_mm']:g} mm), search {w['sampler']}: "
          f"{w['batches']} batch(es) of {w['candidates']} per round, <= {w['max_rounds']} rounds")
    for name, count, each, note in r["rows"]:
        print(f"  {name:40s} {count:3d} x {each:6.1f} s = {count * each:7.1f} s   ({note})")
    print(f"  job time {r['job_s']:.0f} s; dependency chains " +
          ", ".join(f"{k} {v:.0f} s" for k, v in r["critical_path_s"].items()) + " (on an otherwise idle H100)")


if __name__ == "__main__":
    main()
