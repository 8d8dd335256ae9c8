"""`sdmpi` with the test double as the realisation (the ensemble tests run this script,
also under mpirun): python tests/ensemble_run.py run JOB.toml -o RUN.h5 [...]"""

import sys

from sdmpi import cli  # first: sets the thread variables before numpy is imported

from ensemble_double import DoubleRealisation

sys.exit(cli.main(sys.argv[1:], realisation_factory=DoubleRealisation))
