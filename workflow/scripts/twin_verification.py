"""Measure the twin's verification figures that docs/twin.md, docs/loop.md and docs/calibration.md state, on the CPU,
and write them as one record (docs/results/twin_verification.json, read by palpation.report.docnumbers):

    OMP_NUM_THREADS=2 PYTHONPATH=src python workflow/scripts/twin_verification.py \
        --mesh-cache results/twin --out docs/results/twin_verification.json

* uniaxial compression (tests/twin/test_elasticity.py::uniaxial_modulus): smith at 0.2 % and 0.5 %, standard at 0.5 %;
* the free box's energy, undamped over 30 and 300 frames of 100 substeps and damped over 30
  (tests/twin/test_integrate.py::free_box_energies);
* the x5 length scale against mass_scale 25 (tests/twin/test_simulator.py::mass_scale_pair);
* SPEC's marker binding at rest against the template it was bound to (twin.markers.bind_markers), per mesh;
* the largest stable substep (twin.bench.stable_dt, bisection to 3 %) and the Courant estimate, per mesh,
  mass scale and damping.

The same computations the tests assert bounds on; this script records the values. Each run takes a few minutes on
2 cores (the reference mesh's stability bisection dominates). The command that wrote the record is inside it.
"""

from __future__ import annotations

import argparse
import platform
import shlex
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
STABLE_DT_CASES = (  # (mesh, mass_scale, alpha N s/m): the rows of docs/twin.md's stable-dt table
    ("reference", 25.0, 0.02), ("reference", 1.0, 0.02), ("reference", 1.0, 0.0),
    ("coarse", 25.0, 0.02), ("coarse", 25.0, 0.0), ("coarse", 1.0, 0.02), ("coarse", 1.0, 0.0),
)


def uniaxial() -> list[dict]:
    from test_elasticity import E, NU, uniaxial_modulus

    from palpation.twin.elasticity import effective_youngs_modulus

    rows = []
    for lame, strain in (("smith", 0.002), ("smith", 0.005), ("standard", 0.005)):
        e, lateral, residual = uniaxial_modulus(lame, "cpu", strain=strain)
        rows.append({"lame": lame, "strain": strain, "E_measured_pa": float(e), "E_nominal_pa": E, "nu_nominal": NU,
                     "E_ratio": float(e / E), "lateral_ratio": float(lateral), "residual_rel": float(residual),
                     "E_ratio_predicted": float(effective_youngs_modulus(E, NU, lame) / E)})
    return rows


def energy() -> dict:
    from test_integrate import free_box_energies

    from palpation.twin.config import TwinConfig

    cfg = TwinConfig()
    out = {"dt_s": cfg.integrator.dt, "substeps_per_frame": 100}
    for frames in (30, 300):
        e = free_box_energies("cpu", alpha=0.0, beta=0.0, frames=frames)
        out[f"undamped_{frames * 100}_max_rel_change"] = float(np.abs(e / e[0] - 1).max())
    e = free_box_energies("cpu", alpha=0.02, beta=0.01, frames=30)
    out.update({"damped_alpha": 0.02, "damped_beta": 0.01, "damped_time_s": 30 * 100 * cfg.integrator.dt,
                "damped_final_ratio": float(e[-1] / e[0]), "damped_max_rise_rel": float(np.diff(e).max() / e[0])})
    return out


def mass_scale(coarse) -> dict:
    from test_simulator import mass_scale_pair

    big, phys = mass_scale_pair(coarse)
    fz_big, fz_phys = float(big.contact_forces().sum(1)[0, 2] / 25), float(phys.contact_forces().sum(1)[0, 2])
    return {"press_depth_m": 0.0027, "position_max_diff_m": float(np.abs(big.positions_world() / 5
                                                                           - phys.positions_world()).max()),
            "deflection_max_m": float(np.abs(phys.positions_world() - phys.undeformed_world()).max()),
            "fz_x5_over_25_n": fz_big, "fz_si_n": fz_phys, "fz_rel_diff": abs(fz_big - fz_phys) / abs(fz_phys),
            "contact": bool(phys.contact_flags()[0] and big.contact_flags()[0])}


def binding(meshes) -> dict:
    from palpation.markers.template import rest_template
    from palpation.twin.markers import bind_markers

    out = {}
    for name, mesh in meshes.items():
        r = bind_markers(mesh.nodes, mesh.dome_nodes, rest_template()).residual_px
        out[name] = {"mean_px": float(r.mean()), "max_px": float(r.max())}
    return out


def stability(meshes) -> list[dict]:
    from palpation.twin.bench import stable_dt
    from palpation.twin.config import TwinConfig
    from palpation.twin.elasticity import courant_dt

    rows = []
    for name, scale, alpha in STABLE_DT_CASES:
        cfg = TwinConfig()
        cfg.integrator.mass_scale, cfg.damping.alpha = scale, alpha
        mesh, m = meshes[name], cfg.material
        start = time.perf_counter()
        dt = stable_dt(mesh, cfg)
        rows.append({"mesh": name, "mass_scale": scale, "alpha": alpha, "stable_dt_s": dt, "rel_tol": 0.03,
                     "courant_dt_s": float(courant_dt(mesh.nodes, mesh.tets, m.E, m.nu, m.rho, scale)),
                     "wall_s": round(time.perf_counter() - start, 1)})
        print(rows[-1], flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mesh-cache", default="results/twin", help="mesh_{coarse,reference}.npz (rule `mesh`)")
    p.add_argument("--out", default="docs/results/twin_verification.json")
    a = p.parse_args(argv)
    sys.path.insert(0, str(REPO / "tests" / "twin"))  # the tests' own helpers, so the record measures what they check
    import warp as wp

    from palpation.io import save_json
    from palpation.twin.mesh import cached_sensor_mesh

    wp.config.quiet = True
    meshes = {r: cached_sensor_mesh(r, a.mesh_cache) for r in ("coarse", "reference")}
    record = {"command": "python workflow/scripts/twin_verification.py " + shlex.join(argv or sys.argv[1:]),
              "device": "cpu", "python": platform.python_version(), "warp": wp.__version__,
              "uniaxial": uniaxial(), "energy": energy(), "mass_scale": mass_scale(meshes["coarse"]),
              "binding_rest_px": binding(meshes), "stable_dt": stability(meshes)}
    save_json(Path(a.out), record)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
