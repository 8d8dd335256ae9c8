"""The ensemble runner: tasks, rank assignment, the HDF5 run file, checkpoints, MPI driver.

Modules (import the ones you need; only ``runner`` initialises MPI):

``farm``      LPT assignment of tasks to rank groups; communicator split;
``store``     the run file (layout: docs/store.md): create, write, read_summary;
``writers``   the Writer interface of the run file's outputs (registry: sdmpi.registry.WRITERS);
``samples``   the sample stream's writer; ``trajectory`` the H5MD trajectories' writer;
``extension`` lengthening a run (``--extend``); ``start_file`` starts from a run file;
``h5``        HDF5 primitives: early-allocated datasets, lock-free reads;
``runner``    ``run(...)``, the MPI driver behind ``sdmpi run``;
``progress``  aggregate progress on rank 0, per-rank logs;
``faults``    fault injection for the crash tests.

Knows nothing of physics beyond one realisation's interface (``sdmpi.dynamics``).
"""
