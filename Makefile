# Entry points for a fresh machine; each target sets up what is missing first.
VENV ?= .venv
PY := $(VENV)/bin/python
MPIRUN := OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 mpirun -n 2

.PHONY: setup demo test test-fast verify bench clean

setup:
	@bash scripts/bootstrap.sh

demo: setup
	$(VENV)/bin/fabricfem demo

test: setup
	OMP_NUM_THREADS=1 $(PY) -m pytest -q -n 2 --durations=15 tests
	OMP_NUM_THREADS=1 $(MPIRUN) $(PY) -m pytest -q -p no:cacheprovider -m mpi tests

# the fast tier (tests not marked slow, tests/tiers.txt): under 2 minutes on the 2-core machine
test-fast: setup
	OMP_NUM_THREADS=1 $(PY) -m pytest -q -n 2 -m "not slow" tests

verify: setup
	$(VENV)/bin/fabricfem verify

bench: setup
	$(VENV)/bin/fabricfem bench

clean:
	rm -rf results .pytest_cache
