"""Typed settings of the residual loop (Hydra structured config `base_loop`, conf/loop/*.yaml)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from hydra.core.config_store import ConfigStore

from palpation.config_ranges import SEED, Choice, DictOf, Int, ListOf, Num, Text, ranged
from palpation.loop.effects import EFFECTS, PARAMS, check_effects
from palpation.loop.generative_config import GenerativeConfig
from palpation.loop.inputs import TWIST_Z_ANGLES

SAMPLERS = ("gp", "tpe", "random")


@dataclass
class SearchSettings:
    """One recalibration (an Optuna study per problem and round, persistent in <out>/study.journal)."""

    sampler: str = ranged("gp", Choice(*SAMPLERS))
    seed: int = ranged(42, SEED)
    n_trials: int = ranged(10, Int(ge=1))  # completed trials per study, warm starts included
    n_startup: int = ranged(4, Int(ge=0))  # trials before the GP takes over (the warm starts count)
    batch_size: int = ranged(1, Int(ge=1))
    worst_px: float = ranged(165.0, Num(gt=0))  # score of a diverged trial (3 marker spacings)
    # name -> [low, high], over effects.PARAMS
    bounds: dict[str, list[float]] = ranged(rule=DictOf(ListOf(Num(), 2, 2, increasing=True)), factory=dict)
    # rounds >= 1: a log-scaled parameter fitted in an earlier round is searched within this factor of its
    # value (a trust region); 0 = off. Off by default: on the photos E moves x3 once surface contact is in.
    trust_factor: float = ranged(0.0, Num(ge=0))
    # processes that make the Optuna proposals of all problems' studies in parallel (1 = in this process).
    # A GP proposal costs ~0.5 s of CPU: with 60 self-test problems on a GPU they, not the twin, set the pace
    ask_workers: int = ranged(1, Int(ge=1))


@dataclass
class SelftestConfig:
    """Measured-like sets made by the twin with hidden effects on, then the loop on each (loop.selftest).

    Size = len(cases) x runs_per_case. A case is '+'-joined effects; `unlisted:<name>` is one outside the
    candidate list (loop.selftest.UNLISTED)."""

    cases: list[str] = ranged(rule=ListOf(Text()), factory=lambda: [
        "surface_contact", "camera", "viscous", "layered", "marker_anchor",  # singles
        "surface_contact+friction",  # a dependent pair (friction acts only through contact)
        "surface_contact+mount", "surface_contact+camera", "camera+layered", "viscous+marker_anchor",  # pairs
        "unlisted:image_distortion", "unlisted:marker_defect"])  # outside the list
    runs_per_case: int = ranged(1, Int(ge=1))
    strength_low: float = ranged(1.0, Num(gt=0))  # injected strength in nominal steps, drawn uniformly in [low, high]
    strength_high: float = ranged(2.5, Num(gt=0))
    noise_px: float = ranged(0.2, Num(ge=0))  # std per coordinate (SPEC §13.2: photo noise < 0.2 px)
    # on in the starting twin (none: as the real mode)
    base_effects: list[str] = ranged(rule=ListOf(Choice(*EFFECTS), 0, unique=True), factory=list)
    base_params: dict[str, float] = ranged(rule=DictOf(Num()), factory=lambda: {"E": 1.2225e6})
    states: list[str] = ranged(rule=ListOf(Text(), unique=True), factory=lambda: ["press", "twist_z", "twist_x"])
    holdout: list[str] = ranged(rule=ListOf(Text(), 0, unique=True), factory=lambda: ["twist_z"])
    max_rounds: int = ranged(1, Int(ge=1))
    seed: int = ranged(0, SEED)


@dataclass
class LoopConfig:
    # the candidates
    effects: list[str] = ranged(rule=ListOf(Choice(*EFFECTS), unique=True), factory=lambda: list(EFFECTS))
    # state names or kinds to use; None = every interaction state
    states: Optional[list[str]] = ranged(None, ListOf(Text(), unique=True, null=True))
    # scored each round, never fitted
    holdout: list[str] = ranged(rule=ListOf(Text(), 0, unique=True), factory=lambda: ["slide"])
    # quirk 5: 30 deg as the reference, or the file name's angle
    twist_z_angle: str = ranged("reference", Choice(*TWIST_Z_ANGLES))
    max_rounds: int = ranged(4, Int(ge=0))
    # an effect is kept if the held-out MAE falls by min(min_improvement_px, min_improvement_rel x its value):
    # 0.05 px on the photos, less near a noise floor (self-test sets sit at ~0.25 px)
    min_improvement_px: float = ranged(0.05, Num(ge=0))
    min_improvement_rel: float = ranged(0.05, Num(ge=0))
    tries_per_round: int = ranged(2, Int(ge=1))  # effects tried per round, best-ranked first, until one is kept
    # then effect pairs tried jointly (dependent pairs, pairs of the BIC-best subset)
    pair_tries: int = ranged(2, Int(ge=0))
    # compensation guard (loop.refit): every round also re-fits the current parameters with no new effect (the
    # null try, same budget, same twin batches); an effect must pass the gate against it too. Before the final
    # check, up to final_refit_iters Levenberg-Marquardt steps bring the final twin to its optimum (0 = off)
    null_try: bool = True
    # a set that passes the gate does not end the round: smaller sets, and larger ones while the residual stays
    # above the noise, may replace it (loop.compete); false = the first set that passes is kept
    compete: bool = True
    # every finish of a search that has the camera also starts from the camera's best other basin: a grid of
    # principal points, f and rotation in closed form (loop.basins); false = the search's best trials only
    camera_basins: bool = True
    # the grid also spans the rotation (its nominal 5 deg step) and is refined `camera_grid_refine` times at half the
    # step through the best start's own f and rotation (loop.basins): the binding moves with the rotation as with the
    # principal point (5 deg = 26 px at the image circle's 300 px), and a grid at the current rotation ranked the basins
    # through the wrong binding (dev seed 1, contact + camera at the true physics: the old grid's start ended its LM
    # chain at 0.90 px, the truth fits 0.24 px; docs/loop.md). 3 halvings end at 2.5 px / 0.6 deg, the finish's own
    # finite-difference unit (loop.polish: 2 % of the width), below which its Jacobian sees the binding's kinks.
    # Opt-in (false / 0: the principal point only, at the current rotation) until the 60-run GPU self-test measures
    # it: on the reduced dev-seed loop it fixed one strong contact + camera run and lost the other to a wrong set
    # (the grid runs at the search's physics, where k_s / E trade against f; docs/loop.md). The GPU script turns it on
    camera_grid_rotation: bool = False
    camera_grid_refine: int = ranged(0, Int(ge=0))
    # the rotation grid (3 halvings) where the physics is near its optimum instead: a start of the round's null try and
    # of the final refit of a set that has the camera (both converge; the final refit keeps a start only if the
    # held-out is not significantly worse). At the search's physics of the try that adds the camera the grid's f
    # absorbed a k_s error (dev seed 1, docs/loop.md); at converged physics it reaches the truth (the same sets at the
    # true physics: 0.25-0.33 px). With projected_null: 60-run self-test (issue 13) exact set 84 -> 92 % on seed 0,
    # 76 -> 86 % on seed 2 (never used in development), in-list `unexplained` 2 -> 0 / 2 -> 2 (docs/loop.md)
    # (base and the GPU self-test; quick and paper keep it off until a full paper run re-makes their tables)
    camera_grid_converged: bool = True
    # a set's search also starts from the end point of every subset of it tried earlier in the round (the null
    # try's: the empty set), so a larger set fits at least as well as what it contains (loop.refit.subset_starts)
    nested_starts: bool = True
    # the null try's finish goes on to final_refit_iters LM steps (the final refit's convergence) while still
    # descending: the tries after it start from its end point, so an unconverged null lets an extra effect pass
    # the gate on the optimiser's extra steps alone (loop.refit.finish). 60-run H200 self-test: exact set 72 -> 84 %,
    # false accepts 36 -> 27 %, no new miss (docs/loop.md); the paper real-photo loop is the same either way
    null_converge: bool = True
    # the round's winner is also gated against its projected null: its new effects switched off at its end point and
    # the rest re-fitted to final_refit_iters LM steps (the winner finished to the same cap), so an extra effect is
    # not credited with what the old set reaches from there (loop.projected; 60-run self-test runs 28 and 48: the
    # round-2 null stalled above the noise, the extra effect's try reached the old set's truth with it nearly idle).
    # Measured with camera_grid_converged (above); alone on seed 0: 84 -> 88 %, false reject 14 % (docs/loop.md)
    projected_null: bool = True
    # up to final_refit_iters LM steps; a chain stops earlier once a step gains < 0.1 % (loop.polish.MIN_GAIN).
    # 3 left the 60-run H200 self-test's contact + camera finals still descending (1.63 -> 1.08 px in 3 steps)
    final_refit_iters: int = ranged(10, Int(ge=0))
    # after the final refit, up to this many more passes of the camera's rotation grid (3 halvings) at the refit's own
    # end point, each followed by LM and kept as the refit (fit falls, held-out not significantly worse), while the
    # fitted residual stays above unexplained_ratio x the noise (loop.refit.after_passes). The first pass's grid runs
    # at the final twin, which need not be the start the refit ends from: held-out seed 2, runs 31 / 39 (contact + a
    # camera) were flagged `unexplained` at 2.3 / 2.0x at a converged (k_s, f) stall (docs/loop.md, "Held-out seed").
    # Adopted with final_refit_off_starts by the rule written before the 60-run GPU self-tests (H100, 2026-11-26):
    # in-list `unexplained` 0 + 2 -> 0 + 0 on seeds 0 and 2, no run lost, out-of-list 100 %; seed 7 (held out):
    # every aim met. Base and the GPU self-test; quick and paper keep it off (0)
    final_refit_regrid: int = ranged(2, Int(ge=0))
    # after the final refit, one LM pass from its end point with each added effect switched off (where that point lies in
    # the search box; not contact), above unexplained_ratio x the noise (loop.refit.after_passes): an effect kept in
    # an early round can hold a compensating basin once a later one arrived (held-out seed 2, run 31: contact + camera
    # + mount for contact + mount, `unexplained` at 2.3x; on the CPU LM from its camera-off point reaches the truth,
    # 1.05x). Adopted with final_refit_regrid (above)
    final_refit_off_starts: bool = True
    # after the final refit each added effect is taken out (switched off; if that is significantly worse, the rest
    # re-fitted): one the twin does not significantly need (gate_z) leaves the named set and the twin file
    # (loop.parsimony). Off: on the 12 runs of generative dev seed 0 (CPU, quick sizes) it took out one spurious
    # mount (in a run still missing an effect) and one true weak layered shell: exact sets 8 -> 7 of 10; a variant
    # asking the rounds' gate instead took out true weak mounts: 8 -> 6 (docs/loop.md, "5c")
    prune: bool = False
    # every try (the null try too) is finished by a bounded Levenberg-Marquardt solver after its search
    # (loop.polish): polish_iters iterations from its polish_starts best distinct trials (0 = off), so tries
    # are compared at convergence; the final refit starts from the final twin and final_refit_starts - 1
    # more distinct trials of the last kept try (a camera found in the wrong basin)
    polish_iters: int = ranged(2, Int(ge=0))
    polish_starts: int = ranged(1, Int(ge=1))
    final_refit_starts: int = ranged(3, Int(ge=1))
    # gate (loop.gate): a fit that falls this much is kept if the held-out does
    gate_fit_rel: float = ranged(0.3, Num(gt=0, le=1))
    gate_z: float = ranged(2.0, Num(gt=0))  # not move beyond gate_z cluster standard errors either way
    # final check (loop.unexplained): detector noise assumed when the set gives none, the test's level and
    # the RMS ratio over the noise from which an unexplained residual is reported
    noise_px: float = ranged(0.2, Num(gt=0))
    unexplained_alpha: float = ranged(1.0e-3, Num(gt=0, lt=1))
    unexplained_ratio: float = ranged(2.0, Num(gt=0))
    # the mean-MAE target (issue 5: 0.25 mm) was set for the flat-tip photo set only: it is judged on the set
    # whose file stem is target_set, never on another (issue 13.6)
    target_set: str = "measured_photos"
    target_mm: float = ranged(0.25, Num(gt=0))
    shell_thickness_mm: float = ranged(1.5, Num(gt=0))  # layered skin (SPEC gives no two-material values; a choice)
    calibrate_round0: bool = True  # fit `round0_params` before any effect (round 0 = the calibrated twin)
    round0_params: list[str] = ranged(rule=ListOf(Choice(*PARAMS), 0, unique=True), factory=lambda: ["E"])
    # searched every round, with the effects'
    recalibrate: list[str] = ranged(rule=ListOf(Choice(*PARAMS), 0, unique=True), factory=lambda: ["E"])
    # nominal step per parameter, over effects.py
    steps: dict[str, float] = ranged(rule=DictOf(Num(gt=0)), factory=dict)
    search: SearchSettings = field(default_factory=SearchSettings)
    selftest: SelftestConfig = field(default_factory=SelftestConfig)
    generative: GenerativeConfig = field(default_factory=GenerativeConfig)  # drawn truths (loop.generative)
    split_by_kind: str = "auto"  # one twin batch per kind: auto (= on the CPU), true, false
    max_frames: Optional[int] = ranged(None, Int(ge=1, null=True))  # cut every trajectory (smoke tests only)

    def validate(self) -> "LoopConfig":
        check_effects(self.effects, "loop.effects")
        from palpation.loop.selftest import parse_case
        for case in self.selftest.cases:
            parse_case(case, self.selftest.base_effects)
        check_effects(self.selftest.base_effects, "loop.selftest.base_effects")
        for where, names in (("loop.round0_params", self.round0_params), ("loop.recalibrate", self.recalibrate),
                             ("loop.steps", list(self.steps)), ("loop.selftest.base_params",
                                                                 list(self.selftest.base_params))):
            unknown = [n for n in names if n not in PARAMS]
            if unknown:
                raise ValueError(f"{where}: unknown parameter(s) {unknown}; known: {sorted(PARAMS)}")
        for name, pair in self.search.bounds.items():
            if name not in PARAMS or len(pair) != 2 or not float(pair[0]) < float(pair[1]):
                raise ValueError(f"loop.search.bounds.{name}: need a known parameter and [low, high] with "
                                 f"low < high, got {pair}")
        for s in (self.search,):
            if s.sampler not in SAMPLERS or s.n_trials < 1 or s.n_startup < 0 or s.batch_size < 1 \
                    or s.ask_workers < 1:
                raise ValueError(f"loop.search: need sampler in {SAMPLERS}, n_trials >= 1, n_startup >= 0, "
                                 f"batch_size >= 1, ask_workers >= 1, got {s}")
        if self.tries_per_round < 1 or self.pair_tries < 0:
            raise ValueError(f"loop.tries_per_round={self.tries_per_round}, loop.pair_tries={self.pair_tries}: "
                             "need tries_per_round >= 1 and pair_tries >= 0")
        if self.final_refit_regrid < 0:
            raise ValueError(f"loop.final_refit_regrid={self.final_refit_regrid}: need >= 0 (0 = off)")
        if self.camera_grid_refine < 0:
            raise ValueError(f"loop.camera_grid_refine={self.camera_grid_refine}: need >= 0 (0 = the first grid only)")
        if self.final_refit_iters < 0 or self.polish_iters < 0 or self.polish_starts < 1 \
                or self.final_refit_starts < 1:
            raise ValueError(f"loop.final_refit_iters={self.final_refit_iters}, loop.polish_iters="
                             f"{self.polish_iters}, loop.polish_starts={self.polish_starts}, loop.final_refit_starts="
                             f"{self.final_refit_starts}: need iters >= 0 (0 = off) and starts >= 1")
        if not 0 < self.gate_fit_rel <= 1 or self.gate_z <= 0:
            raise ValueError(f"loop.gate_fit_rel={self.gate_fit_rel}, loop.gate_z={self.gate_z}: need "
                             "0 < gate_fit_rel <= 1 and gate_z > 0")
        if self.max_rounds < 0 or self.selftest.max_rounds < 1 or self.selftest.runs_per_case < 1 \
                or not self.selftest.cases:
            raise ValueError("loop: need max_rounds >= 0, selftest.max_rounds >= 1, selftest.runs_per_case >= 1 "
                             "and at least one selftest case")
        if not 0 < self.selftest.strength_low <= self.selftest.strength_high or self.selftest.noise_px < 0:
            st = self.selftest
            raise ValueError(f"loop.selftest: need 0 < strength_low <= strength_high and noise_px >= 0, got "
                             f"{st.strength_low}, {st.strength_high}, {st.noise_px}")
        if self.noise_px <= 0 or not 0 < self.unexplained_alpha < 1 or self.unexplained_ratio <= 0:
            raise ValueError(f"loop.noise_px={self.noise_px}, loop.unexplained_alpha={self.unexplained_alpha}, "
                             f"loop.unexplained_ratio={self.unexplained_ratio}: need noise_px > 0, 0 < alpha < 1 "
                             "and ratio > 0")
        if self.shell_thickness_mm <= 0:
            raise ValueError(f"loop.shell_thickness_mm={self.shell_thickness_mm}: must be > 0")
        if str(self.split_by_kind).lower() not in ("auto", "true", "false"):
            raise ValueError(f"loop.split_by_kind must be auto, true or false, got {self.split_by_kind}")
        return self

    def split(self, device: str) -> bool:
        mode = str(self.split_by_kind).lower()
        return str(device).startswith("cpu") if mode == "auto" else mode == "true"


def register_configs() -> None:
    ConfigStore.instance().store(group="loop", name="base_loop", node=LoopConfig)


register_configs()
