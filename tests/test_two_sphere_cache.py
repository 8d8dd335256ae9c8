"""The disk cache of the two-sphere series tables returns exactly what the recurrences give."""

import numpy as np

from sdmpi.hydro import two_sphere


def test_cache_round_trip_is_exact(tmp_path, monkeypatch):
    monkeypatch.setenv("SDMPI_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(two_sphere, "_TABLES", None)
    first = two_sphere._lambda_polynomials(24)  # computed, then stored
    assert two_sphere._cache_file(24).exists()
    monkeypatch.setattr(two_sphere, "_TABLES", None)
    again = two_sphere._lambda_polynomials(24)  # read back
    fresh = two_sphere._compute_polynomials(24)
    assert set(first) == set(again) == set(fresh)
    for name in fresh:
        assert np.array_equal(again[name], fresh[name]) and np.array_equal(first[name], fresh[name])


def test_unreadable_cache_is_recomputed(tmp_path, monkeypatch):
    monkeypatch.setenv("SDMPI_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(two_sphere, "_TABLES", None)
    path = two_sphere._cache_file(24)
    path.write_bytes(b"not an npz file")
    tables = two_sphere._lambda_polynomials(24)
    assert np.array_equal(tables["XA"], two_sphere._compute_polynomials(24)["XA"])
