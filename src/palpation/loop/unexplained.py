"""The loop's last step: is what remains detector noise, something the candidates could still explain, or
unexplained? And how well is each fitted parameter determined?

* Noise: the detector's per-coordinate noise, from the set's metadata (a twin-made set records it), else
  from repeated rest frames (a rest-like state against the set's rest photo: their difference has twice
  the variance), else the configured assumption (SPEC §13.2: photo noise < 0.2 px), said so in the report.
* Test: the final residual at the fitted states, minus its least-squares projection on the columns of the
  parameters the final twin has, is what the final twin cannot reach. T = |r_perp|^2 / sigma^2 ~ chi2(N - k)
  under "noise only"; the residual is *unexplained* when p < alpha AND its RMS exceeds `ratio` x sigma (N
  counts spatially correlated markers, so the chi-square alone flags any model error; the ratio sets the
  size). The share the remaining candidates' columns would also span is reported beside it, not used to clear
  it: an outside effect that in-list columns span linearly stayed unflagged though the loop's tries of those
  candidates had been refused (`loop.method.unexplained_beyond`: twin, or candidates for the earlier rule).
* Structure of an unexplained residual: residual modes (loop.residual), where on the dome the local
  part sits (centre disc or which ring sector), and how the residual scales with the state's depth.
* Discrepancy (Kennedy-O'Hagan style, last resort, not physics): a rank-1 correction of the marker
  field, r_i ~ a_i v over the fitted states (SVD), its amplitude for a held-out state regressed on depth.
* Uncertainty (Laplace): at the final twin the refit columns J (one per searched dof) give
  cov = s^2 (J^T J)^-1, s^2 = max(sigma^2, RSS / (N - k)); per dof its standard deviation in parameter
  units and the correlations, so a pair that trades (E and k_s) shows |rho| near 1.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from scipy.stats import chi2

from palpation.loop.attribution import Signature
from palpation.loop.engine import refit_dofs, signatures
from palpation.loop.gate import N_SECTORS, clusters
from palpation.loop.parsimony import prune
from palpation.loop.problem import evaluate
from palpation.loop.refit import above_noise, converge
from palpation.loop.residual import decompose
from palpation.measured import MeasuredSet

REST_KINDS = ("rest",)


def noise_estimate(mset: MeasuredSet, assumed_px: float) -> tuple[float, str]:
    """(per-coordinate detector noise px, where it comes from)."""
    det = mset.meta.get("detector") or {}
    if isinstance(det, dict) and det.get("noise_px") is not None:
        return float(det["noise_px"]), "the set's detector metadata"
    rest = np.asarray(mset.rest, np.float64)
    diffs = [np.asarray(m, np.float64) - rest for s, m in zip(mset.states, mset.markers)
             if (s.trajectory in REST_KINDS or (s.trajectory == "press" and (s.depth_mm or 0.0) == 0.0))
             and s.source_file != mset.meta.get("rest_source")]
    diffs = [d for d in diffs if np.any(d != 0)]
    if diffs:
        d = np.concatenate([x.reshape(-1) for x in diffs])
        return float(np.sqrt(np.mean(d ** 2) / 2.0)), f"{len(diffs)} repeated rest frame(s) against the rest photo"
    return float(assumed_px), "assumed (loop.noise_px; SPEC §13.2 photo noise < 0.2 px)"


def residual_test(residual: np.ndarray, columns: np.ndarray, sigma: float, alpha: float, ratio: float) -> dict:
    """Chi-square test of the part of `residual` (stacked fitted coordinates, sim - real) outside the span
    of `columns` against detector noise `sigma` px per coordinate."""
    r = np.asarray(residual, np.float64).reshape(-1)
    X = np.asarray(columns, np.float64)
    live = X[:, np.sqrt(np.mean(X ** 2, axis=0)) > 1e-9] if X.size else np.zeros((len(r), 0))
    k = int(np.linalg.matrix_rank(live)) if live.size else 0
    r_perp = r - live @ np.linalg.lstsq(live, r, rcond=None)[0] if k else r
    dof = max(len(r) - k, 1)
    T = float(r_perp @ r_perp) / sigma ** 2
    rms = float(np.sqrt(r_perp @ r_perp / dof))
    p = float(chi2.sf(T, dof))
    return {"rms_px": float(np.sqrt(np.mean(r ** 2))), "rms_unexplained_px": rms, "noise_px": sigma,
            "excess_ratio": rms / sigma, "chi2": T, "dof": dof, "p_value": p, "columns": k,
            "explained_by_candidates": 1.0 - float(r_perp @ r_perp) / float(r @ r) if r @ r > 0 else 0.0,
            "unexplained": bool(p < alpha and rms > ratio * sigma), "r_perp": r_perp}


def structure(targets, markers: np.ndarray) -> dict:
    """Name the residual's structure: dominant mode, where the local part sits, depth scaling."""
    rows, per_state = [], []
    for t, m in zip(targets, markers):
        d = decompose(m, t.markers, t.name)
        rows.append(d)
        r = np.asarray(m, np.float64) - t.markers
        e = (r ** 2).sum(axis=1)
        lab = clusters(t.markers)
        per_state.append({"name": t.name, "depth_mm": t.state.depth_mm, "rms_px": float(np.sqrt(e.mean())),
                          "energy_by_cluster": [float(e[lab == c].sum()) for c in range(N_SECTORS + 1)]})
    shares = {k: float(np.mean([d.shares[k] for d in rows])) for k in rows[0].shares}
    dominant = max(shares, key=shares.get)
    energy = np.sum([s["energy_by_cluster"] for s in per_state], axis=0)
    where = int(np.argmax(energy))
    total = float(energy.sum()) or 1.0
    sector = "the centre disc" if where == 0 else \
        f"ring sector {where} of {N_SECTORS} (image angle {-180 + (where - 0.5) * 360 / N_SECTORS:.0f}°)"
    depths = np.array([s["depth_mm"] if s["depth_mm"] is not None else np.nan for s in per_state], float)
    rms = np.array([s["rms_px"] for s in per_state])
    ok = np.isfinite(depths)
    if ok.sum() >= 2 and np.ptp(depths[ok]) > 0:
        slope = float(np.polyfit(depths[ok], rms[ok], 1)[0])
        scaling = f"{slope:+.2f} px RMS per mm of depth"
    else:
        slope, scaling = float("nan"), "not measurable (one depth)"
    kind = {"translation": "a rigid shift", "rotation": "a rotation", "radial": "radial (scale)",
            "stretch_shear": "tangential/anisotropic stretch", "local": "local"}[dominant]
    return {"shares": shares, "dominant": dominant, "kind": kind, "where": sector,
            "where_share": float(energy[where] / total), "depth_slope_px_per_mm": slope, "depth_scaling": scaling,
            "text": f"{kind} ({shares[dominant]:.0%} of the energy), concentrated in {sector} "
                    f"({energy[where] / total:.0%}), {scaling}"}


def discrepancy(targets, markers: np.ndarray) -> dict:
    """Rank-1 marker-field correction fitted on the fitted states, scored on the held-out ones."""
    fit = [i for i, t in enumerate(targets) if t.fit]
    held = [i for i, t in enumerate(targets) if not t.fit]
    R = np.stack([(markers[i] - targets[i].markers).reshape(-1) for i in fit])
    U, S, Vt = np.linalg.svd(R, full_matrices=False)
    v, a = Vt[0], U[:, 0] * S[0]
    depth = np.array([targets[i].state.depth_mm or 0.0 for i in fit])

    def amp(i: int) -> float:
        if len(fit) >= 2 and np.ptp(depth) > 0:
            c = np.polyfit(depth, a, 1)
            return float(np.polyval(c, targets[i].state.depth_mm or 0.0))
        return float(a.mean())

    def mae(i, corr):
        x = markers[i] - corr.reshape(-1, 2)
        return float(np.linalg.norm(x - targets[i].markers, axis=1).mean())

    fit_after = float(np.mean([mae(i, a[j] * v) for j, i in enumerate(fit)]))
    held_after = float(np.mean([mae(i, amp(i) * v) for i in held])) if held else float("nan")
    return {"rank": 1, "share_of_fit_energy": float(S[0] ** 2 / (S ** 2).sum()) if S.sum() > 0 else 0.0,
            "mae_fit_px": fit_after, "mae_heldout_px": held_after}


def laplace(refit: Signature, dofs, residual: np.ndarray, sigma: float) -> dict:
    """Per searched dof: sd in nominal steps and in its parameter's unit, and the correlations."""
    J = refit.columns
    live = np.sqrt(np.mean(J ** 2, axis=0)) > 1e-9
    r = np.asarray(residual, np.float64).reshape(-1)
    n, k = J.shape[0], int(live.sum())
    out = {"dofs": [], "corr": {}}
    if k == 0:
        return out
    Jl = J[:, live]
    s2 = max(sigma ** 2, float(r @ r) / max(n - k, 1))
    cov = s2 * np.linalg.pinv(Jl.T @ Jl)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    names = [d for d, ok in zip(refit.dofs, live) if ok]
    moves = {d.name: d.moves for d in dofs}
    for name, s in zip(names, sd):
        text = []
        for param, mode, amount in moves.get(name, ()):
            text.append(f"{param} ±{100 * s * np.log(amount):.1f} %" if mode == "mul" else f"{param} ±{s * amount:.3g}")
        out["dofs"].append({"dof": name, "sd_steps": float(s), "sd": ", ".join(text)})
    c = cov / np.outer(sd, sd).clip(1e-300)
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            out["corr"][f"{names[i]}~{names[j]}"] = float(c[i, j])
    return out


def final_check(p, sigs: list[Signature], cond: Mapping[str, Signature], refit: Signature, refit_dofs,
                sigma: float, alpha: float, ratio: float, beyond: str = "twin") -> dict:
    """Everything the verdict needs about the final twin of problem `p` (signatures at its final params).
    `beyond`: the verdict's residual lies beyond the twin's own columns (twin) or every candidate's too."""
    fit_ix = [i for i, t in enumerate(p.targets) if t.fit]
    residual = np.stack([p.markers[i] - p.targets[i].markers for i in fit_ix])

    def stacked(group):
        cols = [s.columns for s in group if s.columns.size]
        return np.concatenate(cols, axis=1) if cols else np.zeros((residual.size, 0))

    span = residual_test(residual, stacked([*sigs, *cond.values(), refit]), sigma, alpha, ratio)
    test = span if beyond == "candidates" else residual_test(residual, stacked([refit]), sigma, alpha, ratio)
    test = {**test, "beyond": beyond, "explained_by_candidates": span["explained_by_candidates"],
            "excess_beyond_candidates": span["excess_ratio"]}
    test.pop("r_perp")
    out = {"test": test, "structure": structure(p.targets, p.markers),
           "uncertainty": laplace(refit, refit_dofs, residual, sigma)}
    if test["unexplained"]:
        out["discrepancy"] = discrepancy(p.targets, p.markers)
    return out


def check_all(problems: list, simulate, cfg, sigmas: Mapping[str, float]) -> None:
    """The final check of every problem, in one signature batch for those whose twin moved since their
    last round's signatures (a round that kept an effect); the result lands in problem.final."""
    evaluate([p for p in problems if p.markers is None], simulate)
    m, limits = cfg.method, cfg.search.bounds
    polished = {}
    if m.final_refit_iters > 0:  # test what the twin cannot reach, not what the search left (loop.refit)
        polished = converge(problems, simulate, limits, m.final_refit_iters, m.gate_z, m.camera_grid_converged,
                            dict(m.steps), m.final_refit_regrid, m.unexplained_ratio, m.final_refit_off_starts,
                            m.stiffness_starts)
    if m.prune != "off":  # the named set: only the added effects the final twin needs (loop.parsimony)
        # the effects of these sets are also re-fitted without each (else only switched off: inert or not)
        refit = {"inert": set(), "all": {p.name for p in problems},
                 "above_noise": {p.name for p in above_noise(problems, m.unexplained_ratio)}}[m.prune]
        for group, iters in (([p for p in problems if p.name not in refit], 0),
                             ([p for p in problems if p.name in refit], m.final_refit_iters)):
            if group:
                prune(group, simulate, {p.name: {**limits, **p.trust} for p in group}, iters, m.gate_z,
                      m.min_strength_steps)
    stale = [p for p in problems if p.last_signatures is None or p.last_signatures["params"] != p.params]
    for p in stale:
        p.refit = refit_dofs(p)
    if stale:
        sigs, refits, conds = signatures(stale, simulate, dict(cfg.method.steps))
        for p in stale:
            p.last_signatures = {"params": dict(p.params), "sigs": sigs[p.name], "refit": refits[p.name],
                                 "cond": conds[p.name], "refit_dofs": list(p.refit)}
    for p in problems:
        s = p.last_signatures
        p.final = final_check(p, s["sigs"], s["cond"], s["refit"], s["refit_dofs"], sigmas[p.name],
                              cfg.method.unexplained_alpha, cfg.method.verdict_ratio, cfg.method.unexplained_beyond)
        if p.name in polished:
            p.final["refit"] = polished[p.name]
