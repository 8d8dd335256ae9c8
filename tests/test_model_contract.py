"""Every registered hydrodynamic model keeps the `sdmpi.dynamics.models.HydrodynamicEvaluation`
contract at one configuration in a sheared periodic box: a symmetric positive definite
mobility, relative mobilities that are its pair forms, the force pairs with their true
gaps, Brownian terms and statistics of the declared shapes."""

from pathlib import Path

import numpy as np
import pytest

import sdmpi
from sdmpi.dynamics.setup import hydrodynamic_model
from sdmpi.registry import HYDRODYNAMIC_MODELS

from .test_backend_contract import BOX, POSITIONS, STRAIN

DEMO = Path(__file__).resolve().parents[1] / "jobs" / "demo.toml"
#: the mobility of the direct backend is exact to rounding (cond ~30)
EXACT = 1e-12


@pytest.mark.parametrize("name", HYDRODYNAMIC_MODELS.names())
def test_model_keeps_the_contract(name):
    job = sdmpi.load_job(DEMO, [f'hydrodynamics.model="{name}"', "hydrodynamics.ewald_tolerance=1e-8"])
    n = len(POSITIONS)
    at = hydrodynamic_model(job, np.ones(n), BOX).at(POSITIONS, STRAIN)
    assert at.n_particles == n and at.positions.shape == (n, 3)
    zero = np.zeros((n, 5))
    unit = np.eye(6 * n).reshape(6 * n, n, 6)
    mobility = np.array([at.velocities(f, zero).ravel() for f in unit])
    scale = np.abs(mobility).max()
    assert np.abs(mobility - mobility.T).max() < EXACT * scale
    assert np.linalg.eigvalsh(mobility).min() > 0
    pairs = at.pairs
    close = np.argmin(pairs.gap)
    i, j = pairs.i[close:close + 1], pairs.j[close:close + 1]
    assert {int(i[0]), int(j[0])} == {0, 1} and pairs.gap[close] == pytest.approx(0.02, abs=1e-12)
    e = pairs.dx[close:close + 1] / np.linalg.norm(pairs.dx[close])
    f = np.zeros(6 * n)
    f[6 * j[0]:6 * j[0] + 3], f[6 * i[0]:6 * i[0] + 3] = e[0], -e[0]
    assert at.relative_mobility(i, j, e)[0] == pytest.approx(f @ mobility @ f, rel=EXACT)
    terms = at.brownian(np.random.default_rng(3), 1.0, 1e-3)
    assert terms.velocities.shape == (n, 6) and terms.stresslets.shape == (n, 5)
    assert np.all(np.isfinite(terms.velocities)) and np.all(np.isfinite(terms.stresslets))
    assert set(at.stats()) == {"solver_iterations", "solver_residual", "lanczos_iterations"}
    stress = at.stresslets(np.zeros((n, 6)), np.tile([0.3, -0.2, 0.5, 0.1, -0.4], (n, 1)))
    assert stress.shape == (n, 5) and np.abs(stress).max() > 0
