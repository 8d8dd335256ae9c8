"""Two hard spheres in a periodic box at rest, stepped through the model interface and the
overlap correction: the time fraction at small gaps against the exact equilibrium one (the
relative position is uniform outside the excluded sphere), per drift scheme, with or
without the near-contact correction (`sdmpi.dynamics.models`).

    python bench/near_contact_pair.py SCHEME DT BOX STEPS [SEED [uncorrected]]
    python bench/near_contact_pair.py rfd 5e-4 4.1 100000 3    # docs/physics.md, ~5 min

Errors: blocks of 1000 steps."""
import math
import sys
import time

import numpy as np

from sdmpi.dynamics.collisions import separate
from sdmpi.dynamics.models import ResistanceModel
from sdmpi.hydro.geometry import Lattice


def main():
    scheme, dt, side, n = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
    seed = int(sys.argv[5]) if len(sys.argv) > 5 else 3
    corrected_step = len(sys.argv) <= 6 or sys.argv[6] != "uncorrected"
    kt, min_gap, radii = 6 * math.pi, 1e-4, np.ones(2)
    lattice = Lattice(np.full(3, side), 0.0)

    def corrected(pos, strain=0.0):
        pos, collisions = separate(pos, radii, lattice, min_gap)
        return pos, collisions.n_overlaps

    model = ResistanceModel(radii, np.full(3, side), lubrication=True, ewald_tol=1e-6, cutoff=2.0,
                            min_gap=min_gap, scheme=scheme, separate=corrected)
    rng = np.random.default_rng(seed)
    pos = np.array([[1.0, 1.0, 1.0], [3.2, 1.1, 0.9]])
    gaps, contacts, start = np.empty(n), 0, time.time()
    for k in range(n):
        pos, found = corrected(lattice.wrap(pos))
        contacts += found > 0
        d = pos[1] - pos[0]
        d -= np.round(d / side) * side
        gaps[k] = np.linalg.norm(d) - 2
        at = model.at(pos, 0.0)
        if corrected_step:
            brownian = at.brownian(rng, kt, dt)
        else:
            brownian = at.brownian_terms(rng.standard_normal(at.solver.noise_shape), kt, dt)
        pos = at.positions + dt * brownian.velocities[:, :3]
    free = side ** 3 - 4 * math.pi * 8 / 3
    print(f"{scheme} {'corrected' if corrected_step else 'uncorrected'} dt={dt} box={side} steps={n} seed={seed} "
          f"contacts/step={contacts / n:.4f} "
          f"({time.time() - start:.0f} s)")
    for h in (3e-4, 1e-3, 3e-3, 1e-2, 3e-2):
        exact = 4 * math.pi / 3 * ((2 + h) ** 3 - 8) / free
        blocks = (gaps[: n // 1000 * 1000] < h).reshape(-1, 1000).mean(axis=1)
        print(f"  gap < {h:.0e}: time fraction / equilibrium = {blocks.mean() / exact:.3f} "
              f"+- {blocks.std() / math.sqrt(len(blocks)) / exact:.3f}")


if __name__ == "__main__":
    main()
