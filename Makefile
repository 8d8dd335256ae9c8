# sdmpi: `make run` (demonstration, end to end) and `make test` (the suite).
# Both bootstrap a fresh Debian 12 machine: Debian packages (idempotent), a
# virtualenv that sees them (--system-site-packages), sdmpi installed editable without
# its dependencies (Debian provides them; pip does not recognise Debian's parallel h5py
# and would install a serial one over it), and the test tools of the `test` extra.

PY        := /usr/bin/python3
VENV      := .venv
VPY       := $(VENV)/bin/python
DEB_PKGS  := openmpi-bin python3-mpi4py python3-h5py-mpi python3-petsc4py \
             python3-numba python3-scipy python3-matplotlib python3-venv python3-pip
export PETSC_DIR ?= /usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
export NUMBA_CACHE_DIR := $(CURDIR)/.numba_cache

.PHONY: setup run test pip-check bench schaink2000 finite-size finite-size-n343 large-n-1000 dratler1996 dratler1996-sensitivity dratler1996-size clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	@missing=""; for p in $(DEB_PKGS); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing; \
	fi
	$(PY) -m venv --system-site-packages $(VENV)
	$(VPY) -m pip install -q --no-deps -e .
	$(VPY) -c "import tomllib; print('\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['optional-dependencies']['test']))" \
	  | xargs -d '\n' $(VPY) -m pip install -q
	# pyh5md (the H5MD reference reader, tests/test_trajectory.py) without its h5py
	# dependency, which would shadow Debian's parallel h5py in the virtualenv
	$(VPY) -m pip install -q --no-deps pyh5md
	touch $@

run: setup
	mkdir -p out
	mpirun --oversubscribe -n 2 $(VENV)/bin/sdmpi run jobs/demo.toml -o out/demo.h5
	$(VENV)/bin/sdmpi info out/demo.h5
	$(VENV)/bin/sdmpi reduce out/demo.h5 -o out/demo

test: setup
	$(VPY) -m pytest -q tests
	$(MAKE) pip-check

# The pip install path (docs/hpc.md): a virtualenv without system packages, sdmpi and its
# dependencies from PyPI wheels (serial h5py), then SIGKILLs at random instants on one
# and two ranks (tests/durability_check.py).
PIP_VENV  := .venv-pip
pip-check: $(PIP_VENV)/.installed
	$(PIP_VENV)/bin/pip install -q --no-deps --force-reinstall .
	cd $(PIP_VENV) && NUMBA_CACHE_DIR=$(CURDIR)/.numba_cache_pip \
	  bin/python $(CURDIR)/tests/durability_check.py

$(PIP_VENV)/.installed: pyproject.toml
	$(PY) -m venv $(PIP_VENV)
	$(PIP_VENV)/bin/pip install -q --upgrade pip
	$(PIP_VENV)/bin/pip install -q .
	touch $@

bench: setup
	$(VPY) bench/bench_hydro.py --out bench/results.json
	$(VPY) bench/bench_ensemble.py
	$(VPY) bench/bench_step.py --out bench/step.json

# The Schaink et al. (2000) study (docs/validation/schaink2000/README.md): its three jobs on RANKS
# ranks into out/schaink2000/, then its tables, figures and comparison into STUDY_OUT. A
# stopped study resumes where it stopped when this is run again.
RANKS     ?= 2
STUDY_OUT ?= docs/validation/schaink2000
schaink2000: setup
	mkdir -p out/schaink2000
	for job in frequency_scan phi_scan fixed_dt; do \
	  mpirun --oversubscribe -n $(RANKS) $(VENV)/bin/sdmpi run jobs/schaink2000_$$job.toml \
	    -o out/schaink2000/$$job.h5 || exit 1; \
	done
	$(VPY) postprocess/schaink2000.py --newtonian out/schaink2000/frequency_scan.h5 \
	  --phi-scan out/schaink2000/phi_scan.h5 --fixed-dt out/schaink2000/fixed_dt.h5 -o $(STUDY_OUT)

# The finite-size study (docs/validation/finite_size/README.md): the time-step control and
# the N = 27, 64, 125 and 343 runs on RANKS ranks into out/finite_size/ (~9 core-hours in
# all, N = 343 more than half of it), then its tables and figures into FS_OUT. A stopped
# study resumes where it stopped when this is run again; finite-size-n343 runs (or
# resumes) N = 343 alone and then the same tables.
FS_OUT    ?= docs/validation/finite_size
FS_RUN     = mpirun --oversubscribe -n $(RANKS) $(VENV)/bin/sdmpi run
FS_TABLES  = $(VPY) postprocess/finite_size.py --runs out/finite_size/n27.h5 out/finite_size/n64.h5 \
	  out/finite_size/n125.h5 out/finite_size/n343.h5 --control out/finite_size/dt_control.h5 -o $(FS_OUT)
finite-size: setup
	mkdir -p out/finite_size
	for job in dt_control n27 n64 n125 n343; do \
	  $(FS_RUN) jobs/finite_size_$$job.toml -o out/finite_size/$$job.h5 || exit 1; \
	done
	$(FS_TABLES)

finite-size-n343: setup
	mkdir -p out/finite_size
	$(FS_RUN) jobs/finite_size_n343.toml -o out/finite_size/n343.h5
	$(FS_TABLES)

# A 5 000-step realisation of jobs/large_n_krylov.toml (N = 1000, phi = 0.45, oscillatory,
# petsc-krylov on 2 ranks, the rfd scheme with its near-contact correction; docs/performance.md
# "A 5 000-step realisation at N = 1000"): the
# cost estimate of `sdmpi validate --time-steps` on the task's 2 ranks (kept from the first
# call), the run into out/large_n/ (run again to resume after a stop), its trust report.
LN_SET = --set ensemble.realisations=1 --set integration.steps_per_period=2500 --set integration.periods=2 \
	 --set 'brownian.scheme="rfd"'
large-n-1000: setup
	mkdir -p out/large_n
	test -s out/large_n/n1000_estimate.txt || { mpirun --oversubscribe -n 2 $(VENV)/bin/sdmpi validate \
	  jobs/large_n_krylov.toml $(LN_SET) --time-steps 10 > out/large_n/n1000_estimate.tmp && \
	  mv out/large_n/n1000_estimate.tmp out/large_n/n1000_estimate.txt; }
	cat out/large_n/n1000_estimate.txt
	mpirun --oversubscribe -n 2 $(VENV)/bin/sdmpi run jobs/large_n_krylov.toml $(LN_SET) \
	  -o out/large_n/n1000.h5
	$(VENV)/bin/sdmpi reduce out/large_n/n1000.h5 -o out/large_n/n1000 --no-plots

# The Dratler & Schowalter (1996) monolayer study (docs/validation/dratler1996/README.md):
# both models at the paper's length on RANKS ranks into out/dratler1996/, then its tables
# into DS_OUT. A stopped study resumes where it stopped when this is run again.
DS_OUT    ?= docs/validation/dratler1996/full
dratler1996: setup
	mkdir -p out/dratler1996
	for model in hydro repulsion; do \
	  mpirun --oversubscribe -n $(RANKS) $(VENV)/bin/sdmpi run jobs/dratler1996_$$model.toml \
	    -o out/dratler1996/$$model.h5 || exit 1; \
	done
	$(VPY) postprocess/dratler1996.py --hydro out/dratler1996/hydro.h5 \
	  --repulsion out/dratler1996/repulsion.h5 -o $(DS_OUT)

# Its sensitivity runs (sec. 4.2 of the paper; jobs/dratler1996_sensitivity.toml): the
# reference and one parameter changed at a time, then sensitivity.csv into DSS_OUT.
DSS_OUT   ?= docs/validation/dratler1996/sensitivity
DSS_JOB    = jobs/dratler1996_sensitivity.toml
DSS_RUN    = mpirun --oversubscribe -n $(RANKS) $(VENV)/bin/sdmpi run $(DSS_JOB)
dratler1996-sensitivity: setup
	mkdir -p out/dratler1996
	$(DSS_RUN) -o out/dratler1996/sens_reference.h5
	$(DSS_RUN) -o out/dratler1996/sens_gstar0.1.h5 --set interparticle.f0=5.0
	$(DSS_RUN) -o out/dratler1996/sens_gstar10.h5 --set interparticle.f0=0.05
	$(DSS_RUN) -o out/dratler1996/sens_tau1.25e4.h5 --set interparticle.tau=12500.0
	$(DSS_RUN) -o out/dratler1996/sens_tau1.25e5.h5 --set interparticle.tau=125000.0
	$(DSS_RUN) -o out/dratler1996/sens_n36.h5 --set system.n_particles=36
	$(VPY) postprocess/dratler1996_sensitivity.py --reference out/dratler1996/sens_reference.h5 \
	  --variant "gamma*=0.1=out/dratler1996/sens_gstar0.1.h5" \
	  "gamma*=10=out/dratler1996/sens_gstar10.h5" \
	  "tau=1.25e4=out/dratler1996/sens_tau1.25e4.h5" \
	  "tau=1.25e5=out/dratler1996/sens_tau1.25e5.h5" \
	  "N=36=out/dratler1996/sens_n36.h5" -o $(DSS_OUT)

# Its overlaps per sphere against N (sec. 4.1; jobs/dratler1996_size.toml, one process each,
# 2 realisations per N, those at N = 49 and 64 as two files with their own job.seed, N = 64
# to strain 30), then size.csv into DSZ_OUT.
DSZ_OUT   ?= docs/validation/dratler1996/size
DSZ_RUN    = $(VENV)/bin/sdmpi run jobs/dratler1996_size.toml
dratler1996-size: setup
	mkdir -p out/dratler1996
	$(DSZ_RUN) -o out/dratler1996/size_n25.h5
	$(DSZ_RUN) -o out/dratler1996/size_n36.h5 --set system.n_particles=36
	for seed in 1998 1999; do \
	  $(DSZ_RUN) -o out/dratler1996/size_n49_$$seed.h5 --set system.n_particles=49 \
	    --set ensemble.realisations=1 --set job.seed=$$seed || exit 1; \
	  $(DSZ_RUN) -o out/dratler1996/size_n64_$$seed.h5 --set system.n_particles=64 \
	    --set ensemble.realisations=1 --set integration.n_steps=6000 --set job.seed=$$seed || exit 1; \
	done
	$(VPY) postprocess/dratler1996_size.py out/dratler1996/size_n25.h5 out/dratler1996/size_n36.h5 \
	  out/dratler1996/size_n49_1998.h5 out/dratler1996/size_n49_1999.h5 \
	  out/dratler1996/size_n64_1998.h5 out/dratler1996/size_n64_1999.h5 -o $(DSZ_OUT)

clean:
	rm -rf $(VENV) $(PIP_VENV) .numba_cache .numba_cache_pip build *.egg-info
