"""HDF5 primitives of the run file that do not depend on its layout.

* :func:`parallel_hdf5`: whether h5py is built with MPI (the ``mpio`` driver);
* :func:`new_dataset`: a dataset whose storage is allocated when it is created, so that
  writing its values later changes no HDF5 metadata (parallel HDF5 always allocates
  early; serial HDF5 would otherwise allocate, and change metadata, on the first write);
* :func:`open_read`: a read-only handle that ignores HDF5's file lock, to read a file
  that a running job holds open for writing.
"""

from __future__ import annotations

import os

import h5py
import numpy as np


def parallel_hdf5() -> bool:
    """Whether this h5py is built with MPI (parallel HDF5, the ``mpio`` driver).

    Returns:
        True when the ``mpio`` driver is available.
    """
    return bool(h5py.get_config().mpi)


def new_dataset(group: h5py.Group, name: str, shape: tuple[int, ...] | None = None,
                dtype: np.dtype | str | None = None, *, data: np.ndarray | None = None,
                fillvalue: float | int | None = None) -> h5py.Dataset:
    """``group.create_dataset`` with contiguous storage allocated at creation
    (``H5D_ALLOC_TIME_EARLY``; a ``fillvalue`` is written into it then) and no
    modification times.

    Args:
        group: the group (or file) to create it in.
        name: the dataset's name, relative to group.
        shape: its shape, or None to take data's.
        dtype: its dtype, or None to take data's.
        data: initial values, or None.
        fillvalue: the value of unwritten elements, or None for HDF5's default (0).

    Returns:
        The new dataset.
    """
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
    return group.create_dataset(name, shape, dtype, data=data, fillvalue=fillvalue,
                                track_times=False, dcpl=dcpl)


def open_read(path: str | os.PathLike) -> h5py.File:
    """``path`` opened read-only without taking HDF5's file lock (a running serial job
    holds it); h5py or HDF5 versions without that option open it plainly.

    Args:
        path: the HDF5 file.

    Returns:
        The open file (the caller closes it).
    """
    try:
        return h5py.File(path, "r", locking=False)
    except TypeError:
        return h5py.File(path, "r")
