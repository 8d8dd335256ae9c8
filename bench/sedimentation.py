"""Hindered settling function K(phi) = 6 pi <U>/F of sdmpi's hydrodynamics: the same force F
on every sphere (`solve_mobility`, Stokes units, zero-volume-flux frame), on simple cubic
arrays and on equilibrium hard-sphere configurations; writes bench/sedimentation.json
(docs/validation.md, "Sedimentation", compares it with exact hydrodynamics).

Arrays (one sphere per periodic cell): full SD and far field alone, against the FTS
closed form 1 - 2.837297 a/L + phi (Hasimoto 1959, the self Ewald sum of the
Rotne-Prager tensor), the exact drag of Zick & Homsy (1982, table 2) and the series of
Sangani & Acrivos (1982).

Random suspensions: Monte Carlo starts of sdmpi.dynamics.initial.hard_sphere_fluid
(independent seeds), the force along x, y and z in turn (K averaged over the three), full
SD, far field alone (FTS: stresslets from E = 0) and the Rotne-Prager (force-torque) level
alone (U = M_UF F), and eta'_inf of the same configurations; one standard error over the
configurations. K of N spheres in a periodic box differs from the infinite system by
the periodic images of each sphere and its correlation hole (`size_correction`).

    python bench/sedimentation.py [--sizes 27 64 125] [--configs 40 20 10]
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro import solve_mobility
from sdmpi.hydro.bulk import hydrodynamic_viscosity
from sdmpi.hydro.farfield import NDOF, far_field_mobility

PHIS = (0.05, 0.1, 0.2, 0.3, 0.4, 0.45)
#: Hasimoto's constant: 6 pi U/F = 1 - HASIMOTO a/L for point forces on a simple cubic lattice
HASIMOTO = 2.8372975
#: Zick & Homsy (1982), table 2, simple cubic array: (phi, drag F/(6 pi a U))
ZICK_HOMSY = ((0.027, 2.008), (0.064, 2.810), (0.125, 4.292), (0.216, 7.442), (0.343, 15.4), (0.45, 28.1))


def lattice_k(phi, lubrication):
    """6 pi U_z for a unit force on one unit sphere per cubic cell at volume fraction phi."""
    side = (4 * math.pi / (3 * phi)) ** (1 / 3)
    u, _, _ = solve_mobility(np.zeros((1, 3)), np.full(3, side), forces=np.array([[0.0, 0.0, 1.0]]),
                             lubrication=lubrication, ewald_tol=1e-10)
    return 6 * math.pi * u[0, 2]


def fts_lattice(phi):
    """The FTS (Rotne-Prager) value for a simple cubic array, 1 - HASIMOTO a/L + phi."""
    return 1 - HASIMOTO * (3 * phi / (4 * math.pi)) ** (1 / 3) + phi


def sangani_acrivos(phi):
    """Sangani & Acrivos (1982) simple cubic series, chi = phi^(1/3):
    1 - 1.7601 chi + chi^3 - 1.5593 chi^6 + 3.9799 chi^8 - 3.0734 chi^10."""
    c = phi ** (1 / 3)
    return 1 - 1.7601 * c + c ** 3 - 1.5593 * c ** 6 + 3.9799 * c ** 8 - 3.0734 * c ** 10


def structure_factor_zero(phi):
    """S(0) of hard spheres, Carnahan-Starling: (1 - phi)^4 / (1 + 4 phi + 4 phi^2 - 4 phi^3 + phi^4)."""
    return (1 - phi) ** 4 / (1 + 4 * phi + 4 * phi ** 2 - 4 * phi ** 3 + phi ** 4)


def size_correction(phi, n, eta):
    """K_inf - K_N = HASIMOTO (a/L) S(0) / eta: each sphere's periodic images and those of
    its correlation hole (net weight S(0)) in a medium of relative viscosity eta."""
    return HASIMOTO * (3 * phi / (4 * math.pi * n)) ** (1 / 3) * structure_factor_zero(phi) / eta


def exact_k(phi):
    """Fit to exact (multipole, lubrication-corrected) hydrodynamics, infinite system,
    attributed to Abade et al., J. Chem. Phys. 132, 014503 (2010) (docs/validation.md):
    1 - 6.5464 phi (1 - 3.348 phi + 7.426 phi^2 - 10.034 phi^3 + 5.882 phi^4)."""
    return 1 - 6.5464 * phi * (1 - 3.348 * phi + 7.426 * phi ** 2 - 10.034 * phi ** 3 + 5.882 * phi ** 4)


def measure(n, phi, configs, seed=2039):
    """Per configuration: K (full SD), K (far field alone), K (Rotne-Prager level) and
    eta'_inf."""
    rows = []
    for k in range(configs):
        rng = np.random.default_rng([seed, n, int(round(1000 * phi)), k])
        pos, side = hard_sphere_fluid(n, phi, rng)
        box = np.full(3, side)
        row = []
        for lubrication in (True, False):
            total = 0.0
            for axis in range(3):
                forces = np.zeros((n, 3))
                forces[:, axis] = 1.0
                u, _, _ = solve_mobility(pos, box, forces=forces, lubrication=lubrication)
                total += u[:, axis].mean()
            row.append(2 * math.pi * total)  # 6 pi <U> averaged over the three axes
        u_rows = (NDOF * np.arange(n)[:, None] + np.arange(3)).ravel()
        m_uf = far_field_mobility(pos, np.ones(n), box)[np.ix_(u_rows, u_rows)]
        row.append(2 * math.pi * np.trace(m_uf.reshape(n, 3, n, 3).sum(axis=(0, 2))) / n)
        row.append(1 + hydrodynamic_viscosity(pos, box))
        rows.append(row)
    return np.array(rows)


def summary(values):
    return float(values.mean()), float(values.std(ddof=1) / math.sqrt(len(values)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[27, 64, 125])
    parser.add_argument("--configs", type=int, nargs="+", default=[40, 20, 10],
                        help="configurations per phi, one number per size")
    parser.add_argument("--out", default=str(Path(__file__).with_name("sedimentation.json")))
    args = parser.parse_args()
    if len(args.configs) != len(args.sizes):
        parser.error("--configs needs one number per size")
    lattice = []
    for phi, drag in ZICK_HOMSY:
        lattice.append({"phi": phi, "sd": lattice_k(phi, True), "far_field": lattice_k(phi, False),
                        "fts_closed_form": fts_lattice(phi), "sangani_acrivos": sangani_acrivos(phi),
                        "zick_homsy": 1 / drag})
        print("array phi = {phi:.3f}: SD {sd:.4f}, far field {far_field:.4f}, FTS form {fts_closed_form:.4f}, "
              "exact {zick_homsy:.4f}".format(**lattice[-1]), flush=True)
    rows = []
    for n, configs in zip(args.sizes, args.configs):
        for phi in PHIS:
            t = time.perf_counter()
            values = measure(n, phi, configs)
            (k_sd, e_sd), (k_ff, e_ff), (k_rp, e_rp), (eta, e_eta) = (summary(values[:, c]) for c in range(4))
            corr = size_correction(phi, n, eta)
            rows.append({"n_particles": n, "phi": phi, "configs": configs, "k_sd": k_sd, "k_sd_err": e_sd,
                         "k_far_field": k_ff, "k_far_field_err": e_ff, "k_rotne_prager": k_rp,
                         "k_rotne_prager_err": e_rp, "eta_inf": eta, "eta_inf_err": e_eta,
                         "s0": structure_factor_zero(phi), "size_correction": corr,
                         "k_sd_infinite": k_sd + corr, "exact_infinite": exact_k(phi)})
            print(f"N = {n:4d} phi = {phi:.2f}: K_SD = {k_sd:.4f} +- {e_sd:.4f}, far field {k_ff:.4f} +- {e_ff:.4f}, "
                  f"Rotne-Prager {k_rp:.4f}, eta'_inf {eta:.3f}; + size correction {corr:.4f} = {k_sd + corr:.4f}; exact {exact_k(phi):.4f} "
                  f"({time.perf_counter() - t:.0f} s)", flush=True)
    Path(args.out).write_text(json.dumps({"command": "python bench/sedimentation.py " + " ".join(sys.argv[1:]),
                                          "lattice": lattice, "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
