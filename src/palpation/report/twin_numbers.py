"""The twin's verification figures in the docs, read from docs/results/twin_verification.json.

`workflow/scripts/twin_verification.py` writes that record (the command is inside it): uniaxial compression, the free
box's energy, the x5 length scale against mass_scale 25, SPEC's marker binding at rest, and the stable substep per mesh,
mass scale and damping. Registered in report.docnumbers.
"""

from __future__ import annotations

from pathlib import Path

from palpation.readers import read_json
from palpation.report.records import FIX

RECORD = "twin_verification.json"
DEFAULT_DT = 1e-5  # s, the reference's substep (conf/twin/reference.yaml), against which the limits are read


def _record(results: Path) -> dict:
    return read_json(results / RECORD, FIX, "record", kind=dict,
                     keys=("uniaxial", "energy", "mass_scale", "binding_rest_px", "stable_dt"))


def sci(value: float, digits: int = 3) -> str:
    """1.2864e-05 → '1.29e-5' (the docs' way of writing a substep)."""
    mantissa, exponent = f"{value:.{digits - 1}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def _pct(value: float, digits: int = 2, signed: bool = False) -> str:
    return f"{100 * value:{'+' if signed else ''}.{digits}f} %"


def _stable(results: Path, mesh: str, scale: float, alpha: float) -> dict:
    rows = [r for r in _record(results)["stable_dt"]
            if r["mesh"] == mesh and r["mass_scale"] == scale and r["alpha"] == alpha]
    if len(rows) != 1:
        raise ValueError(f"record {results / RECORD} has no one stable-dt row {mesh}/{scale}/{alpha}")
    return rows[0]


def stable_dt_table(results: Path) -> str:
    rows = ["| mesh | mass_scale | α (N s/m) | stable dt (s) | Courant estimate (s) |", "|---|---|---|---|---|"]
    rows += [f"| {r['mesh']} | {r['mass_scale']:g} | {r['alpha']:g} | **{sci(r['stable_dt_s'])}** | "
             f"{sci(r['courant_dt_s'])} |" for r in _record(results)["stable_dt"]]
    return "\n".join(rows)


def stable_dt(results: Path, what: str) -> str:
    if what == "margin":  # the reference's dt against the reference mesh's limit at mass_scale 25
        return f"{DEFAULT_DT / _stable(results, 'reference', 25.0, 0.02)['stable_dt_s']:.2f}"
    if what == "physical_over":
        over = sorted(DEFAULT_DT / _stable(results, "reference", 1.0, a)["stable_dt_s"] for a in (0.0, 0.02))
        return f"{over[0]:.1f}–{over[1]:.1f}×"
    if what == "damping":
        return (f"{sci(_stable(results, 'reference', 1.0, 0.02)['stable_dt_s'], 2)} s with α, "
                f"{sci(_stable(results, 'reference', 1.0, 0.0)['stable_dt_s'], 2)} s without")
    if what == "coarse":
        return f"{sci(_stable(results, 'coarse', 25.0, 0.02)['stable_dt_s'])} s"
    raise ValueError(f"unknown stable-dt figure {what}")


def uniaxial_table(results: Path) -> str:
    rows = ["| lame | strain | E measured | vs nominal E | lateral ratio |", "|---|---|---|---|---|"]
    for r in _record(results)["uniaxial"]:
        versus = (_pct(r["E_ratio"] - 1, signed=True) if r["lame"] == "smith"
                  else f"{r['E_ratio']:.3f} E (predicted {r['E_ratio_predicted']:.3f} E)")
        rows.append(f"| {r['lame']} | {_pct(r['strain'], 1)} | {r['E_measured_pa'] / 1e3:.1f} kPa | {versus} | "
                    f"{r['lateral_ratio']:.3f} |")
    return "\n".join(rows)


def verification(results: Path, what: str) -> str:
    """One measured figure of docs/twin.md's verification table (or its prose)."""
    record = _record(results)
    if what == "uniaxial":
        rows = {(r["lame"], r["strain"]): r for r in record["uniaxial"]}
        smith, standard = rows[("smith", 0.005)], rows[("standard", 0.005)]
        return (f"smith: E {_pct(smith['E_ratio'] - 1, signed=True)}, ν {smith['lateral_ratio']:.3f}; "
                f"standard: {standard['E_ratio']:.3f} E")
    e = record["energy"]
    if what == "energy_undamped":
        return (f"max \\|ΔE\\|/E₀ = {_pct(e['undamped_3000_max_rel_change'])} over 3000 substeps, "
                f"{_pct(e['undamped_30000_max_rel_change'])} over 30,000")
    if what == "energy_damped":
        rises = "never rises" if e["damped_max_rise_rel"] <= 0 else f"rises at most {_pct(e['damped_max_rise_rel'])}"
        return f"E({1e3 * e['damped_time_s']:.0f} ms)/E₀ = {e['damped_final_ratio']:.3f}, {rises}"
    m = record["mass_scale"]
    if what == "mass_scale":
        return (f"{sci(m['position_max_diff_m'], 2)} m of {1e3 * m['deflection_max_m']:.2f} mm; F_z within "
                f"{_pct(m['fz_rel_diff'])}")
    if what == "mass_scale_prose":
        return (f"the positions agree to {sci(m['position_max_diff_m'], 2)} m against a "
                f"{1e3 * m['deflection_max_m']:.2f} mm deflection, and F_z/25 agrees to {_pct(m['fz_rel_diff'])} "
                f"({abs(m['fz_x5_over_25_n']):.3f} vs {abs(m['fz_si_n']):.3f} N)")
    raise ValueError(f"unknown verification figure {what}")


def binding_offset(results: Path, which: str) -> str:
    """SPEC's markers at rest (5 bound dome nodes each) against the template they were bound to, mean px."""
    r = _record(results)["binding_rest_px"]
    if which == "coarse":
        return f"{r['coarse']['mean_px']:.2f} px"
    return (f"{r['coarse']['mean_px']:.2f} px (coarse, max {r['coarse']['max_px']:.0f}) / "
            f"{r['reference']['mean_px']:.2f} px (reference)")
