# fenicsmpm: `make test` and `make demo` do all the set-up on a fresh Debian 12 machine.
SHELL := /bin/bash
SYS_PYTHON := /usr/bin/python3
VENV := .venv
PY := $(VENV)/bin/python
DEBS := python3-dolfinx python3-petsc4py python3-mpi4py python3-meshio python3-h5py python3-numba \
        python3-scipy python3-matplotlib python3-pytest python3-setuptools python3-wheel python3-venv \
        mpi-default-bin python3-sphinx python3-myst-parser python3-sphinx-rtd-theme python3-gmsh \
        libopenblas0-serial
# libopenblas0-serial: an optimised single-threaded BLAS/LAPACK in place of Debian's reference
# libblas3 (update-alternatives), for MUMPS, the default LU from 4,000 dofs: a quasi-static
# cpGIMP step of bench throughput's block took 1.37 s with it, 4.10 s on the reference BLAS;
# the serial build adds no threads to numba's or MPI's (docs/guide/integrators.md).
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
MPI_ROOT := $(shell [ "$$(id -u)" = 0 ] && echo --allow-run-as-root)
NP ?= 2
MPIRUN := mpirun $(MPI_ROOT) -n $(NP)
export OMPI_MCA_rmaps_base_oversubscribe = 1
export OMPI_MCA_btl_vader_single_copy_mechanism = none
# One numba cache for every pass, so each kernel compiles once per checkout (compiling is most
# of a cold run's time). The serial pass's second pytest-xdist worker uses a copy of it
# (tests/conftest.py: numba's cache index is not safe against two processes adding different
# signatures of one function at once; the two MPI ranks add the same ones).
export NUMBA_CACHE_DIR = $(CURDIR)/.numba-cache

.PHONY: all deps deps-optional venv test test-serial test-mpi test-partitions docs demo bench clean

all: test

# Debian packages: install only the missing ones.
deps:
	@missing=""; for p in $(DEBS); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "[make] installing Debian packages:$$missing"; \
	  $(SUDO) apt-get update -qq && \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; \
	fi

# Optional: pytest-xdist runs the serial pass on two worker processes (one per core). If it
# cannot be installed the serial pass runs in one process, as before.
deps-optional: deps
	@dpkg-query -W -f='$${Status}' python3-pytest-xdist 2>/dev/null | grep -q "install ok installed" || \
	  { echo "[make] installing python3-pytest-xdist (optional)"; \
	    { $(SUDO) apt-get update -qq && \
	      $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-pytest-xdist; } || \
	    echo "[make] python3-pytest-xdist not available: the serial pass runs in one process"; }

# The serial pass on 2 workers, each test file on one worker (module fixtures run once);
# empty without pytest-xdist. Expanded when the recipe runs, after deps-optional.
XDIST = $(shell $(PY) -c "import xdist" 2>/dev/null && echo "-n $(NP) --dist loadfile")

# Virtual environment that sees the Debian packages, with fenicsmpm installed editable.
$(VENV)/.installed: pyproject.toml | deps
	@test -x $(PY) || $(SYS_PYTHON) -m venv --system-site-packages $(VENV)
	$(PY) -m pip install -q --no-build-isolation --no-deps -e .
	@touch $@

venv: $(VENV)/.installed

# The 2-rank pass first: its ranks compile the kernels once, at the same time; the serial pass
# then starts warm (its second worker from a copy of the cache).
# The serial pass of `make test` leaves out the tests marked heavy (long physics runs, listed
# in pyproject.toml's markers): the 2-rank pass before it has run them with the same
# assertions. `make test-serial` runs every test serially.
test: $(VENV)/.installed deps-optional
	timeout 1800 $(MPIRUN) $(PY) -m pytest -q --color=no tests
	$(MAKE) --no-print-directory test-serial SERIAL_MARKS="-m 'not heavy'"
	$(MAKE) --no-print-directory docs

test-serial: $(VENV)/.installed deps-optional
	@if [ -n "$(XDIST)" ] && [ -d .numba-cache ]; then rm -rf .numba-cache-gw1 && cp -r .numba-cache .numba-cache-gw1; fi
	$(PY) -m pytest -q --color=no $(XDIST) $(SERIAL_MARKS) tests

test-mpi: $(VENV)/.installed
	timeout 1800 $(MPIRUN) $(PY) -m pytest -q --color=no tests

# The 2-rank pass on SCOTCH partitions of several seeds (tests/conftest.py): finds the tests
# that pass on one partition of dolfinx's default partitioner and fail on another.
SEEDS ?= 1 2 3
test-partitions: $(VENV)/.installed
	for s in $(SEEDS); do echo "[make] partition seed $$s"; \
	  FENICSMPM_TEST_PARTITION_SEED=$$s timeout 1200 $(MPIRUN) $(PY) -m pytest -q --color=no tests || exit 1; done

# The documentation site (docs/): warnings are errors; HTML in docs/_build/html.
docs: $(VENV)/.installed
	$(PY) -m sphinx -W --keep-going -q -b html docs docs/_build/html
	@echo "[make] docs: open docs/_build/html/index.html"

demo: $(VENV)/.installed
	$(PY) demos/vibrating_bar.py

bench: $(VENV)/.installed
	$(PY) -m fenicsmpm.bench $(CASE)

clean:
	rm -rf $(VENV) results bench-results *.egg-info docs/_build docs/_generated .numba-cache .numba-cache-*
