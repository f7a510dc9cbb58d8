# Helpers of the training rules (train.smk, judge.smk, recipe.smk): what a configuration trains on, its Hydra
# overrides, and the groups of configurations that train alike (train_groups) and so share one training job.
# Included by common.smk.


def train_data(wildcards, sim=TRAIN_DATA["sim"]):
    return {name: sim if name == "sim" else TRAIN_DATA[name] for name in EXPERIMENTS[wildcards.exp].datasets}


def train_inputs(wildcards, sim=TRAIN_DATA["sim"], recipe=TRAIN["recipe"]):
    """The datasets and the conf/ files of this configuration (experiment overlay, model, recipe)."""
    choices = {"experiment": wildcards.exp, "model": EXPERIMENTS[wildcards.exp].model, "recipe": recipe}
    return {**train_data(wildcards, sim), "conf": conf_files("train", choices)}


def size_knobs(sizes):
    """train.<knob>=<value> overrides; a null value is passed as null (train_batches/val_batches: the whole split)."""
    return [f"train.{k}={'null' if v is None else v}" for k, v in sizes.items()]


def train_overrides(wildcards, sim=TRAIN_DATA["sim"], recipe=TRAIN["recipe"]):
    """Dataset paths and the profile's size knobs for this configuration's model, as Hydra overrides. Another
    recipe than train.recipe takes the profile's sizes for it where the recipe ablation sets them
    (train.recipe_ablation.sizes), else train.sizes; a knob left out keeps the recipe's own value."""
    data = [f"data.{k}={v}" for k, v in train_data(wildcards, sim).items()]
    model = EXPERIMENTS[wildcards.exp].model
    own = (RECIPE_ABL.get("sizes") or {}).get(recipe) if recipe != TRAIN["recipe"] else None
    sizes = (own if own is not None else TRAIN["sizes"]).get(model) or {}
    return " ".join(data + size_knobs(sizes) + [f"recipe={recipe}"])


def recipe_inputs(wildcards, exps=None):
    """The datasets and conf/ files of one recipe-ablation run (its recipe, not the profile's); `exps`: the
    configurations one job trains together (recipe_groups), else the wildcard's one."""
    return group_inputs(exps or [wildcards.exp], recipe=wildcards.recipe)


def recipe_overrides(wildcards, exps=None):
    """Dataset paths, the ablation's sizes for this recipe and model, the recipe and the switch turned off;
    with `exps` (recipe_groups) the first is the experiment, the others are scored by the same models."""
    from palpation.model.recipe import switch_off

    exps = exps or [wildcards.exp]
    data = [f"data.{k}={v}" for k, v in recipe_inputs(wildcards, exps).items() if k != "conf"]
    sizes = (RECIPE_ABL["sizes"].get(wildcards.recipe) or {}).get(EXPERIMENTS[exps[0]].model) or {}
    knobs = size_knobs(sizes)
    off = [] if wildcards.switch == "none" else switch_off(wildcards.switch)
    also = [also_test_arg(exps[1:])] if exps[1:] else []
    return " ".join(data + knobs + [f"recipe={wildcards.recipe}"] + off + also)


def train_groups(exps):
    """Configurations by what they train (set and model), e.g. {"sim_large": [A-to-A, A-to-B, A-to-C]}: the same
    models, so one job trains them once and scores every test set (app key also_test)."""
    groups = {}
    for exp in exps:
        groups.setdefault(f"{EXPERIMENTS[exp].train_on}_{EXPERIMENTS[exp].model}", []).append(exp)
    return groups


def recipe_groups():
    """The ablation's configurations by what they train (train_groups): with train.seeds_together one job each."""
    return train_groups(RECIPE_ABL["experiments"])


def recipe_seed_outputs(exps, recipe, *switches):
    """Outputs of a seeds-together ablation job: every seed of every configuration of `exps`, per switch_off folder."""
    return run_files(run_dir(recipe_root(RECIPE_DIR, recipe, switch), exp, "{clip_len}", seed)
                     for switch in switches for exp in exps for seed in RECIPE_ABL["seeds"])


def recipe_shares_calibration(exps):
    """Whether the ablation has robust minus `calibration` rows for these configurations (one training group):
    the robust job then writes them from its own models (rule train_recipe_robust_<group>)."""
    return "calibration" in RECIPE_ABL["switches"] and all(
        ("robust", "calibration") in recipe_switch_groups(exp) for exp in exps)


def recipe_switch_groups(exp):
    """(recipe, switch_off) of every row of configuration `exp`: both full recipes, robust minus each switch
    where recipe_ablation.switch_experiments (missing: every configuration) lists it."""
    rows = [(r, "none") for r in ("reference", "robust")]
    if exp in RECIPE_ABL.get("switch_experiments", RECIPE_ABL["experiments"]):
        rows += [("robust", s) for s in RECIPE_ABL["switches"]]
    return rows


def recipe_runs(name):
    """`name` of every run the recipe report reads."""
    return [f for exp in RECIPE_ABL["experiments"] for recipe, switch in recipe_switch_groups(exp)
            for f in expand(f"{RECIPE_RUN}/{name}", recipe=recipe, switch=switch, exp=exp,
                            clip_len=TRAIN["clip_len"], seed=RECIPE_ABL["seeds"])]


def run_files(dirs):
    """A training job's outputs, {"metrics": [<dir>/metrics.json, ...], "scores": ..., ...}, over run folders `dirs`."""
    dirs = list(dirs)
    return {key: [str(Path(d) / name) for d in dirs]
            for key, name in (("metrics", "metrics.json"), ("scores", "scores.npz"), ("pr", "pr.npz"),
                              ("checkpoint", "checkpoint.pt"))}


def shared_outputs(exps, seed):
    """The outputs of train_shared_<group> (train.smk): one seed's run folders (or every seed's, seed None) of each
    configuration of `exps`."""
    seeds = TRAIN["seeds"] if seed is None else [seed]
    return run_files(run_dir(TRAIN_DIR, e, "{clip_len}", s) for e in exps for s in seeds)


def group_inputs(exps, sim=TRAIN_DATA["sim"], recipe=TRAIN["recipe"]):
    """The datasets and conf/ files of configurations one job trains together (train_groups): their union."""
    ins = [train_inputs(SimpleNamespace(exp=e), sim, recipe) for e in exps]
    return {**{k: v for one in ins for k, v in one.items() if k != "conf"},
            "conf": sorted({f for one in ins for f in one["conf"]})}


def also_test_arg(exps):
    """The train app's `also_test` naming `exps` and their test sets, as one shell-quoted override."""
    return "'also_test=[" + ",".join(f"{e}:{EXPERIMENTS[e].test_on}" for e in exps) + "]'"


def group_overrides(exps, sim=TRAIN_DATA["sim"], recipe=TRAIN["recipe"]):
    """The first configuration's overrides, the others' test sets and `also_test` naming them."""
    own = train_data(SimpleNamespace(exp=exps[0]), sim)
    others = {k: v for k, v in group_inputs(exps[1:], sim, recipe).items() if k != "conf" and k not in own}
    return " ".join([train_overrides(SimpleNamespace(exp=exps[0]), sim, recipe)]
                    + [f"data.{k}={v}" for k, v in others.items()] + [also_test_arg(exps[1:])])


def twin_ablation_sim(wildcards):
    """The Sim set of the dataset-twin ablation's {twin} (train_twin_ablation_seeds): the calibrated candidate's set
    (dataset.smk's rule, looked up when a job needs it) or the photo loop's."""
    return rules.simulate_dataset_calibrated.output.manifest if wildcards.twin == "calibrated" else PHOTO_SIM
