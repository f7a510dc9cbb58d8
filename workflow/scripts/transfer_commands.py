"""The training commands of the transfer table (docs/transfer.md), one shell line each, for gpu_transfer.sh:

    python workflow/scripts/transfer_commands.py --stage teachers --pending --device cuda --logs OUT/logs

Per method of --methods and configuration it runs on: A-to-B scored on Silicone and, by the same models, on Meat
as A-to-C (also_test), and C-to-B; a method that chooses its checkpoint on the other real set or self-trains
(recipe.select_on=other_real, recipe.pseudo) trains each configuration apart. All seeds train together in one
process. A method `scored_with` another (an alignment of the scored clips only) has no training of its own: the
other's training scores it too (also_aligned), so both hold the same models. Stage `teachers`: the methods without recipe.pseudo_from; `students`: those with it (their teachers'
scores must exist first). --pending leaves out a training whose every output folder holds every seed's
metrics.json (a cut training is listed again, whole). --check-data loads every data set that --extra names
(`data.sim=`, `data.silicone=`, `data.meat=`) with the train app's own readers and prints nothing: a missing or
broken file (a Meat set without its layout JSON beside it) fails here in one line, before any training starts.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from palpation.graph.sources import load_dataset
from palpation.model.config import DATASETS
from palpation.model.domain import other_real_set, partner_name
from palpation.readers import one_line
from palpation.report.runs import run_dir
from palpation.transfer.report import CONFIGS, alignment_of, covers, read_methods

TEST_SETS = {"A-to-B": "silicone", "A-to-C": "meat", "C-to-B": "silicone"}


def trained_apart(overrides: list[str]) -> bool:
    """Whether a method's configurations need trainings of their own (their checkpoint split or pseudo-labelled
    set depends on the scored set, so A-to-B's models cannot score A-to-C)."""
    return any(o.startswith("recipe.select_on=other_real") for o in overrides) or any(
        o.startswith("recipe.pseudo=") and o != "recipe.pseudo=none" for o in overrides)


def half_partner(overrides: list[str], config: str) -> list[str]:
    """The cross_real partner a Sim-trained configuration of a method choosing on the other set's selection half
    scores besides its own set: [`<config>.on_<set>`] (model.domain.partner_name), else []."""
    if "recipe.select_on=other_real_half" not in overrides or config == "C-to-B":
        return []
    return [partner_name(config, other_real_set(TEST_SETS[config]))]


def stage(overrides: list[str]) -> str:
    return "students" if any(o.startswith("recipe.pseudo_from=") for o in overrides) else "teachers"


def trainings(methods: dict) -> list[tuple[str, str, list[str]]]:
    """(method, configuration, the configurations it scores) of every training, teachers first. A method scored
    with another's models (scored_with) has no training of its own: see scored_with()."""
    out = []
    for name, spec in methods.items():
        if "scored_with" in spec:
            continue
        configs = [c for c in CONFIGS if covers(spec, c)]
        if not trained_apart(spec["overrides"]) and {"A-to-B", "A-to-C"} <= set(configs):
            out.append((name, "A-to-B", ["A-to-B", "A-to-C"]))
            configs = [c for c in configs if c not in ("A-to-B", "A-to-C")]
        out += [(name, c, [c, *half_partner(spec["overrides"], c)]) for c in configs]
    return sorted(out, key=lambda t: stage(methods[t[0]]["overrides"]) == "students")


def scored_with(methods: dict, method: str, scored: list[str]) -> list[str]:
    """The methods scored by `method`'s training of the configurations `scored` (their scored_with), in file order."""
    return [m for m, spec in methods.items()
            if spec.get("scored_with") == method and any(covers(spec, c) for c in scored)]


def command(root: str, methods: dict, method: str, config: str, scored: list[str], seeds: list[int], device: str,
            clip_len: int, python: str, extra: list[str]) -> list[str]:
    sets = {c: TEST_SETS.get(c) or other_real_set(TEST_SETS[config]) for c in scored}  # a partner: the other set
    also = [f"also_test=[{','.join(f'{c}:{sets[c]}' for c in scored if c != config)}]"] if len(scored) > 1 else []
    aligned = [":".join([*alignment_of(methods[m]["overrides"]), str(Path(root) / m)])
               for m in scored_with(methods, method, scored)]
    also += [f"also_aligned=[{','.join(aligned)}]"] if aligned else []
    # `extra` (data paths of the machine) first: a method's own override of the same key wins (robust_spread's Sim set)
    return [python, "-m", "palpation.apps.train", f"experiment={config}", *extra, *methods[method]["overrides"],
            f"device={device}", f"seeds=[{','.join(map(str, seeds))}]", *also, f"clip_len={clip_len}", "track=false",
            "progress=false", f"hydra.run.dir={Path(root) / method / config / f'L{clip_len}'}"]


def finished(root: str, methods: dict, method: str, scored: list[str], seeds: list[int], clip_len: int) -> bool:
    """Every run of the training exists: the method's own and those of the methods it scores too."""
    return all((run_dir(Path(root) / m, c, clip_len, s) / "metrics.json").is_file()
               for m in [method, *scored_with(methods, method, scored)] for c in scored for s in seeds)


def check_data(extra: list[str]) -> None:
    """Load each `data.<set>=<path>` of `extra` as a training would (the Sim set's train split, a real set whole)."""
    for item in extra:
        key, _, path = item.partition("=")
        if key.startswith("data."):
            name = key[len("data."):]
            if name not in DATASETS:
                raise ValueError(f"--extra {item}: unknown data set '{name}' (use data.sim, data.silicone, data.meat)")
            load_dataset(name, path, "train" if name == "sim" else "test")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--methods", default="conf/transfer/methods.yaml")
    p.add_argument("--runs-root", default="results/transfer")
    p.add_argument("--stage", choices=("teachers", "students", "all"), default="all")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    p.add_argument("--device", default="cuda")
    p.add_argument("--clip-len", type=int, default=5)
    p.add_argument("--python", default="python3")
    p.add_argument("--pending", action="store_true", help="leave out trainings whose runs all exist")
    p.add_argument("--logs", help="a folder: each command's output goes to <logs>/<method>_<config>.log")
    p.add_argument("--extra", default="", help="overrides added to every command (one shell-quoted string)")
    p.add_argument("--check-data", action="store_true", help="load the data sets --extra names; print no command")
    a = p.parse_args(argv)
    try:
        methods = read_methods(a.methods)
        if len(set(a.seeds)) != len(a.seeds) or a.clip_len < 1:
            raise ValueError(f"--seeds {a.seeds} must be distinct and --clip-len {a.clip_len} >= 1")
        if a.check_data:
            check_data(shlex.split(a.extra))
            return 0
    except (ValueError, OSError) as exc:
        print(f"transfer_commands: {one_line(exc)}", file=sys.stderr)
        return 1
    for method, config, scored in trainings(methods):
        if a.stage != "all" and stage(methods[method]["overrides"]) != a.stage:
            continue
        if a.pending and finished(a.runs_root, methods, method, scored, a.seeds, a.clip_len):
            continue
        cmd = shlex.join(command(a.runs_root, methods, method, config, scored, a.seeds, a.device,
                                 a.clip_len, a.python, shlex.split(a.extra)))
        print(cmd + (f" > {shlex.quote(str(Path(a.logs) / f'{method}_{config}.log'))} 2>&1" if a.logs else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
