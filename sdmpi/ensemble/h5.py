"""HDF5 primitives of the run file that do not depend on its layout.

* :func:`parallel_hdf5`: whether h5py is built with MPI (the ``mpio`` driver);
* :func:`new_dataset`: a dataset whose storage is allocated when it is created, so that
  writing its values later changes no HDF5 metadata (parallel HDF5 always allocates
  early; serial HDF5 would otherwise allocate, and change metadata, on the first write);
* :func:`open_read`: a read-only handle that ignores HDF5's file lock, to read a file
  that a running job holds open for writing.
"""

from __future__ import annotations

import h5py


def parallel_hdf5() -> bool:
    """Whether this h5py is built with MPI (parallel HDF5, the ``mpio`` driver)."""
    return bool(h5py.get_config().mpi)


def new_dataset(group: h5py.Group, name: str, shape=None, dtype=None, *, data=None,
                fillvalue=None) -> h5py.Dataset:
    """``group.create_dataset`` with contiguous storage allocated at creation
    (``H5D_ALLOC_TIME_EARLY``; a ``fillvalue`` is written into it then) and no
    modification times."""
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
    return group.create_dataset(name, shape, dtype, data=data, fillvalue=fillvalue,
                                track_times=False, dcpl=dcpl)


def open_read(path) -> h5py.File:
    """``path`` opened read-only without taking HDF5's file lock (a running serial job
    holds it); h5py or HDF5 versions without that option open it plainly."""
    try:
        return h5py.File(path, "r", locking=False)
    except TypeError:
        return h5py.File(path, "r")
