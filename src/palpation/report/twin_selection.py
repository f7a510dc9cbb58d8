"""The downstream judge of issue 12: which twin makes the Sim set (docs/slides.md "Twin on the task").

Each candidate twin has Sim->Silicone (A-to-B) and Sim->Meat (A-to-C) models over seeds. Silicone scores are
cross-fitted: a Silicone trial counts only from models whose twin never saw it. A twin fitted on the slides
of one fold (slide_loop, per fold) scores the other fold's trials; the pooled 10-trial AP/AUROC then come from
the two fold twins' models together. A twin fitted on no Silicone trial (calibrated, photo_loop) scores all.
Meat is never fitted on: every model of a candidate scores it. The choice uses the held-out real-slide
motion MAE only (a physics criterion, no test label), with a pre-registered tie rule (`choose`): the candidates
come simplest first (calibrated < photo_loop < slide_loop) and the simplest is kept unless a more complex one is
significantly better, trial by trial (one-sided Wilcoxon signed-rank over the Silicone trials, alpha 0.05), by a
mean gain of at least the slide loop's keep threshold (0.05 px).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from sklearn.metrics import average_precision_score, roc_auc_score

from palpation.markers.lattice import N_MARKERS
from palpation.metrics.scores import Scores
from palpation.slides.gate import GateSettings, verdict

COLUMNS = ("twin", "fitted_on", "heldout_slide_mae_px", "vessel_ratio_sim", "vessel_ratio_real",
           "silicone_ap_crossfit", "silicone_auroc_crossfit", "meat_ap", "meat_auroc", "silicone_pos_share_05",
           "seeds", "chosen", "p_vs_simpler", "why")
# The tie rule (docs/loop.md "Choice"): written after the 26 Nov paper run's detector scores were seen, so that run
# is not a clean test of it; later runs are. Pre-registered here, not tuned: the usual 5 % level, the signed-rank
# test because the per-trial MAE has outlying trials (Silicone trial 1: 3.6 px against ~1.5 px).
TIE_ALPHA = 0.05
TIE_TEST = "one-sided Wilcoxon signed-rank on the per-trial held-out slide MAE"
# ...and the mean per-trial gain must reach the slide loop's own keep threshold (conf/slide_loop.yaml
# min_improvement_px, 0.05 px): a twin better by less than the loop would keep an effect for is not a better twin. Added
# 27 Nov 2026; it changes no committed choice (no complex candidate passed the test there).
TIE_MIN_GAIN_PX = 0.05
# config dataset.twin (workflow/rules/judge.smk, rule twin_choice): the evidence's choice or a pinned candidate
DATASET_TWINS = ("auto", "calibrated", "photo_loop", "slide_loop")


@dataclass
class Member:
    """One twin of a candidate: the Silicone trials (1-based) it was fitted on and its models' scores."""
    fitted_trials: list[int]
    silicone: dict[int, Scores]  # seed -> A-to-B scores
    meat: dict[int, Scores]  # seed -> A-to-C scores


@dataclass
class Candidate:
    twin: str
    fitted_on: str  # in words, e.g. "flat photos" or "Silicone trials odd | even (cross-fitted)"
    members: list[Member]
    heldout_slide_mae_px: float
    vessel_ratio_sim: float
    vessel_ratio_real: float
    trial_mae_px: dict[int, float] | None = None  # 1-based Silicone trial -> held-out motion MAE (the tie rule's pairs)


def _trial_of(scores: Scores) -> np.ndarray:
    """The 1-based Silicone trial of every score (the set's sequence i is trial i + 1, apps.silicone)."""
    return np.repeat(scores.sequence + 1, N_MARKERS)


def crossfit(members: list[Member], seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Pooled Silicone (probs, labels) of one seed: each trial from the members that were not fitted on it.
    A trial no member may score, or one several may, is an error: the folds must partition the trials."""
    probs, labels, owner = [], [], {}
    for k, m in enumerate(members):
        s = m.silicone[seed]
        trial = _trial_of(s)
        keep = ~np.isin(trial, m.fitted_trials)
        for t in np.unique(trial[keep]).tolist():
            if t in owner:
                raise ValueError(f"Silicone trial {t} is held out of two twins' folds ({owner[t]} and {k}); "
                                 "cross-fitting needs folds that partition the trials (slides.folds)")
            owner[t] = k
        probs.append(s.probs[keep])
        labels.append(s.labels[keep])
    every = set(np.unique(_trial_of(members[0].silicone[seed])).tolist())
    if set(owner) != every:
        raise ValueError(f"Silicone trials {sorted(every - set(owner))} are scored by no twin that never saw them; "
                         "each trial must be held out of one fold's twin")
    return np.concatenate(probs), np.concatenate(labels)


def _metrics(probs: np.ndarray, labels: np.ndarray) -> tuple[float, float]:
    if labels.min() == labels.max():
        return float("nan"), float("nan")
    return float(average_precision_score(labels, probs)), float(roc_auc_score(labels, probs))


def candidate_row(c: Candidate) -> dict:
    """One row (COLUMNS, `chosen` left False): seed means of the cross-fitted Silicone and the Meat metrics."""
    seeds = sorted(set.intersection(*(set(m.silicone) & set(m.meat) for m in c.members)))
    if not seeds:
        raise ValueError(f"twin {c.twin}: no seed has both A-to-B and A-to-C scores for every member twin")
    sil, meat, share = [], [], []
    for seed in seeds:
        p, y = crossfit(c.members, seed)
        sil.append(_metrics(p, y))
        share.append(float((p >= 0.5).mean()))
        meat += [_metrics(m.meat[seed].probs, m.meat[seed].labels) for m in c.members]
    return {"twin": c.twin, "fitted_on": c.fitted_on, "heldout_slide_mae_px": c.heldout_slide_mae_px,
            "vessel_ratio_sim": c.vessel_ratio_sim, "vessel_ratio_real": c.vessel_ratio_real,
            "silicone_ap_crossfit": float(np.mean([a for a, _ in sil])),
            "silicone_auroc_crossfit": float(np.mean([r for _, r in sil])),
            "meat_ap": float(np.mean([a for a, _ in meat])), "meat_auroc": float(np.mean([r for _, r in meat])),
            "silicone_pos_share_05": float(np.mean(share)), "seeds": len(seeds), "chosen": False,
            "p_vs_simpler": float("nan"), "why": ""}


def paired_trials(simpler: dict[int, float], other: dict[int, float]) -> tuple[np.ndarray, np.ndarray]:
    """The two candidates' held-out MAE over the same trials, in trial order (the tie rule's pairs)."""
    if sorted(simpler) != sorted(other):
        raise ValueError(f"twin selection: the tie rule pairs trials, but the replays hold trials {sorted(simpler)} "
                         f"and {sorted(other)}; rerun rule judge_slides so every candidate replays the same trials")
    trials = sorted(simpler)
    return np.array([simpler[t] for t in trials]), np.array([other[t] for t in trials])


def rule_text(alpha: float = TIE_ALPHA, min_gain_px: float = TIE_MIN_GAIN_PX) -> str:
    return (f"simplest first, replaced only if significantly better ({TIE_TEST}, alpha {alpha:g}) by a mean of at "
            f"least {min_gain_px:g} px per trial")


def choose(candidates: list[Candidate], alpha: float = TIE_ALPHA,
           min_gain_px: float = TIE_MIN_GAIN_PX) -> tuple[int, list[float], list[str]]:
    """The tie rule: candidates simplest first; the incumbent (at first the simplest) is replaced by a more complex
    candidate only if that one is significantly better than it trial by trial (p < alpha) and by a mean gain
    of at least `min_gain_px`. Returns the chosen index and, per candidate, the p against the incumbent it met and why
    it was (not) chosen."""
    ok = [i for i, c in enumerate(candidates) if c.trial_mae_px and np.isfinite(c.heldout_slide_mae_px)]
    if not ok:
        raise ValueError("twin selection: no candidate has a finite held-out slide MAE per trial to choose by")
    best, ps, why = ok[0], [float("nan")] * len(candidates), [""] * len(candidates)
    why[best] = "simplest twin with a held-out slide MAE; kept unless a more complex one is significantly better"
    for i in ok[1:]:
        inc = candidates[best]
        # the slide loop's own keep decision (one-sided paired test and mean gain), here on the held-out trials
        v = verdict(*paired_trials(inc.trial_mae_px, candidates[i].trial_mae_px),
                    GateSettings(test="wilcoxon", alpha=alpha), min_gain_px)
        ps[i], n, gain = v["p"], v["n_trials"], v["gain_px"]
        if v["passed"]:
            why[best] += f"; replaced by {candidates[i].twin}"
            why[i], best = (f"significantly better than {inc.twin} (p {ps[i]:.3g} < {alpha:g}, {n} trials; mean gain "
                            f"{gain:.3g} px >= {min_gain_px:g})"), i
        elif ps[i] < alpha:
            why[i] = (f"significantly but not materially better than {inc.twin} (p {ps[i]:.3g} < {alpha:g}, "
                      f"{n} trials; mean gain {gain:.3g} px < {min_gain_px:g} px, the slide loop's keep threshold)")
        else:
            why[i] = f"not significantly better than {inc.twin} (p {ps[i]:.3g} >= {alpha:g}, {n} trials)"
    for i, c in enumerate(candidates):
        if i not in ok:
            why[i] = "no held-out slide MAE per trial"
    why[best] = f"chosen: {why[best]} ({TIE_TEST}, alpha {alpha:g})"
    return best, ps, why


def pick(candidates: list[Candidate], alpha: float = TIE_ALPHA) -> tuple[int, list[float], list[str]]:
    """The evidence's choice, the one function the table and the Sim-set choice (`sim_set_choice`) share: the tie
    rule (`choose`) where every candidate has per-trial held-out MAE, else (older replays) the lowest mean."""
    if not candidates:
        raise ValueError("twin selection: no candidate twins")
    names = [c.twin for c in candidates]
    if len(set(names)) != len(names):
        raise ValueError(f"twin selection: candidate names repeat: {names}")
    mae = np.array([c.heldout_slide_mae_px for c in candidates], float)
    if not np.isfinite(mae).any():
        raise ValueError("twin selection: no candidate has a finite held-out slide MAE to choose by")
    if all(c.trial_mae_px for c in candidates):
        return choose(candidates, alpha)
    best, why = int(np.nanargmin(mae)), [""] * len(candidates)
    why[best] = "chosen: lowest mean held-out slide MAE (no per-trial MAE for the tie rule)"
    return best, [float("nan")] * len(candidates), why


def selection_table(candidates: list[Candidate], alpha: float = TIE_ALPHA) -> pd.DataFrame:
    """One row per candidate (simplest first); `chosen` by the held-out slide motion MAE (`pick`). Test labels
    play no part."""
    best, ps, why = pick(candidates, alpha)
    table = pd.DataFrame([candidate_row(c) for c in candidates], columns=list(COLUMNS))
    table["p_vs_simpler"], table["why"] = ps, why
    table.loc[best, "chosen"] = True
    return table


def sim_set_choice(candidates: list[Candidate], twin: str = "auto", alpha: float = TIE_ALPHA) -> dict:
    """Which twin simulates the main Sim set (config dataset.twin): `auto` takes the evidence's choice (`pick`),
    a candidate's name pins it (the evidence is still recorded). Needs the replays only, no detector score."""
    names = [c.twin for c in candidates]
    if twin not in DATASET_TWINS:
        raise ValueError(f"config dataset.twin: unknown value {twin!r}; use one of {', '.join(DATASET_TWINS)} "
                         "(conf/workflow/<profile>.yaml)")
    if twin != "auto" and twin not in names:
        raise ValueError(f"config dataset.twin: {twin!r} is not a judged candidate ({', '.join(names)}); "
                         "pin one of them or use auto")
    best, ps, why = pick(candidates, alpha)
    rows = [{"twin": c.twin, "heldout_slide_mae_px": c.heldout_slide_mae_px, "trial_mae_px": c.trial_mae_px or {},
             "p_vs_simpler": p, "why": w} for c, p, w in zip(candidates, ps, why)]
    used = names[best] if twin == "auto" else twin
    how = "the evidence's choice" if twin == "auto" else f"pinned by dataset.twin (the evidence chose {names[best]})"
    return {"dataset_twin": twin, "chosen": names[best], "sim_set_twin": used, "pinned": twin != "auto",
            "how": how, "rule": rule_text(alpha),
            "candidates": rows}
