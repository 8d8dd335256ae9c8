"""Interparticle forces: the seed-001 repulsion (force = -dU/dh, limits, Newton's third
law, virial)."""

import math

import numpy as np
import pytest

from sdmpi.config import JobError, enumerate_tasks, load_job
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.forces import Repulsion, pair_forces
from sdmpi.hydro.lubrication import close_pairs


def test_repulsion_is_minus_gradient_of_potential_with_limits():
    law = Repulsion(f0=2.0, tau=50.0)
    h = np.linspace(1e-4, 0.3, 50)
    dh = 1e-7
    numeric = -(law.potential(h + dh) - law.potential(h - dh)) / (2 * dh)
    assert np.allclose(law.magnitude(h), numeric, rtol=1e-6)
    assert law.magnitude(np.array([0.0]))[0] == pytest.approx(2.0 * 50.0 / 2)
    far = np.array([0.5])
    assert law.magnitude(far)[0] == pytest.approx(2.0 * 50 * math.exp(-25), rel=1e-10)


def test_pair_forces_obey_newtons_third_law_and_virial():
    pos = np.array([[0.0, 0, 0], [2.01, 0.1, 0], [1.0, 1.8, 0.2]])
    radii = np.ones(3)
    pairs = close_pairs(pos, radii)
    forces, virial = pair_forces(Repulsion(1.0, 20.0), pairs, 3)
    assert np.allclose(forces.sum(axis=0), 0, atol=1e-12)
    assert np.allclose(virial, np.einsum("ni,nj->ij", pos, forces), atol=1e-12)
    # repulsion: particle 1 is pushed away from 0 along +x mostly
    assert forces[1, 0] > 0 and forces[0, 0] < 0


def test_repulsion_keys_validated_and_used():
    with pytest.raises(JobError, match="interparticle.f0"):
        load_job("jobs/demo.toml", overrides=["interparticle.kind='repulsion'"])
    job = load_job("jobs/demo.toml", overrides=["interparticle.kind='repulsion'", "interparticle.f0=1.0",
                                                "interparticle.tau=300.0", "integration.periods=1", "integration.discard_periods=0",
                                                "integration.steps_per_period=8"])
    real = Realisation(job, enumerate_tasks(job)[0])
    out = real.advance(4)
    assert np.any(out["stress_interparticle"] != 0)
