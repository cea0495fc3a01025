"""Shared fixtures for the fenicsmpm test suite (serial and `mpirun -n 2`).

Every test runs the same code path on every rank: global quantities are reduced first
(`Particles.total`, `Probe.data()`, `comm.allreduce`) and only then asserted, so a failing
assertion fails on all ranks together and never leaves a rank waiting in a collective."""
import os
import shutil
import tempfile

# Under pytest-xdist (`make test`'s serial pass) the second worker compiles into its own
# numba cache: numba's cache index is not safe against two processes adding different
# signatures of one function at once. Set before numba is first imported.
_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
if _WORKER != "gw0":
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__))), f".numba-cache-{_WORKER}")
# An xdist worker inherits the variables of the controller's singleton MPI start (PMIX_*,
# OMPI_MCA_ess, ...): drop them before mpi4py starts MPI here, so the worker is a clean
# singleton and an mpirun a test launches does not take them for an enclosing launch.
if "PYTEST_XDIST_WORKER" in os.environ:
    # k workers on this machine share its cores as k MPI ranks do (kernels.threads.
    # default_threads): numba's threads are set below, BLAS/OpenMP's here (before numpy
    # starts them). Measured 2026-12-05 on 2 cores: test_fbar.py's quick bearing-capacity
    # case took 118 s with 2 workers x 2 threads, 40 s alone on 1 thread, 48 s alone on 2.
    _SHARE = max(1, (os.cpu_count() or 1) // int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(_k, str(_SHARE))
    for _k in list(os.environ):
        if (_k.startswith(("PMIX_", "ORTE_")) or _k.startswith("OMPI_") and not _k.startswith("OMPI_MCA_")
                or _k.startswith(("OMPI_MCA_orte_", "OMPI_MCA_ess", "OMPI_MCA_pmix"))):
            del os.environ[_k]

import numpy as np  # noqa: E402
import pytest
from mpi4py import MPI

if "PYTEST_XDIST_WORKER" in os.environ and "NUMBA_NUM_THREADS" not in os.environ:
    import numba
    numba.set_num_threads(_SHARE)     # the cap stays every core: tests may ask for 2


def _seeded_partitions(seed):
    """Meshes made without an explicit partitioner get SCOTCH with this seed instead of
    dolfinx's default (FENICSMPM_TEST_PARTITION_SEED, `make test-partitions`): dolfinx's
    default partition varies from run to run, so a test that passes on one partition of a
    2-rank run may fail on another; sweeping seeds finds those tests."""
    import functools
    import dolfinx.graph
    import dolfinx.mesh as dmesh
    # the positional index of `partitioner` in each constructor (dolfinx 0.5.2)
    where = {"create_rectangle": 5, "create_box": 5, "create_unit_square": 5,
             "create_unit_cube": 6, "create_interval": 4, "create_unit_interval": 3,
             "create_mesh": 5}

    def seeded(make, at):
        @functools.wraps(make)
        def wrapper(*args, **kw):
            if "partitioner" not in kw and len(args) <= at:
                kw["partitioner"] = dmesh.create_cell_partitioner(
                    dolfinx.graph.partitioner_scotch(0.025, seed))
            return make(*args, **kw)
        return wrapper

    for name, at in where.items():
        setattr(dmesh, name, seeded(getattr(dmesh, name), at))


if os.environ.get("FENICSMPM_TEST_PARTITION_SEED"):
    _seeded_partitions(int(os.environ["FENICSMPM_TEST_PARTITION_SEED"]))


@pytest.fixture(scope="session")
def comm():
    """The world communicator."""
    return MPI.COMM_WORLD


def _shared_tmpdir(comm):
    """One temporary directory shared by all ranks: created on rank 0, broadcast, removed
    at teardown (once every rank is done with it)."""
    path = tempfile.mkdtemp(prefix="fenicsmpm_test_") if comm.rank == 0 else None
    path = comm.bcast(path, root=0)
    yield path
    comm.barrier()
    if comm.rank == 0:
        shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def shared_tmp_path(comm):
    yield from _shared_tmpdir(comm)


@pytest.fixture(scope="module")
def shared_module_tmp_path():
    yield from _shared_tmpdir(MPI.COMM_WORLD)


@pytest.fixture
def rng(comm):
    """A random generator seeded differently on each rank (reproducible)."""
    return np.random.default_rng(20240611 + 7919 * comm.rank)



def _coordinate_hash(x, salt):
    """Deterministic pseudo-random numbers in [-0.5, 0.5) computed from coordinates, so a
    vertex shared by two ranks (owned on one, ghost on the other) moves identically."""
    w = np.array([12.9898, 78.233, 37.719]) * (1.0 + 0.1372 * salt)
    s = np.sin(x @ w + 3.1 * salt) * 43758.5453
    return s - np.floor(s) - 0.5


def distort_interior(msh, amplitude):
    """Move every interior vertex of `msh` (in place, before a Grid is built on it) by a
    pseudo-random offset of up to `amplitude` per component; boundary vertices stay, so
    the domain is unchanged. Returns the number of moved vertices (global)."""
    gx = msh.geometry.x
    d = msh.geometry.dim
    lo, hi = gx[:, :d].min(axis=0), gx[:, :d].max(axis=0)
    lo = np.min(msh.comm.allgather(lo), axis=0)
    hi = np.max(msh.comm.allgather(hi), axis=0)
    x0 = gx.copy()
    interior = np.all((x0[:, :d] > lo + 1e-12) & (x0[:, :d] < hi - 1e-12), axis=1)
    for k in range(d):
        gx[interior, k] += amplitude * 2.0 * _coordinate_hash(x0[interior], k)
    return msh.comm.allreduce(int(np.count_nonzero(interior)))


@pytest.fixture(scope="session")
def distort():
    """The distort_interior(msh, amplitude) helper."""
    return distort_interior
