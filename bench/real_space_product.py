"""Benchmark: what bounds the real-space part of a spectral far-field product.

`SpectralFarField.real_space` applies the stored 11 x 11 blocks M_ij of every pair image
(single precision from Ewald tolerance 1e-5 on) as y_i += M_ij x_j, y_j += M_ij^T x_i
(`spectral._pairs_product`). At N = 1000, phi = 0.45, strain 0.3, tolerance 1e-4, one
rank, this times (median of `--repeat`, all variants alternated in one process):

  product   - `_pairs_product`, as the far field runs it
  stream    - reading the blocks alone (a compiled sum over them): the memory-traffic floor
  padded16  - the same product with each block row padded to 16 entries, single-precision
              arithmetic (room for 16-wide vector instructions)
  bsr       - scipy's block-sparse (BSR) products A x + A^T x with the same blocks
  batched K - the blocks applied to K vectors at once, per vector (the loop of
              `_pairs_product` per vector, inside the loop over the blocks)

and writes bench/real_space_product.json.

    python bench/real_space_product.py
"""

import argparse
import datetime
import json
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numba
import numpy as np
import scipy.sparse

from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.spectral import SpectralFarField, _pairs_product

NDOF = 11


@numba.njit(cache=True, fastmath=True)
def stream(blocks):
    """Sum of all block entries: one pass over the blocks' memory."""
    flat = blocks.ravel()
    acc = np.float32(0.0)
    for k in range(flat.shape[0]):
        acc += flat[k]
    return acc


@numba.njit(cache=True, fastmath=True)
def padded_product(pi, pj, blocks, x, y):
    """`_pairs_product` with blocks (P, 11, 16) and x (N, 16) padded, single-precision sums."""
    yi, yj = np.zeros(16, np.float32), np.zeros(16, np.float32)
    for p in range(pi.shape[0]):
        b, xi, xj = blocks[p], x[pi[p]], x[pj[p]]
        yj[:] = 0.0
        for a in range(NDOF):
            acc = np.float32(0.0)
            for c in range(16):
                acc += b[a, c] * xj[c]
                yj[c] += b[a, c] * xi[a]
            yi[a] = acc
        for a in range(NDOF):
            y[NDOF * pi[p] + a] += yi[a]
            y[NDOF * pj[p] + a] += yj[a]


@numba.njit(cache=True, fastmath=True)
def batched_product(pi, pj, blocks, x, y):
    """`_pairs_product` for x, y of shape (K, 11N): each block read once for the K vectors."""
    xi, xj = np.empty(NDOF), np.empty(NDOF)
    yi, yj = np.empty(NDOF), np.empty(NDOF)
    for p in range(pi.shape[0]):
        i0, j0 = NDOF * pi[p], NDOF * pj[p]
        b = blocks[p]
        for m in range(x.shape[0]):
            xm, ym = x[m], y[m]
            for a in range(NDOF):
                xi[a], xj[a], yj[a] = xm[i0 + a], xm[j0 + a], 0.0
            for a in range(NDOF):
                acc, xa = 0.0, xi[a]
                for c in range(NDOF):
                    acc += b[a, c] * xj[c]
                    yj[c] += b[a, c] * xa
                yi[a] = acc
            for a in range(NDOF):
                ym[i0 + a] += yi[a]
                ym[j0 + a] += yj[a]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=21)
    ap.add_argument("--out", default="bench/real_space_product.json")
    args = ap.parse_args()
    n = args.n
    rng = np.random.default_rng(1)
    pos, side = hard_sphere_fluid(n, 0.45, rng, sweeps=100)
    far = SpectralFarField(pos, np.ones(n), Lattice(np.full(3, side), 0.3), tol=1e-4)
    pi, pj, blocks = far._pi, far._pj, far._blocks
    x = rng.standard_normal(NDOF * n)
    reference = np.zeros_like(x)
    _pairs_product(pi, pj, blocks, x, reference)

    padded = np.zeros((len(pi), NDOF, 16), np.float32)
    padded[:, :, :NDOF] = blocks
    x16 = np.zeros((n, 16), np.float32)
    x16[:, :NDOF] = x.reshape(n, NDOF)
    rows = np.searchsorted(pi, np.arange(n + 1))  # pairs are ordered by their first particle
    upper = scipy.sparse.bsr_matrix((blocks, pj, rows), shape=(NDOF * n, NDOF * n))
    lower = upper.T.tobsr(blocksize=(NDOF, NDOF))
    x32 = x.astype(np.float32)
    many = {k: rng.standard_normal((k, NDOF * n)) for k in (4, 8)}

    def run_product():
        y = np.zeros_like(x)
        _pairs_product(pi, pj, blocks, x, y)
        return y

    def run_padded():
        y = np.zeros_like(x)
        padded_product(pi, pj, padded, x16, y)
        return y

    variants = {"product": run_product, "stream": lambda: stream(blocks), "padded16": run_padded,
                "bsr": lambda: upper @ x32 + lower @ x32}
    for k, xs in many.items():
        variants[f"batched {k}"] = lambda xs=xs: batched_product(pi, pj, blocks, xs, np.zeros_like(xs))
    errors = {"padded16": run_padded(), "bsr": variants["bsr"]()}
    errors = {k: float(np.abs(v - reference).max() / np.abs(reference).max()) for k, v in errors.items()}
    times = {k: [] for k in variants}
    for fn in variants.values():
        fn()  # compile
    for _ in range(args.repeat):
        for name, fn in variants.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    ms = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
    for k in many:
        ms[f"batched {k}"] /= k
    result = {"date": datetime.date.today().isoformat(), "n": n, "pair_images": int(len(pi)),
              "blocks_mb": blocks.nbytes / 1e6, "ms": ms, "ns_per_pair_image": 1e6 * ms["product"] / len(pi),
              "max_relative_difference": errors}
    for k, v in ms.items():
        print(f"{k:12s} {v:6.2f} ms{' per vector' if k.startswith('batched') else ''}")
    with open(args.out, "w") as f:
        json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
