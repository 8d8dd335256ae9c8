"""Synthetic run files for the reducer's tests: the layout of docs/store.md (format 1, as
written by ``sdmpi.ensemble.store.create``), written serially with h5py, with stress
signals of known moduli plus correlated noise instead of SD output.

    write_run(path, job_text, {"hydrodynamic": (g1, g2), "brownian": (g1, g2)}, noise=...)

Oscillatory jobs: contribution c has sigma_xy(t_k) = gamma0 (G'_c sin w t_k + G''_c cos w t_k)
+ offset + noise at t_k = k dt; steady jobs: sigma_xy = eta_c gamma_dot + noise. The noise
is a stationary AR(1) series (unit variance times ``noise``, correlation time ``tau``
samples), independent per task and contribution. Moduli may be given per task by a
callable task -> (G', G'') (or eta).
"""

import json

import h5py
import numpy as np
from scipy.signal import lfilter

from sdmpi.config import canonical_text, enumerate_tasks, job_hash, parse_job, resume_hash

STORED = ("hydrodynamic", "brownian", "interparticle")


def ar1(rng, n, tau):
    """Stationary unit-variance AR(1) series of length n, correlation time tau samples."""
    a = np.exp(-1.0 / tau)
    zi = [a * rng.standard_normal()]
    return lfilter([np.sqrt(1 - a * a)], [1.0, -a], rng.standard_normal(n), zi=zi)[0]


def signal(job, task, value, rng, noise, tau, offset=0.0):
    """xy stress of one contribution of one task (see the module docstring)."""
    t = task.dt * np.arange(task.n_steps)
    if callable(value):
        value = value(task)
    if job.shear.protocol == "oscillatory":
        g1, g2 = value
        w = task.omega
        clean = job.shear.gamma0 * (g1 * np.sin(w * t) + g2 * np.cos(w * t))
    else:
        clean = np.full(task.n_steps, value * (job.shear.rate or 0.0))
    return clean + offset + (noise * ar1(rng, task.n_steps, tau) if noise else 0.0)


def write_run(path, job_text, moduli, *, noise=0.0, tau=5.0, progress=None, seed=0,
              viscous=None, offset=0.0, tasks=None):
    """Write a run file for ``job_text`` (any valid job TOML; stored canonically).

    moduli: contribution ("hydrodynamic", "brownian", "interparticle") -> (G', G'') or
    eta, or a callable task -> that; missing contributions are zero. For Maxwell media
    ``moduli["hydrodynamic"]`` goes to stress_hydrodynamic_maxwell and ``viscous`` (same
    form) to stress_hydrodynamic. progress: None (complete), an int for every task, or
    a dict task_id -> committed samples; uncommitted samples are filled with garbage.
    tasks: optional dict task_id -> {contribution: raw xy series (n_steps,)} that
    replaces the generated signal (to write the same data into several files).
    Returns {task_id: {dataset: xy series}} of what was written."""
    job = parse_job(job_text)
    text = canonical_text(job)
    all_tasks = enumerate_tasks(job)
    rng = np.random.default_rng(seed)
    written = {}
    with h5py.File(path, "w") as f:
        f.attrs.update({
            "format": "sdmpi-run", "format_version": 1, "job_text": text,
            "job_hash": job_hash(job), "resume_hash": resume_hash(job),
            "time_unit": job.time_unit,
            "stress_unit": "eta_m/t_D" if job.time_unit == "t_D" else "eta_m gamma_dot",
            "component_order": "xx yy zz xy xz yz",
            "versions": json.dumps({"sdmpi": "synthetic"}), "created": "2000-08-03T00:00:00Z",
            "n_tasks": len(all_tasks)})
        done_all = np.array([task.n_steps if progress is None else
                             (progress if isinstance(progress, int) else
                              progress.get(task.task_id, task.n_steps))
                             for task in all_tasks], dtype=np.int64)
        f.create_dataset("progress", data=done_all)
        maxwell = job.medium.kind == "maxwell"
        for task, done in zip(all_tasks, done_all):
            key = f"{task.task_id:06d}"
            g = f.create_group(f"tasks/{key}")
            omega = np.nan if task.omega is None else task.omega
            g.attrs.update({"task_id": task.task_id, "phi": task.phi, "omega": omega,
                            "realisation": task.realisation, "dt": task.dt,
                            "n_steps": task.n_steps, "discard_steps": task.discard_steps,
                            "n_particles": job.system.n_particles, "box": np.full(3, 10.0),
                            "gamma0": job.shear.gamma0 or np.nan})
            s = g.create_group("samples")
            t = task.dt * np.arange(task.n_steps)
            s["time"] = t
            if task.omega is not None:
                s["strain"] = job.shear.gamma0 * np.sin(task.omega * t)
                s["rate"] = job.shear.gamma0 * task.omega * np.cos(task.omega * t)
            else:
                rate = job.shear.rate or 0.0           # None: quiescent
                s["strain"] = rate * t
                s["rate"] = np.full(task.n_steps, rate)
            series = {}
            for c in STORED:
                name = "stress_" + c + ("_maxwell" if maxwell and c == "hydrodynamic" else "")
                series[name] = signal(job, task, moduli.get(c, (0.0, 0.0) if task.omega
                                      is not None else 0.0), rng, noise, tau, offset)
            if maxwell:
                series["stress_hydrodynamic"] = signal(
                    job, task, viscous if viscous is not None else (0.0, 0.0), rng, 0.0, tau)
            if tasks is not None and task.task_id in tasks:
                series.update(tasks[task.task_id])
            written[task.task_id] = series
            for name, xy in series.items():
                full = 1e-3 * rng.standard_normal((task.n_steps, 6))
                full[:, 3] = xy
                full[done:] = 1e30          # never committed: must not be read
                s[name] = full
            s["n_overlaps"] = np.zeros(task.n_steps, dtype=np.int32)
            s["min_gap"] = np.full(task.n_steps, 0.01)
            ck = f.create_group(f"checkpoints/{key}")
            ck["slot_step"] = np.array([done if done > 0 else -1, -1], dtype=np.int64)
            for slot in (0, 1):
                ck.create_group(f"slot{slot}")["positions"] = np.zeros((job.system.n_particles, 3))
    return written
