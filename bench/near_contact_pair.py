"""Two hard spheres in a periodic box at rest, stepped through the model interface and the
overlap correction: the time fraction at small gaps against the exact equilibrium one (the
relative position is uniform outside the excluded sphere), per drift scheme.

    python bench/near_contact_pair.py SCHEME DT BOX STEPS [SEED]
    python bench/near_contact_pair.py rfd 5e-4 4.1 200000      # docs/physics.md, ~10 min

Errors: blocks of 1000 steps."""
import math, sys, time
import numpy as np
from sdmpi.dynamics.models import ResistanceModel
from sdmpi.dynamics.collisions import separate
from sdmpi.hydro.geometry import Lattice

scheme, dt, L, n = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
BOX = np.full(3, L); KT = 6 * math.pi; MIN_GAP = 1e-4; radii = np.ones(2); LAT = Lattice(BOX, 0.0)
sep = lambda p, strain: (lambda r: (r[0], r[1].n_overlaps))(separate(p, radii, LAT, MIN_GAP))
model = ResistanceModel(radii, BOX, lubrication=True, ewald_tol=1e-6, cutoff=2.0, min_gap=MIN_GAP,
                        scheme=scheme, separate=sep)
rng = np.random.default_rng(int(sys.argv[5]) if len(sys.argv) > 5 else 3)
pos = np.array([[1.0, 1.0, 1.0], [3.2, 1.1, 0.9]])
gaps = np.empty(n); nover = 0; t = time.time()
for k in range(n):
    pos, coll = separate(LAT.wrap(pos), radii, LAT, MIN_GAP); nover += coll.n_overlaps > 0
    d = pos[1] - pos[0]; d -= np.round(d / L) * L; gaps[k] = np.linalg.norm(d) - 2
    at = model.at(pos, 0.0)
    pos = at.positions + dt * at.brownian(rng, KT, dt).velocities[:, :3]
vfree = L ** 3 - 4 * math.pi * 8 / 3
out = [f"{scheme} dt={dt} L={L} n={n} contacts/step={nover/n:.4f} ({time.time()-t:.0f}s)"]
for hmax in (3e-4, 1e-3, 3e-3, 1e-2, 3e-2):
    exact = 4 * math.pi / 3 * ((2 + hmax) ** 3 - 8) / vfree
    b = (gaps[: n // 1000 * 1000] < hmax).reshape(-1, 1000).mean(axis=1)
    out.append(f"  h<{hmax:.0e}: sim/exact={b.mean()/exact:.3f} +- {b.std()/math.sqrt(len(b))/exact:.3f}")
print("\n".join(out), flush=True)
