"""The press depth of each real slide estimated from its unlabelled marker motion with a twin-made lookup, and the
Sim set's depths drawn over those estimates (`dataset.depths_from`, docs/transfer.md).

A slide's *signature* is read from its markers relative to a rest layout, frame by frame, after the whole field's
translation is taken off (the trial-specific drift that no twin reproduces, docs/loop.md): the mean outward radial
displacement about the layout's centroid (a deeper press spreads the markers) and the RMS of the displacement;
the slide's signature is their median over frames. The lookup is a least-squares fit of depth on the signature
over twin slides simulated at known depths (`set=depth_bank` of palpation.apps.simulate); its leave-one-out error
on the bank says how well the twin's own depths are recovered. Labels are never read.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from palpation.twin.trajectory import MAX_DEPTH_MM

log = logging.getLogger(__name__)
SIGNATURE = ("radial_px", "rms_px")


def slide_signature(markers: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """markers (T, 127, 2) px and the rest layout (127, 2) -> (radial, rms) px, medians over frames."""
    markers, rest = np.asarray(markers, np.float64), np.asarray(rest, np.float64)
    if markers.ndim != 3 or markers.shape[1:] != rest.shape or len(markers) == 0:
        raise ValueError(f"slide signature: markers must be (T, {len(rest)}, 2) with T >= 1, got {markers.shape}")
    d = markers - rest
    d = d - d.mean(axis=1, keepdims=True)  # the whole field's translation off
    out = rest - rest.mean(axis=0)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    unit = np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)
    radial = (d * unit).sum(-1).mean(-1)
    rms = np.sqrt((d ** 2).sum(-1).mean(-1))
    return np.array([np.median(radial), np.median(rms)])


@dataclass(frozen=True)
class DepthLookup:
    """depth_mm = coef[0] + coef[1:] . signature, fitted on twin slides at known depths."""

    coef: np.ndarray
    loo_rmse_mm: float  # leave-one-out RMS error of the fit on its own bank
    n_bank: int
    bank_mm: tuple[float, float] = (0.0, MAX_DEPTH_MM)  # the bank's shallowest and deepest slide

    @classmethod
    def fit(cls, signatures: np.ndarray, depths_mm: np.ndarray) -> "DepthLookup":
        x, y = np.asarray(signatures, np.float64), np.asarray(depths_mm, np.float64)
        if x.ndim != 2 or len(x) != len(y) or len(y) < x.shape[1] + 2 or len(np.unique(y)) < 2:
            raise ValueError(f"depth lookup: need at least {x.shape[-1] + 2} bank slides at 2 or more depths, got "
                             f"{len(y)} at {np.unique(y).tolist()} mm")
        a = np.column_stack([np.ones(len(x)), x])
        coef = np.linalg.lstsq(a, y, rcond=None)[0]
        loo = [y[i] - a[i] @ np.linalg.lstsq(np.delete(a, i, 0), np.delete(y, i), rcond=None)[0]
               for i in range(len(y))]
        return cls(coef, float(np.sqrt(np.mean(np.square(loo)))), len(y), (float(y.min()), float(y.max())))

    def raw(self, signatures: np.ndarray) -> np.ndarray:
        """The fit's depths (mm) of slides' signatures, unclipped."""
        x = np.atleast_2d(np.asarray(signatures, np.float64))
        return self.coef[0] + x @ self.coef[1:]

    def estimate(self, signatures: np.ndarray) -> np.ndarray:
        """Depths (mm) of slides' signatures, clipped to the twin's range [0, MAX_DEPTH_MM]."""
        return np.clip(self.raw(signatures), 0.0, MAX_DEPTH_MM)

    def in_bank(self, signatures: np.ndarray) -> np.ndarray:
        """Whether each fitted depth lies within the bank's depths widened by twice the leave-one-out error: outside
        it the lookup extrapolates (a slide that moves unlike any bank slide, e.g. another tissue's surface)."""
        raw, margin = self.raw(signatures), 2.0 * self.loo_rmse_mm
        return (raw >= self.bank_mm[0] - margin) & (raw <= self.bank_mm[1] + margin)


def read_estimates(path: str | Path) -> np.ndarray:
    """The `depth_mm` of the in-bank rows of an estimates CSV (workflow/scripts/latent_depth.py), checked: an
    estimate the lookup extrapolated (`in_bank` false) is left out, and a file with none in the bank is refused."""
    from palpation.readers import read_csv

    fix = "run workflow/scripts/latent_depth.py (docs/transfer.md)"
    df = read_csv(path, ("set", "trial", "depth_mm", "in_bank"), fix, "depth estimates")
    depths = np.asarray(df["depth_mm"].to_numpy(), np.float64) if df["depth_mm"].dtype.kind in "fiu" else None
    if depths is None or not np.all(np.isfinite(depths)) or np.any((depths < 0) | (depths > MAX_DEPTH_MM)):
        raise ValueError(f"{path}: need finite depth_mm in [0, {MAX_DEPTH_MM}] mm, one row per real slide")
    flags = df["in_bank"].astype(str).str.lower()
    if not flags.isin(["true", "false"]).all():
        raise ValueError(f"{path}: in_bank must be true or false on every row; {fix}")
    keep = (flags == "true").to_numpy()
    if not keep.any():
        raise ValueError(f"{path}: every estimate lies outside its bank's depths (in_bank false): the twin that made "
                         "the bank moves its markers unlike these slides; make a bank that spans them")
    if not keep.all():
        out = sorted(set(df.loc[~keep, "set"]))
        log.warning("%s: %d of %d estimates lie outside the bank's depths (sets %s) and are left out", path,
                    int((~keep).sum()), len(keep), out)
    return depths[keep]


def draw_depths(estimates: np.ndarray, n: int, seed: int) -> np.ndarray:
    """`n` depths drawn with replacement from the estimates (their empirical distribution), from a stream of their
    own (the set's other draws keep theirs: default_rng(seed) is not touched)."""
    rng = np.random.default_rng([seed, 0x64657074])  # "dept"
    return rng.choice(np.asarray(estimates, np.float64), size=n, replace=True)


def bank_lookup(manifest: str | Path) -> tuple[DepthLookup, list[dict]]:
    """The lookup fitted on a depth bank Sim set (each trajectory's markers about its own rest markers, its
    `depth_mm` from the record's params) and one row per bank slide (its depth, signature, fitted depth)."""
    from palpation.twin.output import load_trajectory, read_sim_manifest

    rows = []
    for f in read_sim_manifest(manifest)[1]:
        t = load_trajectory(f)
        depth = t["params"].get("depth_mm")
        if depth is None:
            raise ValueError(f"{f}: no depth_mm in its params; make the bank with set=depth_bank")
        sig = slide_signature(t["markers"], t["rest_markers_px"])
        rows.append({"trial": f.stem, "depth_mm": float(depth), **dict(zip(SIGNATURE, sig.tolist()))})
    sigs = np.array([[r[k] for k in SIGNATURE] for r in rows])
    lookup = DepthLookup.fit(sigs, np.array([r["depth_mm"] for r in rows]))
    for r, est in zip(rows, lookup.estimate(sigs)):
        r["fitted_mm"] = float(est)
    return lookup, rows


def real_estimates(lookup: DepthLookup, sets: dict[str, str | Path], rest: np.ndarray) -> list[dict]:
    """One row per real slide of each set ({name: path}, all trials): its signature and estimated depth."""
    from palpation.graph.sources import load_dataset

    rows = []
    for name, path in sets.items():
        seqs = load_dataset(name, path, "test")
        for trial, markers in zip(seqs.ids, seqs.markers):
            sig = slide_signature(markers, rest)
            rows.append({"set": name, "trial": trial, "depth_mm": float(lookup.estimate(sig)[0]),
                         "raw_mm": float(lookup.raw(sig)[0]), "in_bank": str(bool(lookup.in_bank(sig)[0])).lower(),
                         **dict(zip(SIGNATURE, sig.tolist()))})
    return rows
