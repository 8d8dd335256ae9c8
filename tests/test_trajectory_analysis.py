"""g(r) and mean-squared displacements from H5MD trajectories (sdmpi.analysis.trajectories
and postprocess/trajectory_analysis.py) on synthetic data with known answers: lattice
coordination shells, an ideal gas, Brownian walks under Lees-Edwards oscillatory and steady
shear."""

import math
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from sdmpi.analysis.trajectories import (mean_squared_displacement, pair_distribution, read,
                                         self_diffusion, unwrap)
from sdmpi.hydro.geometry import Lattice

ROOT = Path(__file__).resolve().parents[1]


def write_h5md(path, positions, box, strain, dt=1.0, group="walk"):
    """A minimal H5MD file: positions (F, N, 3), Lees-Edwards cells of box at each strain."""
    frames = len(positions)
    with h5py.File(path, "w") as f:
        h5md = f.create_group("h5md")
        h5md.attrs["version"] = np.array([1, 1])
        h5md.create_group("author").attrs["name"] = "test"
        h5md.create_group("creator").attrs.update({"name": "test", "version": "1"})
        g = f.create_group(f"particles/{group}")
        box_group = g.create_group("box")
        box_group.attrs.update({"dimension": 3, "boundary": np.array([b"periodic"] * 3)})
        step = np.arange(frames)
        for name, value in [("box/edges", [Lattice(box, s).vectors for s in strain]),
                            ("position", positions)]:
            e = g.create_group(name)
            e["step"], e["time"], e["value"] = step, step * dt, np.asarray(value)
        e = f.create_group(f"observables/{group}/strain")
        e["step"], e["time"], e["value"] = step, step * dt, np.asarray(strain, dtype=float)
    return path


def cubic_lattice(m, d):
    grid = (np.arange(m) + 0.5) * d
    return np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), -1).reshape(-1, 3)


def coordination(r, g, rho, lo, hi):
    """rho int_lo^hi g 4 pi r^2 dr over whole bins (the shells' own volumes); with
    g normalised by the N (N - 1) / 2 pairs, rho = (N - 1) / V, the other particles'."""
    width = r[1] - r[0]
    inside = (r > lo) & (r < hi)
    shells = 4 * math.pi / 3 * ((r + width / 2) ** 3 - (r - width / 2) ** 3)
    return rho * float(np.sum(g[inside] * shells[inside]))


def test_simple_cubic_lattice_has_its_coordination_shells(tmp_path):
    m, d = 4, 2.5
    x = cubic_lattice(m, d)
    box = np.full(3, m * d)
    path = write_h5md(tmp_path / "sc.h5", x[None], box, [0.0])
    r, g = pair_distribution(read(path), r_max=5.0, bins=200)
    rho = (len(x) - 1) / box.prod()
    # 6 neighbours at d, 12 at sqrt2 d, 8 at sqrt3 d, none below d
    assert coordination(r, g, rho, 0, 0.99 * d) == 0
    for shell, neighbours in [(1.0, 6), (math.sqrt(2), 12), (math.sqrt(3), 8)]:
        assert coordination(r, g, rho, 0.99 * shell * d, 1.01 * shell * d) == \
            pytest.approx(neighbours, rel=1e-12)


def test_a_sheared_lattice_in_its_lees_edwards_cell(tmp_path):
    """The lattice with vectors (d, 0, 0), (gamma d, d, 0), (0, 0, d), wrapped into the
    Lees-Edwards cell at strain gamma: 4 neighbours at d (x and z) and 2 at d sqrt(1 +
    gamma^2) (along the sheared y vector), the next at d sqrt(1 + (1 - gamma)^2)."""
    m, d, gamma = 4, 2.5, 0.2
    x = cubic_lattice(m, d)
    x[:, 0] += gamma * x[:, 1]
    box = np.full(3, m * d)
    x = Lattice(box, gamma).wrap(x)
    path = write_h5md(tmp_path / "shear.h5", x[None], box, [gamma])
    r, g = pair_distribution(read(path), r_max=4.8, bins=480)  # half the face distance: 4.90
    rho = (len(x) - 1) / box.prod()
    assert coordination(r, g, rho, 0.99 * d, 1.01 * d) == pytest.approx(4, rel=1e-12)
    tilted = d * math.sqrt(1 + gamma ** 2)
    assert coordination(r, g, rho, 1.01 * d, 1.01 * tilted) == pytest.approx(2, rel=1e-12)
    assert coordination(r, g, rho, 1.01 * tilted, 0.99 * d * math.sqrt(1 + (1 - gamma) ** 2)) == 0


def test_ideal_gas_has_g_one(tmp_path):
    rng = np.random.default_rng(3)
    frames, n, side = 200, 100, 10.0
    x = rng.uniform(0, side, (frames, n, 3))
    strain = np.full(frames, 0.3)
    x = np.stack([Lattice(np.full(3, side), 0.3).wrap(f) for f in x])
    path = write_h5md(tmp_path / "gas.h5", x, np.full(3, side), strain)
    r, g = pair_distribution(read(path), r_max=4.5, bins=9)
    # Poisson counts: the relative error of a bin is 1/sqrt(count); all within 4 sigma
    pairs = frames * n * (n - 1) / 2
    shells = 4 * math.pi / 3 * np.diff(np.linspace(0, 4.5, 10) ** 3)
    sigma = 1 / np.sqrt(pairs * shells / side ** 3)
    assert np.all(np.abs(g - 1) < 4 * sigma), (g, sigma)


def brownian_walk(rng, frames, n, side, dt, diffusion, strain_of):
    """Unbounded walks under the affine flow (dx = dgamma y), wrapped at each strain."""
    u = np.empty((frames, n, 3))
    u[0] = rng.uniform(0, side, (n, 3))
    strain = np.array([strain_of(k * dt) for k in range(frames)])
    for k in range(frames - 1):
        u[k + 1] = u[k] + math.sqrt(2 * diffusion * dt) * rng.standard_normal((n, 3))
        u[k + 1, :, 0] += (strain[k + 1] - strain[k]) * u[k, :, 1]
    wrapped = np.stack([Lattice(np.full(3, side), s).wrap(x) for x, s in zip(u, strain)])
    return u, wrapped, strain


def test_unwrapping_recovers_the_walk_under_steady_shear(tmp_path):
    """Strains up to 4 (the cell is reduced to |gamma| <= 1/2 eight times over)."""
    rng = np.random.default_rng(5)
    u, x, strain = brownian_walk(rng, 400, 50, 6.0, 0.01, 1.0, lambda t: 1.0 * t)
    path = write_h5md(tmp_path / "steady.h5", x, np.full(3, 6.0), strain, dt=0.01)
    traj = read(path)
    np.testing.assert_allclose(unwrap(traj), u - u[0] + x[0], rtol=0, atol=1e-9)


def test_msd_of_a_brownian_walk_under_oscillatory_shear(tmp_path):
    rng = np.random.default_rng(11)
    frames, n, dt, diffusion, gamma0, omega = 300, 200, 0.01, 0.7, 0.5, 2 * math.pi
    u, x, strain = brownian_walk(rng, frames, n, 6.0, dt, diffusion,
                                 lambda t: gamma0 * math.sin(omega * t))
    path = write_h5md(tmp_path / "osc.h5", x, np.full(3, 6.0), strain, dt=dt)
    lags, t, msd = mean_squared_displacement(read(path), max_lag=10)
    np.testing.assert_allclose(t, lags * dt)
    # y, z: 2 D t; x (convected): 2 D dt sum (1 + gamma_{k+1}^2) over each window
    samples = n * (frames - lags)
    sigma = np.sqrt(2 / samples) * np.sqrt(lags)  # relative; overlapping origins ~ sqrt(lag)
    for c in (1, 2):
        assert np.all(np.abs(msd[:, c] / (2 * diffusion * t) - 1) < 5 * sigma)
    per_step = 1 + strain[1:] ** 2
    expected_x = np.array([2 * diffusion * dt * np.mean(
        [per_step[k:k + lag].sum() for k in range(frames - lag)]) for lag in lags])
    assert np.all(np.abs(msd[:, 0] / expected_x - 1) < 5 * sigma)
    assert np.all(np.abs(self_diffusion(t, msd) / diffusion - 1) < 5 * sigma)


def test_the_script_reads_a_run_file_and_writes_tables(tmp_path):
    rng = np.random.default_rng(2)
    _, x, strain = brownian_walk(rng, 50, 64, 8.0, 0.01, 1.0, lambda t: 0.0)
    path = write_h5md(tmp_path / "w.h5", x, np.full(3, 8.0), strain, dt=0.01)
    res = subprocess.run([sys.executable, str(ROOT / "postprocess" / "trajectory_analysis.py"),
                          str(path), "-o", str(tmp_path / "out"), "--r-max", "4",
                          "--max-lag", "5"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    rows = (tmp_path / "out" / "msd.csv").read_text().splitlines()
    assert rows[0].startswith("lag_frames,lag_time,msd_x,msd_y,msd_z,D_yz") and len(rows) == 6
    assert len((tmp_path / "out" / "gr.csv").read_text().splitlines()) == 101
    assert (tmp_path / "out" / "gr.png").exists() and (tmp_path / "out" / "msd.png").exists()
    bad = subprocess.run([sys.executable, str(ROOT / "postprocess" / "trajectory_analysis.py"),
                          str(path), "-o", str(tmp_path / "o2"), "--r-max", "40"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "r_max = 40 exceeds half the smallest cell width" in bad.stderr
    assert "Traceback" not in bad.stderr


def test_largest_r_is_that_of_the_most_sheared_frame(tmp_path):
    """A cube of side 10 sheared by 0.3 has its x faces 10 / sqrt(1 + 0.3^2) apart."""
    x = cubic_lattice(2, 5.0)
    path = write_h5md(tmp_path / "two.h5", np.stack([x, x]), np.full(3, 10.0), [0.0, 0.3])
    traj = read(path)
    assert traj.largest_r() == pytest.approx(5.0 / math.sqrt(1 + 0.3 ** 2), rel=1e-12)
    with pytest.raises(ValueError, match="exceeds half the smallest cell width"):
        pair_distribution(traj, r_max=4.9)
