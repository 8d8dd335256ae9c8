"""`sdmpi` with the test double as the realisation (the ensemble tests run this script,
also under mpirun): python tests/ensemble_run.py [--serial-h5py] [--stack NAME=VERSION]
run JOB.toml -o RUN.h5 [...]

--serial-h5py: h5py's MPI support reported missing (`store.parallel_hdf5` False), as
with an h5py built without MPI.
--stack NAME=VERSION: the library stack reported with NAME's version replaced, as on
another install (`runner.versions`)."""

import sys

from sdmpi import cli  # first: sets the thread variables before numpy is imported

from ensemble_double import DoubleRealisation  # this script's directory is on sys.path

args = sys.argv[1:]
if args[:1] == ["--serial-h5py"]:
    from sdmpi.ensemble import store

    args = args[1:]
    store.parallel_hdf5 = lambda: False
if args[:1] == ["--stack"]:
    from sdmpi.ensemble import runner

    name, _, version = args[1].partition("=")
    args, real = args[2:], runner.versions
    runner.versions = lambda: {**real(), name: version}
sys.exit(cli.main(args, realisation_factory=DoubleRealisation))
